//! A capture episode under the attachment and the distributed elasticity, both at the default
//! 0.01 s step: the default task (wake and turbulence on, the same seeds), each model settled
//! on its own open-loop equilibrium, then 60 s of the same open-loop flap commands (a slow
//! sweep of pitch and yaw). Prints, per model and scheme, the wall time, the capture point's
//! equilibrium and its largest distance from the attachment model's (RK4) over the run, the
//! peak attachment tension and the peak tension anywhere along the chain.
//!
//! Run: `cargo run --release -p accd-sim --example capture_elasticity -- [seconds]`.
use std::sync::Arc;
use std::time::Instant;

use accd_sim::{EnvConfig, Episode, Equilibrium, Seeds};
use accd_tether::{Elasticity, Scheme};
use nalgebra::Vector3;

struct Run {
    name: String,
    wall: f64,
    equilibrium: Vector3<f64>,
    track: Vec<Vector3<f64>>,
    peak_attachment: f64,
    peak_chain: f64,
}

fn run(elasticity: Elasticity, scheme: Scheme, seconds: f64) -> Run {
    let mut config = EnvConfig::default();
    config.physics.tether.elasticity = elasticity;
    config.physics.tether.scheme = scheme;
    // No capture and no episode end: the whole run is compared.
    config.physics.boom.capture_radius = 1e-6;
    config.capture_window = 1000.0;
    let config = Arc::new(config.validated().unwrap());
    let start = Instant::now();
    let eq = Arc::new(Equilibrium::settle(&config).unwrap());
    let seeds = Seeds {
        initial: 3,
        wake: 4,
        rlv: 5,
    };
    let mut ep = Episode::new(config.clone(), eq.clone(), seeds).unwrap();
    let n = config.physics.tether.segments;
    let mut tensions = vec![0.0; n + 1];
    let (mut track, mut peak_attachment, mut peak_chain) = (Vec::new(), 0.0f64, 0.0f64);
    let agent_dt = config.physics.tether.time_step * 10.0;
    for k in 0..(seconds / agent_dt).round() as usize {
        let t = k as f64 * agent_dt;
        let (pitch, yaw) = (0.5 * (0.2 * t).sin(), 0.3 * (0.13 * t).cos());
        let a = [pitch as f32, pitch as f32, yaw as f32, yaw as f32];
        let outcome = ep.step(&a).unwrap();
        assert!(!outcome.terminated, "{outcome:?}");
        let sim = ep.sim_mut();
        sim.tensions(&mut tensions).unwrap();
        peak_attachment = peak_attachment.max(sim.attachment_tension());
        peak_chain = tensions.iter().fold(peak_chain, |m, t| m.max(*t));
        track.push(sim.snapshot().unwrap().capture_point);
    }
    Run {
        name: format!("{}, {}", elasticity.name(), scheme.name()),
        wall: start.elapsed().as_secs_f64(),
        equilibrium: eq.capture_point,
        track,
        peak_attachment,
        peak_chain,
    }
}

fn main() {
    let seconds: f64 = std::env::args()
        .nth(1)
        .map_or(60.0, |a| a.parse().expect("seconds"));
    let runs = [
        run(Elasticity::Attachment, Scheme::Explicit, seconds),
        run(Elasticity::Attachment, Scheme::ImplicitAxial, seconds),
        run(Elasticity::Distributed, Scheme::ImplicitAxial, seconds),
    ];
    let base = &runs[0];
    for r in &runs {
        let (far, at) = r
            .track
            .iter()
            .zip(&base.track)
            .enumerate()
            .map(|(i, (a, b))| ((a - b).norm(), i))
            .fold((0.0f64, 0), |m, x| if x.0 > m.0 { x } else { m });
        let e = r.equilibrium;
        println!(
            "{{\"run\": \"{}\", \"wall_s\": {:.2}, \"equilibrium_capture_point_m\": [{:.4}, {:.4}, {:.4}], \
             \"equilibrium_offset_m\": {:.4}, \"max_capture_point_offset_m\": {far:.4}, \
             \"at_s\": {:.1}, \"peak_attachment_tension_n\": {:.1}, \"peak_chain_tension_n\": {:.1}}}",
            r.name,
            r.wall,
            e.x,
            e.y,
            e.z,
            (e - base.equilibrium).norm(),
            (at + 1) as f64 * 0.1,
            r.peak_attachment,
            r.peak_chain
        );
    }
}
