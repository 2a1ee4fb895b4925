//! Equilibria against closed-form results and the paper.
//!
//! * A vertical hanging tether stretches by its weight over k.
//! * A constant acceleration a of the towing aircraft tilts a hanging tether to atan(a/g).
//! * Tensions from Newton's law along the chain agree with the axial element's k s + c s'.
//! * Towed at 185 m/s, 6000 m with a stand-in capturing device, Table 3's tether settles to a
//!   steady shape about 50 m below the aircraft (paper Fig. 19).

use crate::common;

use accd_tether::{reference, Tether, TetherConfig, TetherModel, TetherState, UniformFlow, Vacuum};
use common::SplitMix;
use nalgebra::Vector3;

#[test]
fn hanging_tether_stretches_by_weight_over_k() {
    let cfg = TetherConfig {
        tip_mass: 50.0,
        ..TetherConfig::table3()
    };
    let weight = (cfg.total_mass() + cfg.tip_mass) * cfg.gravity;
    let expected = weight / cfg.axial_stiffness;
    let mut tether = Tether::new(&cfg).unwrap();
    tether
        .set_state(
            TetherState::straight(cfg.segments, reference::hanging_direction(), 0.0).unwrap(),
        )
        .unwrap();
    // Released unstretched, the axial mode (damping ratio 0.85) settles within a few seconds.
    tether.step_many(1000, &Vacuum).unwrap();
    let s = tether.state().elongation();
    eprintln!("hanging stretch {s:.9} m, weight / k = {expected:.9} m");
    assert!((s / expected - 1.0).abs() < 1e-9);
    assert!((tether.attachment_tension() / weight - 1.0).abs() < 1e-9);
}

fn tilt_from_vertical(state: &TetherState, k: usize) -> f64 {
    let e = state.direction(k);
    (-e.x).atan2(e.z)
}

#[test]
fn towing_aircraft_acceleration_tilts_hanging_tether() {
    let g = TetherConfig::table1().gravity;
    for a in [0.5, 2.0, 5.0] {
        let expected = (a / g).atan();
        // Equilibrium: Table 3 with a tip body, set at the predicted angle, does not accelerate.
        let cfg = TetherConfig {
            tip_mass: 50.0,
            ..TetherConfig::table3()
        };
        let env = UniformFlow {
            frame_acceleration: Vector3::new(a, 0.0, 0.0),
            ..UniformFlow::still()
        };
        let dir = Vector3::new(-expected.sin(), 0.0, expected.cos());
        let s_eq = (cfg.total_mass() + cfg.tip_mass) * (g * g + a * a).sqrt() / cfg.axial_stiffness;
        let st = TetherState::straight(cfg.segments, dir, s_eq).unwrap();
        let mut model = TetherModel::new(&cfg).unwrap();
        let mut qdd = vec![0.0; cfg.dofs()];
        model
            .accelerations(0.0, &st.q, &st.qd, &env, &mut qdd)
            .unwrap();
        assert!(
            qdd.iter().all(|v| v.abs() < 1e-9),
            "not an equilibrium at a = {a}: {qdd:?}"
        );

        // Dynamics: Table 1's chain, released hanging straight down, swings back and settles at
        // the predicted angle. Drag in dense still air damps the swing without moving the
        // equilibrium (the air is at rest in the aircraft's frame here).
        let cfg = TetherConfig {
            normal_drag_coefficient: 1.2,
            diameter: 0.1,
            time_step: 0.005,
            ..TetherConfig::table1()
        };
        let env = UniformFlow {
            density: 1000.0,
            ..env
        };
        let mut tether = Tether::new(&cfg).unwrap();
        tether
            .set_state(
                TetherState::straight(cfg.segments, reference::hanging_direction(), 0.0).unwrap(),
            )
            .unwrap();
        tether.step_many(12_000, &env).unwrap();
        // Quadratic drag fades with the swing, so average over the last 20 s of a small residual.
        let mut mean = vec![0.0; cfg.segments];
        let mut swing: f64 = 0.0;
        let samples = 4000;
        for _ in 0..samples {
            tether.step(&env).unwrap();
            for (k, m) in mean.iter_mut().enumerate() {
                let tilt = tilt_from_vertical(tether.state(), k);
                *m += tilt / samples as f64;
                swing = swing.max((tilt - expected).abs());
            }
        }
        assert!(swing < 1e-3, "a = {a}: still swinging by {swing} rad");
        for (k, tilt) in mean.iter().enumerate() {
            assert!(
                (tilt - expected).abs() < 1e-5,
                "a = {a}: segment {k} at {tilt} rad on average, expected {expected}"
            );
        }
        eprintln!("a = {a} m/s^2: mean tilt {:.8} rad, atan(a/g) = {expected:.8} rad, residual swing {swing:.1e} rad", mean[0]);
    }
}

