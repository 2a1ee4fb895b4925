//! Stepping allocates nothing on the heap: every buffer is made when the tether is built (the
//! dense reference's mass matrix on its first use).
//!
//! One test function only: the allocation counter is global, and tests run on parallel threads.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use accd_tether::{reference, Solver, Tether, TetherModel};

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
    assert_eq!(tether.model_mut().solver(), Solver::Recursive);
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

    // Both solvers' entry points, on a model of their own (the dense one after its first use).
    let mut model = TetherModel::new(&cfg).unwrap();
    let state = tether.state().clone();
    let mut qdd = vec![0.0; model.dofs()];
    model
        .accelerations_dense(state.time, &state.q, &state.qd, &flow, &mut qdd)
        .unwrap();
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    for _ in 0..50 {
        model
            .accelerations_recursive(state.time, &state.q, &state.qd, &flow, &mut qdd)
            .unwrap();
        model
            .tensions(
                state.time,
                &state.q,
                &state.qd,
                &flow,
                &mut qdd,
                &mut tensions,
            )
            .unwrap();
        model
            .accelerations_dense(state.time, &state.q, &state.qd, &flow, &mut qdd)
            .unwrap();
    }
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert_eq!(after - before, 0, "{} allocations", after - before);
}
