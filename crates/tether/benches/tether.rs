//! Cost of one right-hand-side evaluation and one RK4 step of the dense formulation, for
//! Table 3's tether towed with the stand-in capturing device (aerodynamics on), at n = 10, 30, 100.
//!
//! Run: `cargo bench -p accd-tether --bench tether`

use std::hint::black_box;

use accd_tether::{reference, Tether, TetherConfig, TetherModel};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};

/// The towed reference case with `n` segments, advanced 20 s so that the state is a realistic,
/// sagging, moving one.
fn towed(n: usize) -> (Tether, accd_tether::UniformFlow) {
    let cfg = TetherConfig {
        segments: n,
        ..TetherConfig::table3()
    };
    let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
    let mut tether = Tether::new(&cfg).unwrap();
    tether.step_many(2000, &flow).unwrap();
    (tether, flow)
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("dense");
    for n in [10usize, 30, 100] {
        let (tether, flow) = towed(n);
        let state = tether.state().clone();
        let mut model = TetherModel::new(tether.config()).unwrap();
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

criterion_group!(benches, bench);
criterion_main!(benches);
