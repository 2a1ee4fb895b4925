//! The capture-system physics step against the tether alone, timed in interleaved rounds (each
//! round steps the tether 2000 times, then the capture system 2000 times) and reported as the
//! minimum per step over the rounds, so that the ratio compares runs under the same machine load:
//! `cargo run --release -p accd-sim --example capture_ratio [rounds]` (default 40).
//!
//! The tether alone is Table 3's towed with the stand-in body (`reference::towed`), the capture
//! system the default configuration (tether n = 30 with the ACCD, 8 deg wake with turbulence,
//! boom, capture check) under small flap commands, both after 2000 steps of settling: the pair of
//! `benches/capture.rs`.

use std::time::Instant;

use accd_sim::{CaptureConfig, CaptureSim, Seeds};
use accd_tether::{reference, Tether, TetherConfig};

fn main() {
    let rounds: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(40);
    let (cfg, flow) =
        reference::towed(&TetherConfig::table3(), reference::StandInBody::accd()).unwrap();
    let mut tether = Tether::new(&cfg).unwrap();
    let config = CaptureConfig::default().validated().unwrap();
    let seeds = Seeds {
        initial: 1,
        wake: 42,
        rlv: 3,
    };
    let mut sim = CaptureSim::new(&config, seeds).unwrap();
    for _ in 0..2000 {
        tether.step(&flow).unwrap();
    }
    sim.step_many(2000, [0.0; 4]).unwrap();
    let (mut best_tether, mut best_capture) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..rounds {
        let t = Instant::now();
        for _ in 0..2000 {
            tether.step(&flow).unwrap();
        }
        best_tether = best_tether.min(t.elapsed().as_secs_f64() / 2000.0);
        let t = Instant::now();
        for k in 0..2000 {
            let a = 0.01 * ((k % 5) as f64 - 2.0);
            sim.step([a, -a, 0.02, 0.0]).unwrap();
        }
        best_capture = best_capture.min(t.elapsed().as_secs_f64() / 2000.0);
    }
    println!(
        "tether alone {:.3} us, capture system {:.3} us per physics step: ratio {:.3}",
        best_tether * 1e6,
        best_capture * 1e6,
        best_capture / best_tether
    );
}
