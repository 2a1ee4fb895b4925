//! The paper's Fig. 9 cases (section 2.3.6) under both elasticities, Table 1's 10 m chain (n = 4,
//! c1 = 20 on joints and elements, vacuum): (a) hanging vertically, released unstretched, the
//! chain stretches under its own weight; (b) released at rest from phi = psi = pi/4 and swings.
//! Prints, per case and model, the total elongation's static level, its first peak, the amplitude
//! of its oscillation (first peak minus the level it settles to) and the frequency of that
//! oscillation (from its first two maxima), as JSON lines.
//!
//! Run: `cargo run --release -p accd-tether --example fig9 [seconds]` (default 3 s).

use accd_tether::direction::direction;
use accd_tether::{reference, Elasticity, Tether, TetherConfig, TetherState, Vacuum};
use nalgebra::Vector3;

/// Total elongation of the chain: the sum of the elements' stretches.
fn elongation(cfg: &TetherConfig, q: &[f64]) -> f64 {
    let n = cfg.segments;
    if cfg.is_distributed() {
        q[0] + q[2 * n + 1..].iter().sum::<f64>()
    } else {
        q[0]
    }
}

fn run(cfg: &TetherConfig, start: TetherState, seconds: f64) -> (Vec<f64>, Vec<f64>) {
    let mut tether = Tether::new(cfg).unwrap();
    let start = if cfg.is_distributed() {
        start.to_distributed().unwrap()
    } else {
        start
    };
    tether.set_state(start).unwrap();
    let (mut t, mut s) = (Vec::new(), Vec::new());
    for _ in 0..(seconds / cfg.time_step).round() as usize {
        tether.step(&Vacuum).unwrap();
        t.push(tether.state().time);
        s.push(elongation(cfg, &tether.state().q));
    }
    (t, s)
}

fn main() {
    let seconds: f64 = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("seconds"))
        .unwrap_or(3.0);
    let base = TetherConfig {
        time_step: 1e-3,
        ..TetherConfig::table1()
    };
    let n = base.segments;
    let d = direction(std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4);
    let cases = [
        (
            "a_vertical",
            TetherState::straight(n, reference::hanging_direction(), 0.0).unwrap(),
        ),
        (
            "b_swing",
            TetherState::from_directions(&vec![d; n], &vec![Vector3::zeros(); n], 0.0, 0.0)
                .unwrap(),
        ),
    ];
    for (case, start) in cases {
        for elasticity in [Elasticity::Attachment, Elasticity::Distributed] {
            let cfg = TetherConfig {
                elasticity,
                ..base.clone()
            };
            let (t, s) = run(&cfg, start.clone(), seconds);
            let peaks: Vec<(f64, f64)> = (1..s.len() - 1)
                .filter(|&i| s[i] > s[i - 1] && s[i] >= s[i + 1])
                .map(|i| (t[i], s[i]))
                .collect();
            let settled = s[s.len() - 1];
            let first_peak = peaks.first().map(|p| p.1).unwrap_or(f64::NAN);
            // From the first two maxima (later ones are damped into the noise of higher modes).
            let frequency_hz = if peaks.len() >= 2 {
                1.0 / (peaks[1].0 - peaks[0].0)
            } else {
                f64::NAN
            };
            println!(
                "{{\"case\": \"{case}\", \"elasticity\": \"{}\", \"final_elongation_m\": {settled:.6e}, \
                 \"first_peak_m\": {first_peak:.6e}, \"amplitude_m\": {:.6e}, \
                 \"frequency_hz\": {frequency_hz:.4}, \"peaks\": {}}}",
                elasticity.name(),
                first_peak - settled,
                peaks.len()
            );
        }
    }
}