#[test]
fn chain_tension_from_newton_matches_the_axial_element() {
    let mut rng = SplitMix(11);
    for _ in 0..30 {
        let n = 1 + (rng.next() * 40.0) as usize;
        let cfg = TetherConfig {
            segments: n,
            tip_mass: rng.range(0.0, 100.0),
            ..TetherConfig::table3()
        };
        let (cfg, mut flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
        flow.frame_acceleration = Vector3::new(rng.range(-2.0, 2.0), 0.0, 0.0);
        let mut q = vec![rng.range(0.0, 0.05)];
        let mut qd = vec![rng.range(-0.5, 0.5)];
        for _ in 0..n {
            q.extend([rng.range(-0.3, 1.5), rng.range(-0.5, 0.5)]);
            qd.extend([rng.range(-0.3, 0.3), rng.range(-0.3, 0.3)]);
        }
        let mut model = TetherModel::new(&cfg).unwrap();
        let mut qdd = vec![0.0; cfg.dofs()];
        let mut tension = vec![0.0; n + 1];
        model
            .tensions(0.0, &q, &qd, &flow, &mut qdd, &mut tension)
            .unwrap();
        let axial = cfg.axial_stiffness * q[0] + cfg.axial_damping() * qd[0];
        assert!(
            (tension[0] - axial).abs() < 1e-8 * axial.abs().max(1.0),
            "Newton gives {} N at the attachment, the element {axial} N",
            tension[0]
        );
    }
}

/// Simulates `config` towed with the stand-in body from straight trailing for `seconds`; returns
/// the tip depth history (one sample per 0.1 s) and the final tether.
fn settle(config: &TetherConfig, seconds: f64) -> (Vec<f64>, Tether) {
    let (cfg, flow) = reference::towed(config, reference::StandInBody::accd()).unwrap();
    let mut tether = Tether::new(&cfg).unwrap();
    let mut depth = vec![];
    let per_sample = (0.1 / cfg.time_step).round() as usize;
    while tether.state().time < seconds - 1e-9 {
        tether.step_many(per_sample, &flow).unwrap();
        depth.push(tether.tip_state().0.z);
    }
    (depth, tether)
}

/// Time after which the depth stays within `band` (m) of its final value.
fn settling_time(depth: &[f64], band: f64) -> f64 {
    let last = depth[depth.len() - 1];
    let i = depth
        .iter()
        .rposition(|z| (z - last).abs() > band)
        .map_or(0, |i| i + 1);
    i as f64 * 0.1
}

#[test]
fn table3_tether_settles_behind_the_aircraft() {
    let (depth, mut tether) = settle(&TetherConfig::table3(), 120.0);
    let final_depth = depth[depth.len() - 1];
    let settle_2pct = settling_time(&depth, 0.02 * final_depth);
    let (tip, tip_vel) = tether.tip_state();
    let (cfg, flow) = reference::towed_table3();
    let mut tension = vec![0.0; cfg.segments + 1];
    tether.tensions(&flow, &mut tension).unwrap();
    eprintln!(
        "Table 3 towed: tip at ({:.2}, {:.2}, {:.2}) m, depth {final_depth:.2} m (paper: about 50 m), \
         within 2 % after {settle_2pct:.1} s (paper: vibrations damped in about 40 s), \
         tension {:.0} N at the attachment, {:.0} N at the tip",
        tip.x, tip.y, tip.z, tension[0], tension[cfg.segments]
    );
    // Steady: the tip no longer moves.
    assert!(
        tip_vel.norm() < 1e-3,
        "tip still moving at {} m/s",
        tip_vel.norm()
    );
    assert!(depth[depth.len() - 200..]
        .iter()
        .all(|z| (z - final_depth).abs() < 1e-3));
    // The expected settling (docs/paper-reproduction.md): about 50 m below the aircraft (within 15 %), damped in about 40 s.
    assert!(
        (final_depth / 50.0 - 1.0).abs() < 0.15,
        "depth {final_depth}"
    );
    assert!(settle_2pct < 60.0, "took {settle_2pct} s to settle");
    // Tension grows monotonically from the tip towards the aircraft (drag and weight accumulate).
    assert!(tension.windows(2).all(|w| w[0] >= w[1]), "{tension:?}");
}

#[test]
fn steel_settles_deeper_and_longer_tethers_deeper() {
    let depth_of = |name: &str| {
        let (depth, _) = settle(&TetherConfig::preset(name).unwrap(), 120.0);
        (
            depth[depth.len() - 1],
            settling_time(&depth, 0.02 * depth[depth.len() - 1]),
        )
    };
    let (uhmwpe, uhmwpe_settle) = depth_of("uhmwpe-250m-24mm");
    let (steel, steel_settle) = depth_of("steel-250m-24mm");
    let (long, _) = depth_of("uhmwpe-300m-24mm");
    eprintln!(
        "settled depth: uhmwpe 250 m {uhmwpe:.1} m in {uhmwpe_settle:.1} s, steel {steel:.1} m in {steel_settle:.1} s, \
         uhmwpe 300 m {long:.1} m"
    );
    // The expected settling: steel more than 100 m below and oscillating longer; 300 m about 70 m.
    assert!(steel > 100.0);
    assert!(steel_settle > uhmwpe_settle);
    assert!((long / 70.0 - 1.0).abs() < 0.15, "300 m tether at {long} m");
}
