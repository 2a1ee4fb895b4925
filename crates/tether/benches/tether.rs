//! Cost of one right-hand-side evaluation and one RK4 step, for Table 3's tether towed with the
//! stand-in capturing device (aerodynamics on): the O(n) recursive solver (the hot path) at
//! n = 10, 30, 100, 300 and the dense O(n^3) reference at n = 10, 30, 100; and the distributed
//! elasticity (`elasticity: "distributed"`) by both solvers at n = 30, 100, where `rk4_step` is one
//! step of the largest stable length (its stiff axial modes allow about 1e-5 s at n = 30 with
//! Table 3's damping; printed when the bench starts); and `implicit_axial`: one step at the
//! default 0.01 s of explicit RK4 (attachment) beside the implicit scheme (attachment and
//! distributed) at n = 30, 100.
//!
//! Run: `cargo bench -p accd-tether --features bench --bench tether -- --warm-up-time 1 --measurement-time 3`
//! (results and machine in BENCHMARKS.md at the repository root).

use std::hint::black_box;

use accd_tether::config::{StepLoad, RK4_STABILITY_LIMIT};
use accd_tether::{reference, Elasticity, Scheme, Solver, Tether, TetherConfig};
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

/// The towed attachment-model state of [`towed`] in the distributed layout, the attachment
/// element's stretch shared equally by the n elements (the same tension in each), with a time
/// step of 0.9 of the largest stable one for the chain at rest under its weight.
fn towed_distributed(n: usize, solver: Solver) -> (Tether, accd_tether::UniformFlow) {
    let (att, flow) = towed(n, Solver::Recursive);
    let cfg = TetherConfig {
        elasticity: Elasticity::Distributed,
        ..att.config().clone()
    };
    let load = StepLoad::at_rest(
        &cfg,
        cfg.static_tension(),
        flow.density,
        185.0,
        cfg.tip_mass,
    );
    let cfg = TetherConfig {
        time_step: 0.9 * RK4_STABILITY_LIMIT / cfg.fastest_rate(&load),
        ..cfg
    };
    let mut state = att.state().to_distributed().unwrap();
    let (s, sd) = (state.q[0] / n as f64, state.qd[0] / n as f64);
    state.q[0] = s;
    state.qd[0] = sd;
    for k in 1..n {
        state.q[2 * n + k] = s;
        state.qd[2 * n + k] = sd;
    }
    let mut tether = Tether::new(&cfg).unwrap();
    tether.set_state(state).unwrap();
    tether.model_mut().set_solver(solver);
    eprintln!(
        "distributed, n = {n}: time_step {:.3e} s, {} substep(s)",
        cfg.time_step,
        tether.substeps(&flow).unwrap()
    );
    (tether, flow)
}

fn bench(c: &mut Criterion) {
    group(c, "recursive", Solver::Recursive, &[10, 30, 100, 300]);
    group(c, "dense", Solver::Dense, &[10, 30, 100]);
    let mut dist = c.benchmark_group("distributed");
    for (name, solver) in [("recursive", Solver::Recursive), ("dense", Solver::Dense)] {
        for n in [30usize, 100] {
            let (tether, flow) = towed_distributed(n, solver);
            let state = tether.state().clone();
            let mut model = tether.clone();
            let model = model.model_mut();
            let mut qdd = vec![0.0; model.dofs()];
            dist.bench_with_input(BenchmarkId::new(format!("{name}_rhs"), n), &n, |b, _| {
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
            let mut stepper = tether.clone();
            dist.bench_with_input(
                BenchmarkId::new(format!("{name}_rk4_step"), n),
                &n,
                |b, _| b.iter(|| stepper.step(black_box(&flow)).unwrap()),
            );
        }
    }
    dist.finish();
}

/// The implicit scheme (`scheme: "implicit_axial"`) beside explicit RK4, Table 3's towed tether
/// at the default 0.01 s (the towed state of [`towed`] after 20 s; the distributed one from it
/// as in [`towed_distributed`], then 5 s of its own steps): one step of each, side by side.
fn implicit_axial(c: &mut Criterion) {
    let mut group = c.benchmark_group("implicit_axial");
    for n in [30usize, 100] {
        let (att, flow) = towed(n, Solver::Recursive);
        let implicit = |cfg: &TetherConfig| TetherConfig {
            scheme: Scheme::ImplicitAxial,
            ..cfg.clone()
        };
        let mut explicit = att.clone();
        let mut attachment = Tether::new(&implicit(att.config())).unwrap();
        attachment.set_state(att.state().clone()).unwrap();
        let (dist, _) = towed_distributed(n, Solver::Recursive);
        let mut distributed = Tether::new(&TetherConfig {
            time_step: att.config().time_step,
            ..implicit(dist.config())
        })
        .unwrap();
        distributed.set_state(dist.state().clone()).unwrap();
        distributed.step_many(500, &flow).unwrap();
        for (name, tether) in [
            ("attachment_rk4_step", &mut explicit),
            ("attachment_implicit_step", &mut attachment),
            ("distributed_implicit_step", &mut distributed),
        ] {
            group.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
                b.iter(|| tether.step(black_box(&flow)).unwrap())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench, implicit_axial);
criterion_main!(benches);
