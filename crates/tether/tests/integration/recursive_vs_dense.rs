//! The O(n) recursive solver against the dense formulation (the oracle): accelerations and
//! tensions at random states, including near-folded joints, with the tip mass, aerodynamics, a
//! tip force and a frame acceleration on, for n = 1 ... 300; and trajectories of Table 3's towed
//! tether over 10 s.
//!
//! Measure: for each state, `max_i |qdd_rec_i - qdd_dense_i| / max_i |qdd_dense_i|` over all
//! 2n + 1 generalized accelerations (and the same over the angle accelerations alone, so that a
//! large elongation acceleration cannot hide errors in the angles).

use crate::common;

use accd_tether::direction::{angles, direction};
use accd_tether::{reference, Solver, Tether, TetherConfig, TetherModel, UniformFlow};
use common::{SplitMix, V3};
use nalgebra::Vector3;

/// Table 3's tether with `n` segments and the stand-in ACCD at the tip, towed at 185 m/s, with a
/// frame acceleration, a side wind and a constant tip force added so that every term is on.
fn towed(n: usize) -> (TetherConfig, UniformFlow) {
    let cfg = TetherConfig {
        segments: n,
        ..TetherConfig::table3()
    };
    let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
    let flow = UniformFlow {
        velocity: flow.velocity + Vector3::new(0.0, 7.0, -3.0),
        frame_acceleration: Vector3::new(1.5, -0.7, -2.0),
        tip_force: Vector3::new(-40.0, 25.0, 60.0),
        ..flow
    };
    (cfg, flow)
}

/// A random direction at most 70 degrees out of the vertical plane.
fn random_direction(rng: &mut SplitMix) -> V3 {
    direction(rng.range(-3.1, 3.1), rng.range(-1.2, 1.2))
}

/// `e` turned by `angle` about a random axis normal to it.
fn turned(rng: &mut SplitMix, e: V3, angle: f64) -> V3 {
    let helper = if e.x.abs() < 0.9 { V3::x() } else { V3::y() };
    let u = e.cross(&helper).normalize();
    let v = e.cross(&u);
    let a = rng.range(0.0, std::f64::consts::TAU);
    let axis = u * a.cos() + v * a.sin();
    e * angle.cos() + axis.cross(&e) * angle.sin()
}

/// A random state: elongation, directions (a third of the joints folded to 170-179 degrees, the
/// rest bent by up to 60 degrees), and rates.
fn random_state(rng: &mut SplitMix, n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut q = vec![rng.range(-0.02, 0.3)];
    let mut qd = vec![rng.range(-2.0, 2.0)];
    let mut e = random_direction(rng);
    for k in 0..n {
        if k > 0 {
            e = if rng.next() < 0.33 {
                let gap = rng.range(1.0, 10.0).to_radians();
                turned(rng, -e, gap)
            } else {
                let bend = rng.range(0.0, 60.0).to_radians();
                turned(rng, e, bend)
            };
            // Stay away from the chart's singular (lateral) axis.
            if e.y.abs() > 0.95 {
                e = random_direction(rng);
            }
        }
        let (phi, psi) = angles(&e);
        q.extend([phi, psi]);
        qd.extend([rng.range(-1.5, 1.5), rng.range(-1.5, 1.5)]);
    }
    (q, qd)
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |a, b| a.max(b.abs()))
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

#[test]
fn accelerations_and_tensions_match_dense() {
    let mut rng = SplitMix(0x5EED_0004);
    for &n in &[1usize, 2, 3, 5, 10, 30, 100, 300] {
        let (cfg, flow) = towed(n);
        let mut rec = TetherModel::new(&cfg).unwrap();
        let mut dense = TetherModel::new(&cfg).unwrap();
        dense.set_solver(Solver::Dense);
        assert_eq!(rec.solver(), Solver::Recursive);
        let dim = cfg.dofs();
        let cases = if n >= 100 { 6 } else { 40 };
        let (mut worst, mut worst_angles, mut worst_tension) = (0.0f64, 0.0f64, 0.0f64);
        for case in 0..cases {
            let (q, qd) = random_state(&mut rng, n);
            let t = 0.1 * case as f64;
            let (mut a_rec, mut a_dense) = (vec![0.0; dim], vec![0.0; dim]);
            rec.accelerations(t, &q, &qd, &flow, &mut a_rec).unwrap();
            dense
                .accelerations(t, &q, &qd, &flow, &mut a_dense)
                .unwrap();
            let err = max_diff(&a_rec, &a_dense) / max_abs(&a_dense);
            let err_angles = max_diff(&a_rec[1..], &a_dense[1..]) / max_abs(&a_dense[1..]);
            assert!(
                err <= 1e-9 && err_angles <= 1e-9,
                "n = {n}, case {case}: relative difference {err:e} (angles {err_angles:e})"
            );
            worst = worst.max(err);
            worst_angles = worst_angles.max(err_angles);

            // The explicit entry points agree with the configured ones.
            let mut a = vec![0.0; dim];
            dense
                .accelerations_recursive(t, &q, &qd, &flow, &mut a)
                .unwrap();
            assert_eq!(a, a_rec);
            rec.accelerations_dense(t, &q, &qd, &flow, &mut a).unwrap();
            assert_eq!(a, a_dense);

            let (mut t_rec, mut t_dense) = (vec![0.0; n + 1], vec![0.0; n + 1]);
            rec.tensions(t, &q, &qd, &flow, &mut a, &mut t_rec).unwrap();
            assert_eq!(a, a_rec, "tensions write the same accelerations");
            dense
                .tensions(t, &q, &qd, &flow, &mut a, &mut t_dense)
                .unwrap();
            let err_t = max_diff(&t_rec, &t_dense) / max_abs(&t_dense);
            assert!(
                err_t <= 1e-9,
                "n = {n}, case {case}: tensions differ by {err_t:e}"
            );
            worst_tension = worst_tension.max(err_t);
        }
        eprintln!(
            "n = {n:3}: max relative difference of accelerations {worst:.2e} (angles alone \
             {worst_angles:.2e}), of tensions {worst_tension:.2e}"
        );
    }
}

#[test]
fn table3_trajectories_agree_over_10_s() {
    let (cfg, flow) = reference::towed_table3();
    let mut rec = Tether::new(&cfg).unwrap();
    let mut dense = Tether::new(&cfg).unwrap();
    dense.model_mut().set_solver(Solver::Dense);
    let steps = (10.0 / cfg.time_step).round() as usize;
    let (mut worst_tip, mut worst_q) = (0.0f64, 0.0f64);
    let mut travel = 0.0f64;
    let start = rec.tip_state().0;
    for _ in 0..steps {
        rec.step(&flow).unwrap();
        dense.step(&flow).unwrap();
        let (pr, pd) = (rec.tip_state().0, dense.tip_state().0);
        worst_tip = worst_tip.max((pr - pd).norm());
        worst_q = worst_q.max(max_diff(&rec.state().q, &dense.state().q));
        travel = travel.max((pd - start).norm());
    }
    eprintln!(
        "10 s of Table 3's towed tether: tip positions within {worst_tip:.2e} m (the tip moved \
         {travel:.1} m), coordinates within {worst_q:.2e}"
    );
    assert!(travel > 10.0, "the test must move the tether: {travel} m");
    assert!(worst_tip < 1e-6, "tip positions differ by {worst_tip:e} m");
    assert!(worst_q < 1e-8, "coordinates differ by {worst_q:e}");
}
