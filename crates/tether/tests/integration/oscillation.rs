//! Small oscillations against closed-form results.
//!
//! * One segment swings as a compound pendulum: period 2 pi sqrt(2 l / (3 g)).
//! * A hanging chain's lowest frequency converges to Bernoulli's continuous result
//!   (j01 / 2) sqrt(g / L) as n grows, j01 the first zero of the Bessel function J0.

use crate::common;

use accd_tether::{reference, Tether, TetherConfig, TetherModel, TetherState, Vacuum};
use common::upward_crossings;
use nalgebra::{DMatrix, Vector3};
use std::f64::consts::{FRAC_PI_2, PI};

/// First zero of the Bessel function J0.
const J01: f64 = 2.404_825_557_695_773;

/// An undamped chain in vacuum without bending stiffness or tip mass, stiff axially so that
/// stretching changes lengths by less than 1e-5.
fn bare_chain(segments: usize, length: f64) -> TetherConfig {
    TetherConfig {
        segments,
        length,
        mass_per_length: 1.0 / length,
        axial_stiffness: 1e6,
        axial_damping_per_mass: 0.0,
        flexural_rigidity: 0.0,
        joint_damping_per_mass: 0.0,
        normal_drag_coefficient: 0.0,
        tangential_drag_coefficient: 0.0,
        tip_mass: 0.0,
        ..TetherConfig::table3()
    }
}

#[test]
fn single_segment_is_a_compound_pendulum() {
    let l = 2.0;
    let cfg = TetherConfig {
        time_step: 2e-4,
        ..bare_chain(1, l)
    };
    let g = cfg.gravity;
    let expected = 2.0 * PI * (2.0 * l / (3.0 * g)).sqrt();
    let amplitude = 0.01;
    let s_eq = cfg.total_mass() * g / cfg.axial_stiffness;
    let st = TetherState::from_angles(&[FRAC_PI_2 + amplitude], &[0.0], &[0.0], &[0.0], s_eq, 0.0)
        .unwrap();
    let mut tether = Tether::new(&cfg).unwrap();
    tether.set_state(st).unwrap();
    let (mut times, mut values) = (vec![], vec![]);
    while tether.state().time < 6.0 * expected {
        tether.step(&Vacuum).unwrap();
        times.push(tether.state().time);
        values.push(tether.state().q[1] - FRAC_PI_2);
    }
    let crossings = upward_crossings(&times, &values);
    assert!(crossings.len() >= 5);
    let period = (crossings[crossings.len() - 1] - crossings[0]) / (crossings.len() - 1) as f64;
    let error = period / expected - 1.0;
    eprintln!(
        "compound pendulum: period {period:.6} s, closed form {expected:.6} s, error {error:.2e}"
    );
    assert!(error.abs() < 1e-3, "period {period} vs {expected}");
}

/// Lowest angular frequency of small oscillations about the hanging equilibrium, from the
/// model's linearisation: K = -M dq''/dq by central differences, then the generalized symmetric
/// eigenproblem K v = w^2 M v.
fn lowest_frequency(cfg: &TetherConfig) -> f64 {
    let mut model = TetherModel::new(cfg).unwrap();
    let s_eq = (cfg.total_mass() + cfg.tip_mass) * cfg.gravity / cfg.axial_stiffness;
    let q0 = TetherState::straight(cfg.segments, reference::hanging_direction(), s_eq)
        .unwrap()
        .q;
    let dim = cfg.dofs();
    let zeros = vec![0.0; dim];
    let mut acc = vec![0.0; dim];
    model
        .accelerations(0.0, &q0, &zeros, &Vacuum, &mut acc)
        .unwrap();
    assert!(
        acc.iter().all(|a| a.abs() < 1e-9),
        "the straight hanging chain is an equilibrium"
    );
    let h = 1e-7;
    let mut jac = DMatrix::zeros(dim, dim);
    let (mut ap, mut am) = (vec![0.0; dim], vec![0.0; dim]);
    for j in 0..dim {
        let mut qp = q0.clone();
        let mut qm = q0.clone();
        qp[j] += h;
        qm[j] -= h;
        model
            .accelerations(0.0, &qp, &zeros, &Vacuum, &mut ap)
            .unwrap();
        model
            .accelerations(0.0, &qm, &zeros, &Vacuum, &mut am)
            .unwrap();
        for i in 0..dim {
            jac[(i, j)] = (ap[i] - am[i]) / (2.0 * h);
        }
    }
    let mass = model.mass_matrix(&q0).unwrap();
    let stiffness = -(&mass * jac);
    let stiffness = (&stiffness + stiffness.transpose()) * 0.5;
    let l = mass.cholesky().unwrap().l();
    let l_inv = l.try_inverse().unwrap();
    let reduced = &l_inv * stiffness * l_inv.transpose();
    let reduced = (&reduced + reduced.transpose()) * 0.5;
    let w2 = reduced.symmetric_eigenvalues().min();
    assert!(w2 > 0.0);
    w2.sqrt()
}

