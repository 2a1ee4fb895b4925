//! Interleaved timing of one step at 0.01 s of Table 3's towed tether (n segments, stand-in
//! ACCD): explicit RK4 on the attachment model against the implicit scheme
//! (`scheme: "implicit_axial"`) on the attachment and the distributed model. Rounds of `chunk`
//! steps of each in turn, the best round of each kept: the ratios are robust to other load on
//! the machine, which slows all three alike.
//!
//! Run: `cargo run --release -p accd-tether --example implicit_axial_timing -- [n] [rounds]`.
use std::time::Instant;

use accd_tether::{reference, Elasticity, Scheme, Tether, TetherConfig};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).map_or(30, |a| a.parse().unwrap());
    let rounds: usize = args.get(2).map_or(200, |a| a.parse().unwrap());
    let base = TetherConfig {
        segments: n,
        ..TetherConfig::table3()
    };
    let (base, flow) = reference::towed(&base, reference::StandInBody::accd()).unwrap();
    let make = |elasticity, scheme| {
        let cfg = TetherConfig {
            elasticity,
            scheme,
            ..base.clone()
        };
        let mut t = Tether::new(&cfg).unwrap();
        // 20 s of towing: a realistic, sagging, moving state.
        t.step_many(2000, &flow).unwrap();
        t
    };
    let mut tethers = [
        (
            "attachment, RK4",
            make(Elasticity::Attachment, Scheme::Explicit),
        ),
        (
            "attachment, implicit_axial",
            make(Elasticity::Attachment, Scheme::ImplicitAxial),
        ),
        (
            "distributed, implicit_axial",
            make(Elasticity::Distributed, Scheme::ImplicitAxial),
        ),
    ];
    let chunk = 100;
    let mut best = [f64::INFINITY; 3];
    for _ in 0..rounds {
        for (j, (_, t)) in tethers.iter_mut().enumerate() {
            let start = Instant::now();
            t.step_many(chunk, &flow).unwrap();
            best[j] = best[j].min(start.elapsed().as_secs_f64() / chunk as f64);
        }
    }
    for (j, (name, _)) in tethers.iter().enumerate() {
        println!(
            "n = {n}, {name}: best {:.3} us per step, {:.2}x the attachment RK4 step",
            best[j] * 1e6,
            best[j] / best[0]
        );
    }
}
