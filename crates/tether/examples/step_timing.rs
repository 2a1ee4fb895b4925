//! Times RK4 steps of Table 3's towed tether (a quick check beside the criterion benches):
//! `cargo run --release -p accd-tether --example step_timing -- [n] [steps] [dense]`.
use std::time::Instant;

use accd_tether::{reference, Solver, Tether, TetherConfig};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).map_or(30, |a| a.parse().unwrap());
    let steps: usize = args.get(2).map_or(100_000, |a| a.parse().unwrap());
    let solver = if args.get(3).is_some_and(|a| a == "dense") {
        Solver::Dense
    } else {
        Solver::Recursive
    };
    let cfg = TetherConfig {
        segments: n,
        time_step: if n >= 300 { 0.005 } else { 0.01 },
        ..TetherConfig::table3()
    };
    let (cfg, mut flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
    let mut tether = Tether::new(&cfg).unwrap();
    tether.step_many(2000, &flow).unwrap();
    if args.get(4).is_some_and(|a| a == "still") {
        flow.density = 0.0;
    }
    tether.model_mut().set_solver(solver);
    let mut best = f64::INFINITY;
    // Best of many short runs: robust to other load on the machine.
    let chunk = 200;
    for _ in 0..(steps / chunk).max(1) {
        let start = Instant::now();
        tether.step_many(chunk, &flow).unwrap();
        best = best.min(start.elapsed().as_secs_f64() / chunk as f64);
    }
    println!(
        "n = {n}, {solver:?}: best {:.3} us per RK4 step",
        best * 1e6
    );
}
