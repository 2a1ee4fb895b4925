//! Stepping a batch allocates nothing on the heap, on any thread (autoresets included).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use accd_batch::{Autoreset, BatchEnv, StepOutputs};
use accd_sim::{EnvConfig, ACT_DIM};

struct Counting;

/// Allocations by every thread (the pool's workers included); this binary has one test only.
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn batch_steps_allocate_nothing() {
    // The sensor model (ring buffers and delay line allocated at construction) in the second.
    for (mode, sensors) in [
        (Autoreset::SameStep, false),
        (Autoreset::NextStep, false),
        (Autoreset::SameStep, true),
    ] {
        let config = EnvConfig {
            capture_window: 0.5,
            initial: accd_sim::task::InitialConfig {
                settle_time: 10.0,
                ..Default::default()
            },
            sensors: accd_sim::SensorsConfig {
                enabled: sensors,
                delay_steps: 2 * sensors as usize,
                ..Default::default()
            },
            ..EnvConfig::default()
        };
        let n = 6;
        let mut env = BatchEnv::new(config.validated().unwrap(), n, 3, mode, 2).unwrap();
        let actions: Vec<f32> = (0..n * ACT_DIM)
            .map(|k| ((k % 5) as f32 - 2.0) / 3.0)
            .collect();
        let mut out = StepOutputs::new(n);
        let mut step = |env: &mut BatchEnv| env.step(&actions, out.buffers()).unwrap();
        // Warm-up: the pool's workers allocate once, lazily, the first time they take work and
        // the first time they go to sleep (their thread handles); let every worker do both.
        for _ in 0..5 {
            step(&mut env);
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
        let before = ALLOCATIONS.load(Ordering::SeqCst);
        // 30 steps of 5-step episodes: every env resets several times.
        for _ in 0..30 {
            step(&mut env);
        }
        let after = ALLOCATIONS.load(Ordering::SeqCst);
        assert_eq!(
            after - before,
            0,
            "{mode:?}, sensors {sensors}: {} allocations",
            after - before
        );
    }
}
