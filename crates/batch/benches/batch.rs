//! Agent steps per second of the batch env (10 physics steps each), N = 1, 16, 256, on one
//! thread and on all cores.

use accd_batch::{Autoreset, BatchEnv, StepOutputs};
use accd_sim::{EnvConfig, ACT_DIM};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

/// The exact air scheme of the first releases: per-stage sampling, Box-Muller normals, one
/// shared turbulence stream (the default is the fast scheme).
fn exact() -> EnvConfig {
    let mut config = EnvConfig::default();
    config.physics.wake.sampling = accd_sim::AirSampling::PerStage;
    config.physics.turbulence.normal_sampler = accd_sim::NormalSampler::BoxMuller;
    config.physics.turbulence.lane_streams = accd_sim::LaneStreams::Shared;
    config
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("batch_step");
    group.sample_size(10);
    for (scheme, config) in [("default", EnvConfig::default()), ("exact", exact())] {
        for &n in &[1usize, 16, 256] {
            for &threads in &[1usize, 0] {
                let mut env = BatchEnv::new(
                    config.clone().validated().unwrap(),
                    n,
                    1,
                    Autoreset::SameStep,
                    threads,
                )
                .unwrap();
                let label = format!("{scheme}-n{n}-threads{}", env.threads());
                let actions: Vec<f32> = (0..n * ACT_DIM)
                    .map(|k| ((k % 7) as f32 - 3.0) / 4.0)
                    .collect();
                let mut out = StepOutputs::new(n);
                group.throughput(Throughput::Elements(n as u64));
                group.bench_function(BenchmarkId::new("agent_steps", label), |b| {
                    b.iter(|| env.step(&actions, out.buffers()).unwrap())
                });
            }
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
