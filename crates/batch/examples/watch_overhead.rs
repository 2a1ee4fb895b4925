//! The cost of the interruptible batch step (the path the Python envs take) against the plain
//! one: best of interleaved rounds, per batch step, for N = 1, 4, 16, 256.
//!
//!     cargo run --release -p accd-batch --example watch_overhead [ROUNDS]

use accd_batch::{Autoreset, BatchEnv, StepOutputs};
use accd_sim::{EnvConfig, ACT_DIM};
use std::time::Instant;

fn main() {
    let rounds: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(7);
    for n in [1usize, 4, 16, 256] {
        let mut env = BatchEnv::new(
            EnvConfig::default().validated().unwrap(),
            n,
            1,
            Autoreset::SameStep,
            0,
        )
        .unwrap();
        let actions: Vec<f32> = (0..n * ACT_DIM)
            .map(|k| ((k % 7) as f32 - 3.0) / 4.0)
            .collect();
        let mut out = StepOutputs::new(n);
        let steps = (2000 / n).max(50);
        let (mut plain, mut watched) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..rounds {
            let t = Instant::now();
            for _ in 0..steps {
                env.step(&actions, out.buffers()).unwrap();
            }
            plain = plain.min(t.elapsed().as_secs_f64() / steps as f64);
            let t = Instant::now();
            for _ in 0..steps {
                env.step_interruptible(&actions, out.buffers(), &mut || false)
                    .unwrap();
            }
            watched = watched.min(t.elapsed().as_secs_f64() / steps as f64);
        }
        println!(
            "N = {n:>2}: plain {:8.1} us, interruptible {:8.1} us per batch step ({:+.1} %)",
            plain * 1e6,
            watched * 1e6,
            (watched / plain - 1.0) * 100.0
        );
    }
}
