//! Stepping allocates nothing on the heap: every buffer is made when the tether is built (the
//! dense reference's mass matrix on its first use).
//!
//! Allocations are counted per thread: the test harness's own threads allocate at times (a
//! global counter saw 4 of them in 200 steps once, under load: regression
//! `stepping_does_not_allocate` flaking in fresh-clone CI runs).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use accd_tether::{reference, Solver, Tether, TetherModel};

struct Counting;

thread_local! {
    /// Allocations made by this thread.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn count() {
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
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
    let before = allocations();
    for _ in 0..200 {
        tether.step(&flow).unwrap();
        tether.tensions(&flow, &mut tensions).unwrap();
        tether.joint_positions(&mut joints).unwrap();
        let _ = tether.energy();
        let _ = tether.tip_state();
    }
    let after = allocations();
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
    let before = allocations();
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
    let after = allocations();
    assert_eq!(after - before, 0, "{} allocations", after - before);
}

#[test]
fn distributed_stepping_does_not_allocate() {
    let (cfg, flow) = reference::towed_table3();
    let cfg = accd_tether::TetherConfig {
        elasticity: accd_tether::Elasticity::Distributed,
        time_step: 2e-4,
        ..cfg
    };
    let mut tether = Tether::new(&cfg).unwrap();
    let mut tensions = vec![0.0; cfg.segments + 1];
    let mut joints = vec![nalgebra::Vector3::zeros(); cfg.segments + 1];
    let mut centres = vec![nalgebra::Vector3::zeros(); cfg.segments];
    tether.step(&flow).unwrap();
    let mut model = TetherModel::new(&cfg).unwrap();
    let state = tether.state().clone();
    let mut qdd = vec![0.0; model.dofs()];
    model
        .accelerations_dense(state.time, &state.q, &state.qd, &flow, &mut qdd)
        .unwrap();
    let before = allocations();
    for _ in 0..20 {
        tether.step(&flow).unwrap();
        tether.tensions(&flow, &mut tensions).unwrap();
        tether.joint_positions(&mut joints).unwrap();
        let _ = tether.energy();
        let _ = tether.tip_state();
        model
            .accelerations_dense(state.time, &state.q, &state.qd, &flow, &mut qdd)
            .unwrap();
        model
            .centres_and_tip_batch(&state.q, &state.qd, &mut centres)
            .unwrap();
    }
    let after = allocations();
    assert_eq!(after - before, 0, "{} allocations", after - before);
}

#[test]
fn implicit_axial_stepping_does_not_allocate() {
    let (cfg, flow) = reference::towed_table3();
    for elasticity in [
        accd_tether::Elasticity::Attachment,
        accd_tether::Elasticity::Distributed,
    ] {
        let cfg = accd_tether::TetherConfig {
            elasticity,
            scheme: accd_tether::Scheme::ImplicitAxial,
            ..cfg.clone()
        };
        let mut tether = Tether::new(&cfg).unwrap();
        tether.step(&flow).unwrap();
        let before = allocations();
        for _ in 0..50 {
            tether.step(&flow).unwrap();
        }
        let after = allocations();
        assert_eq!(
            after - before,
            0,
            "{elasticity:?}: {} allocations",
            after - before
        );
    }
}
