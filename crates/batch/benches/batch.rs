//! Agent steps per second of the batch env (10 physics steps each), N = 1, 16, 256, on one
//! thread and on all cores.

use accd_batch::{info, Autoreset, BatchEnv, StepBuffers};
use accd_sim::{EnvConfig, ACT_DIM, OBS_DIM};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("batch_step");
    group.sample_size(10);
    for &n in &[1usize, 16, 256] {
        for &threads in &[1usize, 0] {
            let mut env =
                BatchEnv::new(EnvConfig::default(), n, 1, Autoreset::SameStep, threads).unwrap();
            let label = format!("n{n}-threads{}", env.threads());
            let actions: Vec<f32> = (0..n * ACT_DIM)
                .map(|k| ((k % 7) as f32 - 3.0) / 4.0)
                .collect();
            let mut obs = vec![0.0; n * OBS_DIM];
            let mut final_obs = vec![0.0; n * OBS_DIM];
            let mut reward = vec![0.0; n];
            let mut terminated = vec![false; n];
            let mut truncated = vec![false; n];
            let mut infos = vec![0.0; n * info::DIM];
            let mut wake = vec![0; n];
            let mut reset = vec![false; n];
            group.throughput(Throughput::Elements(n as u64));
            group.bench_function(BenchmarkId::new("agent_steps", label), |b| {
                b.iter(|| {
                    env.step(
                        &actions,
                        StepBuffers {
                            obs: &mut obs,
                            reward: &mut reward,
                            terminated: &mut terminated,
                            truncated: &mut truncated,
                            final_obs: &mut final_obs,
                            info: &mut infos,
                            wake_seed: &mut wake,
                            autoreset: &mut reset,
                        },
                    )
                    .unwrap()
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
