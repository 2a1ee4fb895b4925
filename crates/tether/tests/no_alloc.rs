//! Stepping allocates nothing on the heap: every buffer is made when the tether is built.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use accd_tether::{reference, Tether};

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
fn stepping_does_not_allocate() {
    let (cfg, flow) = reference::towed_table3();
    let mut tether = Tether::new(&cfg).unwrap();
    let mut tensions = vec![0.0; cfg.segments + 1];
    let mut joints = vec![nalgebra::Vector3::zeros(); cfg.segments + 1];
    tether.step(&flow).unwrap();
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    for _ in 0..200 {
        tether.step(&flow).unwrap();
        tether.tensions(&flow, &mut tensions).unwrap();
        tether.joint_positions(&mut joints).unwrap();
        let _ = tether.energy();
        let _ = tether.tip_state();
    }
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert_eq!(
        after - before,
        0,
        "{} allocations in 200 steps",
        after - before
    );
}
