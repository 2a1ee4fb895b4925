//! Stepping a batch allocates nothing on the heap, on any thread (autoresets included).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use std::sync::Arc;

use accd_batch::{Autoreset, BatchEnv, StepOutputs};
use accd_sim::control::controller::{Controller, LqrController};
use accd_sim::control::filter::LqrFilter;
use accd_sim::control::lqr::{EXTRA_STATES, MEASURED_DIM};
use accd_sim::control::matrix::Matrix;
use accd_sim::{EnvConfig, ACT_DIM};

/// A filter of `n` plant states with small deterministic matrices (a stable estimate).
fn filter(n: usize) -> LqrFilter {
    let nz = n + EXTRA_STATES;
    let m = |r: usize, c: usize, s: f64| {
        Matrix::from_fn(r, c, |i, j| {
            s * (((i * 7 + j * 3) % 11) as f64 / 11.0 - 0.5)
        })
    };
    let (f, g, h, l) = (
        m(nz, nz, 0.05),
        m(nz, ACT_DIM, 1.0),
        m(MEASURED_DIM, nz, 1.0),
        m(nz, MEASURED_DIM, 0.05),
    );
    let (k, k_ff) = (m(ACT_DIM, n, 0.2), m(ACT_DIM, 4, 1.0));
    LqrFilter::from_parts(n, &f, &g, &h, &l, &k, &k_ff, [0.01; MEASURED_DIM]).unwrap()
}

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
    // The sensor model (ring buffers and delay line allocated at construction) in the third;
    // per-env LQR controllers (their scratch allocated at construction) in the last two.
    for (mode, sensors, controller) in [
        (Autoreset::SameStep, false, false),
        (Autoreset::NextStep, false, false),
        (Autoreset::SameStep, true, false),
        (Autoreset::SameStep, false, true),
        (Autoreset::NextStep, false, true),
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
        if controller {
            let filter = Arc::new(filter(17));
            let make = move || -> Box<dyn Controller> {
                Box::new(LqrController::new(Arc::clone(&filter)))
            };
            env.set_controllers(Some(&make));
        }
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
            "{mode:?}, sensors {sensors}, controller {controller}: {} allocations",
            after - before
        );
    }
}
