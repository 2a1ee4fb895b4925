//! One physics step of the whole capture system (tether n = 30 with the ACCD, 8 deg wake with
//! turbulence, boom, capture check) under the exact and the fast air schemes, beside the tether
//! alone (Table 3 towed with the stand-in body): the ratio the performance work tracks.

use accd_sim::{AirSampling, CaptureConfig, CaptureSim, LaneStreams, NormalSampler, Seeds};
use accd_tether::{reference, Tether, TetherConfig};
use criterion::{criterion_group, criterion_main, Criterion};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("physics_step");
    let (cfg, flow) =
        reference::towed(&TetherConfig::table3(), reference::StandInBody::accd()).unwrap();
    let mut tether = Tether::new(&cfg).unwrap();
    for _ in 0..2000 {
        tether.step(&flow).unwrap();
    }
    group.bench_function("tether_n30", |b| b.iter(|| tether.step(&flow).unwrap()));
    // The default is the fast scheme; the exact one is the first releases'.
    let mut exact = CaptureConfig::default();
    exact.wake.sampling = AirSampling::PerStage;
    exact.turbulence.normal_sampler = NormalSampler::BoxMuller;
    exact.turbulence.lane_streams = LaneStreams::Shared;
    for (name, config) in [
        ("capture_exact", exact),
        ("capture_fast", CaptureConfig::default()),
    ] {
        let seeds = Seeds {
            initial: 1,
            wake: 42,
            rlv: 3,
        };
        let mut sim = CaptureSim::new(&config.clone().validated().unwrap(), seeds).unwrap();
        sim.step_many(2000, [0.0; 4]).unwrap();
        group.bench_function(name, |b| {
            b.iter(|| sim.step([0.01, -0.01, 0.02, 0.0]).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
