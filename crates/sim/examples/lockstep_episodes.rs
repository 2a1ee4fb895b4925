//! Four episodes of the default task stepped one by one (`Episode::step`) against four stepped
//! together (`Episode::step_four`: the tether's recursion four AVX2 lanes wide), on one thread,
//! timed in interleaved rounds so that both see the same machine load; the minimum per
//! env-agent-step over the rounds counts. Also checks that both end in the same states.
//!
//! `cargo run --release -p accd-sim --example lockstep_episodes -- [rounds] [default|exact] [both|alone|four] [threads]`
//! (one mode alone, for a profiler; with 2 threads each steps its own four episodes, the
//! figures are per thread).
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use accd_sim::{AirSampling, EnvConfig, Episode, Equilibrium, LaneStreams, NormalSampler, Seeds};
use accd_tether::LockstepWork;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rounds: usize = args
        .get(1)
        .map_or(10, |a| a.parse().expect("rounds: a count"));
    let mut config = EnvConfig::default();
    if args.get(2).map(String::as_str) == Some("exact") {
        config.physics.wake.sampling = AirSampling::PerStage;
        config.physics.turbulence.normal_sampler = NormalSampler::BoxMuller;
        config.physics.turbulence.lane_streams = LaneStreams::Shared;
    }
    // Long episodes that nothing ends: every agent step is ten physics steps.
    config.physics.boom.capture_radius = 1e-6;
    config.capture_window = 1000.0;
    config.limits.max_distance = 1e4;
    let config = Arc::new(config.validated().unwrap());
    let eq = Arc::new(Equilibrium::settle(&config).unwrap());
    let make = |j: u64| {
        let seeds = Seeds {
            initial: j,
            wake: 100 + j,
            rlv: 200 + j,
        };
        Episode::new(Arc::clone(&config), Arc::clone(&eq), seeds).unwrap()
    };
    let mode = args.get(3).map_or("both", String::as_str);
    let threads: usize = args
        .get(4)
        .map_or(1, |a| a.parse().expect("threads: a count"));
    let (run_alone, run_four) = (mode != "four", mode != "alone");
    let action = |j: usize, k: usize| {
        let t = 0.1 * k as f32 + j as f32;
        [0.3 * t.sin(), 0.3 * t.sin(), 0.2 * t.cos(), 0.2 * t.cos()]
    };
    let steps = 100;
    // One thread's measurement: its four episodes one by one and its copies together.
    let measure = |first: u64| {
        let mut alone: Vec<Episode> = (first..first + 4).map(make).collect();
        let mut four = alone.clone();
        let stop = AtomicBool::new(false);
        let mut work = LockstepWork::default();
        let mut k = 0;
        let (mut best_alone, mut best_four) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..rounds {
            let t = Instant::now();
            for s in 0..steps * usize::from(run_alone) {
                for (j, e) in alone.iter_mut().enumerate() {
                    e.step(&action(j, k + s)).unwrap();
                }
            }
            best_alone = best_alone.min(t.elapsed().as_secs_f64() / (4 * steps) as f64);
            let t = Instant::now();
            for s in 0..steps * usize::from(run_four) {
                let actions: [[f32; 4]; 4] = std::array::from_fn(|j| action(j, k + s));
                let [a, b, c, d] = &mut four[..] else {
                    unreachable!()
                };
                let results = Episode::step_four(
                    [a, b, c, d],
                    std::array::from_fn(|j| &actions[j][..]),
                    &stop,
                    &mut work,
                );
                for r in results {
                    r.unwrap();
                }
            }
            best_four = best_four.min(t.elapsed().as_secs_f64() / (4 * steps) as f64);
            k += steps;
        }
        let same = !(run_alone && run_four)
            || alone
                .iter()
                .zip(&four)
                .all(|(a, b)| format!("{:?}", a.state()) == format!("{:?}", b.state()));
        (best_alone, best_four, same)
    };
    let results: Vec<(f64, f64, bool)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|i| {
                let measure = &measure;
                scope.spawn(move || measure(4 * i as u64))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (i, (best_alone, best_four, same)) in results.into_iter().enumerate() {
        println!("thread {i}: the same states bit for bit: {same}");
        println!(
            "one by one {:.1} us, four together {:.1} us per env agent step: {:.3}x",
            best_alone * 1e6,
            best_four * 1e6,
            best_alone / best_four
        );
    }
}