#[test]
fn hanging_chain_converges_to_bernoulli() {
    let length = 250.0;
    let g = TetherConfig::table3().gravity;
    let bernoulli = 0.5 * J01 * (g / length).sqrt();
    let mut last = f64::INFINITY;
    for n in [2, 5, 10, 20, 30] {
        let cfg = TetherConfig {
            axial_stiffness: 1e9,
            ..bare_chain(n, length)
        };
        let error = lowest_frequency(&cfg) / bernoulli - 1.0;
        eprintln!("hanging chain n = {n:2}: relative frequency error {error:.3e}");
        assert!(error.abs() < last, "error must shrink as n grows");
        last = error.abs();
        if n == 30 {
            assert!(error.abs() < 1e-3);
        }
    }
}

#[test]
fn hanging_chain_oscillates_at_its_linear_frequency_in_time() {
    // The time-domain check of the same claim: a 10-segment chain released in its first mode
    // shape swings at the frequency the linearisation predicts.
    let cfg = TetherConfig {
        time_step: 1e-3,
        ..bare_chain(10, 10.0)
    };
    let w = lowest_frequency(&cfg);
    let n = cfg.segments;
    // Mode shape of the continuous chain, sampled: lateral displacement J0(2 w sqrt(x/g)), x
    // measured up from the free end; segment slopes from its differences, small amplitude.
    let g = cfg.gravity;
    let l = cfg.segment_length();
    let shape = |depth: f64| bessel_j0(2.0 * w * ((cfg.length - depth) / g).sqrt());
    let slopes: Vec<f64> = (0..n)
        .map(|k| 0.005 * (shape((k + 1) as f64 * l) - shape(k as f64 * l)) / l)
        .collect();
    let dirs: Vec<Vector3<f64>> = slopes
        .iter()
        .map(|sl| Vector3::new(-sl, 0.0, 1.0))
        .collect();
    let s_eq = cfg.total_mass() * g / cfg.axial_stiffness;
    let st = TetherState::from_directions(&dirs, &vec![Vector3::zeros(); n], s_eq, 0.0).unwrap();
    let mut tether = Tether::new(&cfg).unwrap();
    tether.set_state(st).unwrap();
    let (mut times, mut xs) = (vec![], vec![]);
    let period = 2.0 * PI / w;
    while tether.state().time < 5.0 * period {
        tether.step(&Vacuum).unwrap();
        times.push(tether.state().time);
        xs.push(tether.tip_state().0.x);
    }
    let c = upward_crossings(&times, &xs);
    let measured = (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
    eprintln!("hanging chain n = 10: period {measured:.5} s in time, {period:.5} s linearised");
    assert!((measured / period - 1.0).abs() < 2e-3);
}

/// J0 by its power series (converges quickly for the arguments used here, x < 3).
fn bessel_j0(x: f64) -> f64 {
    let mut term = 1.0;
    let mut sum = 1.0;
    for k in 1..40 {
        term *= -(x * x / 4.0) / (k as f64 * k as f64);
        sum += term;
    }
    sum
}
