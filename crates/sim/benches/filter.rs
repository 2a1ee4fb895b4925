//! The LQR baseline's per-step work (the Kalman filter's predict and update, then the control
//! law) at the default configuration's size: one env's step, as the batch's threads run it
//! beside each env, and a block of 16 rows, as a policy stepping a whole batch runs it. The
//! matrices have the design's shapes and made-up values: the cost depends on the shapes only.

use accd_sim::control::filter::LqrFilter;
use accd_sim::control::lqr::{EXTRA_STATES, MEASURED_DIM};
use accd_sim::control::matrix::Matrix;
use accd_sim::task::observation::{ACT_DIM, OBS_DIM};
use accd_sim::{linearize, EnvConfig};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let config = EnvConfig::default().validated().unwrap();
    let n = linearize(&config).unwrap().trim.len();
    let nz = n + EXTRA_STATES;
    // Small values in a fixed pattern (no zeros, no subnormals): the cost depends on the shapes.
    let m = |r: usize, c: usize, s: f64| {
        Matrix::from_fn(r, c, |i, j| {
            s * (((i * 31 + j * 17) % 23) as f64 / 23.0 - 0.48)
        })
    };
    let (f, g, h, l) = (
        m(nz, nz, 0.05),
        m(nz, ACT_DIM, 1.0),
        m(MEASURED_DIM, nz, 1.0),
        m(nz, MEASURED_DIM, 0.05),
    );
    let (k, k_ff) = (m(ACT_DIM, n, 0.01), m(ACT_DIM, 4, 1.0));
    let filter = LqrFilter::from_parts(n, &f, &g, &h, &l, &k, &k_ff, [0.01; MEASURED_DIM]).unwrap();
    let obs: [f64; OBS_DIM] = std::array::from_fn(|i| (i % 7) as f64 * 0.01);
    let mut group = c.benchmark_group(format!("lqr_filter_nz{nz}"));
    let mut state = filter.new_state();
    let mut u = [0.0_f32; ACT_DIM];
    group.bench_function("step_one_env", |b| {
        b.iter(|| {
            filter.step(&mut state, black_box(&obs), &mut u).unwrap();
            black_box(u)
        })
    });
    let rows = 16;
    let mut states: Vec<_> = (0..rows).map(|_| filter.new_state()).collect();
    let obs_rows = vec![obs; rows];
    let selected = vec![true; rows];
    let mut out = vec![[0.0_f32; ACT_DIM]; rows];
    group.bench_function("step_rows_16", |b| {
        b.iter(|| {
            filter
                .step_rows(&mut states, black_box(&obs_rows), &selected, &mut out)
                .unwrap();
            black_box(&out);
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
