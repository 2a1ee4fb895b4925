//! Four tethers stepped one by one (`Tether::step`) against four stepped together
//! (`Tether::step_four`, the recursion four AVX2 lanes wide), timed in interleaved rounds so
//! that both see the same machine load; the minimum per tether-step over the rounds counts.
//! Also checks that both give the same states bit for bit.
//!
//! `cargo run --release -p accd-tether --example lockstep_step -- [n] [rounds]`
use std::time::Instant;

use accd_tether::{reference, LockstepWork, Tether, TetherConfig};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args
        .get(1)
        .map_or(30, |a| a.parse().expect("n: a number of segments"));
    let rounds: usize = args
        .get(2)
        .map_or(15, |a| a.parse().expect("rounds: a count"));
    let cfg = TetherConfig {
        segments: n,
        time_step: if n >= 300 { 0.005 } else { 0.01 },
        ..TetherConfig::table3()
    };
    let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
    // Table 3's towed tether after 20 s, and three copies 0.1, 0.2, 0.3 s further on.
    let mut base = Tether::new(&cfg).unwrap();
    base.step_many(2000, &flow).unwrap();
    let mut alone: Vec<Tether> = (0..4)
        .map(|j| {
            let mut t = base.clone();
            t.step_many(10 * j, &flow).unwrap();
            t
        })
        .collect();
    let mut four = alone.clone();
    let mut work = LockstepWork::default();
    let flows = [&flow; 4];
    let steps = 2000;
    let (mut best_alone, mut best_four) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..rounds {
        let t = Instant::now();
        for _ in 0..steps {
            for tether in alone.iter_mut() {
                tether.step(&flow).unwrap();
            }
        }
        best_alone = best_alone.min(t.elapsed().as_secs_f64() / (4 * steps) as f64);
        let t = Instant::now();
        for _ in 0..steps {
            let [a, b, c, d] = &mut four[..] else {
                unreachable!()
            };
            for r in Tether::step_four([a, b, c, d], flows, &mut work) {
                r.unwrap();
            }
        }
        best_four = best_four.min(t.elapsed().as_secs_f64() / (4 * steps) as f64);
    }
    let same = alone.iter().zip(&four).all(|(a, b)| {
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        bits(&a.state().q) == bits(&b.state().q) && bits(&a.state().qd) == bits(&b.state().qd)
    });
    println!("n = {n}: the same states bit for bit: {same}");
    println!(
        "one by one {:.3} us, four together {:.3} us per tether-step: {:.3}x",
        best_alone * 1e6,
        best_four * 1e6,
        best_alone / best_four
    );
}
