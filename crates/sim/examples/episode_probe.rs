//! Times agent steps of one episode under several air models (for profiling the task's hot path):
//! `cargo run --release -p accd-sim --example episode_probe [steps] [default|sensors|fast|...]`.
use std::sync::Arc;

use accd_sim::{AirSampling, EnvConfig, Episode, Equilibrium, LaneStreams, NormalSampler, Seeds};

fn time(label: &str, config: EnvConfig, steps: usize) {
    let mut config = config;
    config.physics.boom.capture_radius = 1e-6;
    config.capture_window = 1000.0;
    let config = Arc::new(config.validated().unwrap());
    let eq = Arc::new(Equilibrium::settle(&config).unwrap());
    let mut ep = Episode::new(
        config,
        eq,
        Seeds {
            initial: 3,
            wake: 4,
            rlv: 5,
        },
    )
    .unwrap();
    let t = std::time::Instant::now();
    for k in 0..steps {
        let a = [0.1 * ((k % 7) as f32 - 3.0); 4];
        let o = ep.step(&a).unwrap();
        assert!(!o.terminated, "{o:?}");
    }
    let per = t.elapsed().as_secs_f64() / (steps * 10) as f64;
    println!("{label:<28} {:.2} us per physics step", per * 1e6);
}

fn main() {
    let steps: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(2000);
    let only = std::env::args().nth(2).unwrap_or_default();
    if only == "per_step" {
        let mut per_step = EnvConfig::default();
        per_step.physics.wake.sampling = AirSampling::PerStep;
        return time("... sampled once per step", per_step, steps);
    }
    if only == "fast" {
        let mut fast = EnvConfig::default();
        fast.physics.wake.sampling = AirSampling::PerStep;
        fast.physics.turbulence.normal_sampler = NormalSampler::Ziggurat;
        fast.physics.turbulence.lane_streams = LaneStreams::PerLane;
        return time("per step, ziggurat, on-demand lanes", fast, steps);
    }
    if only == "default" {
        return time("mean wake + turbulence", EnvConfig::default(), steps);
    }
    if only == "sensors" {
        // The default task under Python's `accd_gym.config.SENSORS_TIER`.
        let mut sensed = EnvConfig::default();
        sensed.sensors.enabled = true;
        sensed.sensors.vision.latency = 0.06;
        sensed.sensors.vision.dropout = 0.1;
        sensed.sensors.vision.dropout_burst = 5.0;
        return time("default + sensors tier", sensed, steps);
    }
    if only == "legacy" {
        // The three runs of the probe at a3be75f (before the capture-layer rebuild), each under
        // the exact air scheme it then had by default: the same work, for instruction counts.
        for (label, wake, turbulence) in [
            ("no wake, no turbulence", false, false),
            ("mean wake", true, false),
            ("mean wake + turbulence", true, true),
        ] {
            let mut c = EnvConfig::default();
            c.physics.wake.enabled = wake;
            c.physics.turbulence.wake_turbulence = turbulence;
            c.physics.wake.sampling = AirSampling::PerStage;
            c.physics.turbulence.normal_sampler = NormalSampler::BoxMuller;
            c.physics.turbulence.lane_streams = LaneStreams::Shared;
            time(label, c, steps);
        }
        return;
    }
    if only == "exact" {
        let mut exact = EnvConfig::default();
        exact.physics.wake.sampling = AirSampling::PerStage;
        exact.physics.turbulence.normal_sampler = NormalSampler::BoxMuller;
        exact.physics.turbulence.lane_streams = LaneStreams::Shared;
        return time("exact scheme (first releases)", exact, steps);
    }
    let mut calm = EnvConfig::default();
    calm.physics.wake.enabled = false;
    calm.physics.turbulence.wake_turbulence = false;
    time("no wake, no turbulence", calm, steps);
    let mut mean = EnvConfig::default();
    mean.physics.turbulence.wake_turbulence = false;
    time("mean wake", mean, steps);
    time("mean wake + turbulence", EnvConfig::default(), steps);
    let mut per_stage = EnvConfig::default();
    per_stage.physics.wake.sampling = AirSampling::PerStage;
    time("... sampled at every RK4 stage", per_stage, steps);
}
