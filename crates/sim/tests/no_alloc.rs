//! Sampling the wake and the turbulence, advancing and resetting the turbulence, and stepping a
//! tether in the wake field allocate nothing on the heap.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use accd_sim::turbulence::AmbientTurbulence;
use accd_sim::{WakeField, WakeFieldConfig};
use accd_tether::{reference, Surroundings, Tether};
use nalgebra::Vector3;

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn sampling_advancing_and_stepping_do_not_allocate() {
    let (cfg, flow) = reference::towed_table3();
    let mut config = WakeFieldConfig::default();
    config.turbulence.ambient = AmbientTurbulence::Moderate;
    let mut field = WakeField::new(&config, 3)
        .unwrap()
        .with_tip_drag_area(flow.tip_drag_area);
    let mut tether = Tether::new(&cfg).unwrap();
    tether.step(&field).unwrap();
    field.advance(cfg.time_step).unwrap();
    let points = [
        Vector3::new(-100.0, 2.0, 20.0),
        Vector3::new(-240.0, 0.0, 50.0),
        Vector3::new(-2000.0, 0.0, 0.0),
    ];
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let mut acc = Vector3::zeros();
    for i in 0..300 {
        tether.step(&field).unwrap();
        field.advance(cfg.time_step).unwrap();
        for p in &points {
            let w = field.wake().sample(p);
            acc += w.velocity + field.turbulence().sample(p, w.tke);
            acc += field.air_velocity(0.0, p);
            acc += field.tip_force(0.0, p, &Vector3::zeros());
        }
        if i == 150 {
            field.reset(4);
        }
    }
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert!(acc.iter().all(|v| v.is_finite()));
    assert_eq!(after - before, 0, "{} allocations", after - before);
}
