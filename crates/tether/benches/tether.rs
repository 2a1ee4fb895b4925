//! Cost of one right-hand-side evaluation and one RK4 step, for Table 3's tether towed with the
//! stand-in capturing device (aerodynamics on): the O(n) recursive solver (the hot path) at
//! n = 10, 30, 100, 300 and the dense O(n^3) reference at n = 10, 30, 100.
//!
//! Run: `cargo bench -p accd-tether --bench tether -- --warm-up-time 1 --measurement-time 3`
//! (results and machine in BENCHMARKS.md at the repository root).

use std::hint::black_box;

use accd_tether::{reference, Solver, Tether, TetherConfig};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};

/// The towed reference case with `n` segments and the given solver, advanced 20 s so that the
/// state is a realistic, sagging, moving one.
fn towed(n: usize, solver: Solver) -> (Tether, accd_tether::UniformFlow) {
    // Explicit RK4 at the default 0.01 s is unstable for n = 300 (0.83 m segments); the cost of
    // a step does not depend on its length.
    let cfg = TetherConfig {
        segments: n,
        time_step: if n >= 300 { 0.005 } else { 0.01 },
        ..TetherConfig::table3()
    };
    let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
    let mut tether = Tether::new(&cfg).unwrap();
    tether.model_mut().set_solver(Solver::Recursive);
    tether.step_many(2000, &flow).unwrap();
    tether.model_mut().set_solver(solver);
    (tether, flow)
}

fn group(c: &mut Criterion, name: &str, solver: Solver, sizes: &[usize]) {
    let mut group = c.benchmark_group(name);
    for &n in sizes {
        let (tether, flow) = towed(n, solver);
        let state = tether.state().clone();
        let mut model = tether.clone();
        let model = model.model_mut();
        let mut qdd = vec![0.0; model.dofs()];
        group.bench_with_input(BenchmarkId::new("rhs", n), &n, |b, _| {
            b.iter(|| {
                model
                    .accelerations(
                        state.time,
                        black_box(&state.q),
                        black_box(&state.qd),
                        &flow,
                        &mut qdd,
                    )
                    .unwrap();
                black_box(&qdd);
            })
        });
        // The towed tether is near its steady state, so stepping on keeps it representative.
        let mut stepper = tether.clone();
        group.bench_with_input(BenchmarkId::new("rk4_step", n), &n, |b, _| {
            b.iter(|| stepper.step(black_box(&flow)).unwrap())
        });
    }
    group.finish();
}

fn bench(c: &mut Criterion) {
    group(c, "recursive", Solver::Recursive, &[10, 30, 100, 300]);
    group(c, "dense", Solver::Dense, &[10, 30, 100]);
}

criterion_group!(benches, bench);
criterion_main!(benches);
