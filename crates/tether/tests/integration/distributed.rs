//! The distributed elasticity (`elasticity: "distributed"`, an element of stiffness n k and
//! damping n c_s in every segment): its O(n) solver against the dense formulation, its mass
//! matrix against the kinetic energy of independently written geometry, and its physics against
//! closed forms that do not come from this code:
//!
//! * a tether hanging under its own weight stretches by `(n + 1) / (2n) M g / k` (each element
//!   carries the weight below it), which tends to the continuum's `M g / (2k)`: half the stretch of
//!   the same weight at the tip (the attachment model's `M g / k`);
//! * the first longitudinal mode of a fixed-free bar with a tip mass, `omega = beta c / L` with
//!   `beta tan beta = m_bar / m_tip` and the wave speed `c = sqrt(EA / mu)`, `EA = k L`;
//! * energy is conserved without damping;
//! * the distributed model tends to the attachment model as the stiffness grows.

use crate::common;

use accd_tether::direction::{angles, direction};
use accd_tether::{
    reference, Elasticity, Solver, Tether, TetherConfig, TetherModel, TetherState, UniformFlow,
    Vacuum,
};
use common::{SplitMix, V3};
use nalgebra::{DMatrix, Vector3};

fn distributed(cfg: TetherConfig) -> TetherConfig {
    TetherConfig {
        elasticity: Elasticity::Distributed,
        ..cfg
    }
}

/// Table 3's tether (distributed) with `n` segments and the stand-in ACCD at the tip, towed,
/// with a frame acceleration, side wind and tip force so that every term is on.
fn towed(n: usize) -> (TetherConfig, UniformFlow) {
    let cfg = distributed(TetherConfig {
        segments: n,
        ..TetherConfig::table3()
    });
    let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
    let flow = UniformFlow {
        velocity: flow.velocity + Vector3::new(0.0, 7.0, -3.0),
        frame_acceleration: Vector3::new(1.5, -0.7, -2.0),
        tip_force: Vector3::new(-40.0, 25.0, 60.0),
        ..flow
    };
    (cfg, flow)
}

/// A random distributed state (3n): stretches, directions bent by up to 60 degrees, rates.
fn random_state(rng: &mut SplitMix, n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut q = vec![rng.range(-0.02, 0.1)];
    let mut qd = vec![rng.range(-1.0, 1.0)];
    let mut e = direction(rng.range(-3.1, 3.1), rng.range(-1.0, 1.0));
    for k in 0..n {
        if k > 0 {
            let helper = if e.x.abs() < 0.9 { V3::x() } else { V3::y() };
            let axis = e.cross(&helper).normalize();
            let bend = rng.range(0.0, 60.0).to_radians();
            e = (e * bend.cos() + axis.cross(&e) * bend.sin()).normalize();
            if e.y.abs() > 0.95 {
                e = direction(rng.range(-3.1, 3.1), rng.range(-1.0, 1.0));
            }
        }
        let (phi, psi) = angles(&e);
        q.extend([phi, psi]);
        qd.extend([rng.range(-1.5, 1.5), rng.range(-1.5, 1.5)]);
    }
    for _ in 1..n {
        q.push(rng.range(-0.01, 0.05));
        qd.push(rng.range(-0.5, 0.5));
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

/// Stretch of segment k in the distributed layout, written from the layout's definition.
fn stretch(n: usize, q: &[f64], k: usize) -> f64 {
    if k == 0 {
        q[0]
    } else {
        q[2 * n + k]
    }
}

/// Centres, directions and tip of a distributed state, straight from the geometry: segment k's
/// rod starts s_k beyond the end of segment k - 1.
fn positions(cfg: &TetherConfig, q: &[f64]) -> (Vec<V3>, Vec<V3>, V3) {
    let (n, l) = (cfg.segments, cfg.segment_length());
    let mut p = V3::zeros();
    let (mut centres, mut dirs) = (Vec::new(), Vec::new());
    for k in 0..n {
        let e = direction(q[1 + 2 * k], q[2 + 2 * k]);
        p += e * stretch(n, q, k);
        centres.push(p + e * (0.5 * l));
        dirs.push(e);
        p += e * l;
    }
    (centres, dirs, p)
}

#[test]
fn config_option_parses_defaults_and_rejects_unknown_values() {
    let default = TetherConfig::table3();
    assert_eq!(default.elasticity, Elasticity::Attachment);
    assert!(
        !default.to_json().contains("elasticity"),
        "the default serializes as before"
    );
    let d = TetherConfig::from_json(r#"{"elasticity": "distributed", "segments": 7}"#).unwrap();
    assert_eq!(d.elasticity, Elasticity::Distributed);
    assert_eq!(d.dofs(), 21);
    assert_eq!(TetherConfig::from_json(&d.to_json()).unwrap(), d);
    assert!((d.element_stiffness() - 7.0 * d.axial_stiffness).abs() < 1e-6);
    let err = TetherConfig::from_json(r#"{"elasticity": "everywhere"}"#)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("`elasticity`") && err.contains("everywhere") && err.contains("distributed"),
        "{err}"
    );
    let model = TetherModel::new(&d).unwrap();
    assert_eq!(model.dofs(), 21);
    let tether = Tether::new(&distributed(TetherConfig::table1())).unwrap();
    assert_eq!(tether.state().q.len(), 12);
}

/// The O(n) recursion against the dense mass matrix and Cholesky, accelerations and tensions.
#[test]
fn recursive_matches_dense() {
    let mut rng = SplitMix(0xD157_0001);
    for &n in &[1usize, 2, 3, 5, 10, 30, 100] {
        let (cfg, flow) = towed(n);
        let mut rec = TetherModel::new(&cfg).unwrap();
        let mut dense = TetherModel::new(&cfg).unwrap();
        dense.set_solver(Solver::Dense);
        let dim = cfg.dofs();
        let (mut worst, mut worst_t) = (0.0f64, 0.0f64);
        for case in 0..if n >= 100 { 4 } else { 20 } {
            let (q, qd) = random_state(&mut rng, n);
            let t = 0.1 * case as f64;
            let (mut a_rec, mut a_dense) = (vec![0.0; dim], vec![0.0; dim]);
            rec.accelerations(t, &q, &qd, &flow, &mut a_rec).unwrap();
            dense
                .accelerations(t, &q, &qd, &flow, &mut a_dense)
                .unwrap();
            let err = max_diff(&a_rec, &a_dense) / max_abs(&a_dense);
            assert!(err <= 1e-10, "n = {n}, case {case}: {err:e}");
            worst = worst.max(err);
            // Tensions: the recursion's P_k . e_k against the elements' own n k s + n c s'.
            let (mut t_rec, mut t_dense) = (vec![0.0; n + 1], vec![0.0; n + 1]);
            let mut a = vec![0.0; dim];
            rec.tensions(t, &q, &qd, &flow, &mut a, &mut t_rec).unwrap();
            assert_eq!(a, a_rec);
            dense
                .tensions(t, &q, &qd, &flow, &mut a, &mut t_dense)
                .unwrap();
            let err_t = max_diff(&t_rec, &t_dense) / max_abs(&t_dense);
            assert!(err_t <= 1e-9, "n = {n}, case {case}: tensions {err_t:e}");
            worst_t = worst_t.max(err_t);
        }
        eprintln!("n = {n:3}: accelerations {worst:.2e}, tensions {worst_t:.2e}");
    }
}

/// 1/2 v^T M(q) v equals the kinetic energy from central differences of the independently
/// written positions.
#[test]
fn mass_matrix_is_the_kinetic_energy_of_the_geometry() {
    let mut rng = SplitMix(0xD157_0002);
    for &n in &[1usize, 3, 8] {
        let cfg = distributed(TetherConfig {
            segments: n,
            tip_mass: 7.0,
            ..TetherConfig::table1()
        });
        let mut model = TetherModel::new(&cfg).unwrap();
        let (m, l) = (cfg.segment_mass(), cfg.segment_length());
        for _ in 0..5 {
            let (q, v) = random_state(&mut rng, n);
            let mass = model.mass_matrix(&q).unwrap();
            let vv = DMatrix::from_column_slice(v.len(), 1, &v);
            let t_model = 0.5 * (vv.transpose() * &mass * &vv)[(0, 0)];
            let h = 1e-6;
            let plus: Vec<f64> = q.iter().zip(&v).map(|(a, b)| a + h * b).collect();
            let minus: Vec<f64> = q.iter().zip(&v).map(|(a, b)| a - h * b).collect();
            let (cp, ep, tp) = positions(&cfg, &plus);
            let (cm, em, tm) = positions(&cfg, &minus);
            let mut t_fd = 0.5 * cfg.tip_mass * ((tp - tm) / (2.0 * h)).norm_squared();
            for k in 0..n {
                t_fd += 0.5 * m * ((cp[k] - cm[k]) / (2.0 * h)).norm_squared();
                t_fd += 0.5 * m * l * l / 12.0 * ((ep[k] - em[k]) / (2.0 * h)).norm_squared();
            }
            let rel = (t_model - t_fd).abs() / t_fd;
            assert!(rel < 1e-7, "n = {n}: {t_model} vs {t_fd} ({rel:e})");
            // And the model's own energy and tip agree with the geometry.
            let e = model.energy(&q, &v).unwrap();
            assert!((e.kinetic - t_model).abs() <= 1e-9 * t_model);
            let (tip, _) = model.tip_state(&q, &v).unwrap();
            assert!((tip - positions(&cfg, &q).2).norm() < 1e-12);
        }
    }
}

/// The stretches of the elements of a vertical tether hanging at rest: element k carries the
/// weight of segments k ... n and the tip.
fn hanging_stretches(cfg: &TetherConfig) -> Vec<f64> {
    let n = cfg.segments;
    (0..n)
        .map(|k| {
            let below = cfg.segment_mass() * (n - k) as f64 + cfg.tip_mass;
            below * cfg.gravity / cfg.element_stiffness()
        })
        .collect()
}

fn vertical_state(cfg: &TetherConfig, stretches: &[f64]) -> TetherState {
    let n = cfg.segments;
    let straight = TetherState::straight(n, reference::hanging_direction(), stretches[0]).unwrap();
    let mut st = straight.to_distributed().unwrap();
    for (k, s) in stretches.iter().enumerate().skip(1) {
        st.q[2 * n + k] = *s;
    }
    st
}

/// Hanging under its own weight: the closed-form stretches are an equilibrium, the total tends to
/// half the tip-load stretch, and a damped release from unstretched settles onto it.
#[test]
fn hanging_tether_stretches_half_as_much_as_its_weight_at_the_tip() {
    for &n in &[4usize, 30, 300] {
        let cfg = distributed(TetherConfig {
            segments: n,
            ..TetherConfig::table1()
        });
        let s = hanging_stretches(&cfg);
        let st = vertical_state(&cfg, &s);
        let mut model = TetherModel::new(&cfg).unwrap();
        let mut qdd = vec![0.0; cfg.dofs()];
        model
            .accelerations(0.0, &st.q, &st.qd, &Vacuum, &mut qdd)
            .unwrap();
        let g = cfg.gravity;
        assert!(max_abs(&qdd) < 1e-9 * g, "n = {n}: {:e}", max_abs(&qdd));
        let total: f64 = s.iter().sum();
        let weight_at_tip = cfg.total_mass() * g / cfg.axial_stiffness;
        let ratio = total / weight_at_tip;
        let expected = (n as f64 + 1.0) / (2.0 * n as f64);
        assert!((ratio - expected).abs() < 1e-12, "n = {n}: {ratio}");
        assert!((ratio - 0.5).abs() <= 0.5 / n as f64 + 1e-12);
        eprintln!("n = {n}: stretch / (M g / k) = {ratio:.6}");
    }
    // Released unstretched, Table 1's damping settles it onto the closed form.
    let cfg = distributed(TetherConfig {
        time_step: 0.002,
        ..TetherConfig::table1()
    });
    let n = cfg.segments;
    let mut tether = Tether::new(&cfg).unwrap();
    tether
        .set_state(vertical_state(&cfg, &vec![0.0; n]))
        .unwrap();
    for _ in 0..2500 {
        tether.step(&Vacuum).unwrap();
    }
    let q = &tether.state().q;
    let expected = hanging_stretches(&cfg);
    for (k, want) in expected.iter().enumerate() {
        let got = stretch(n, q, k);
        assert!(
            (got - want).abs() < 1e-6 * want,
            "segment {k}: {got} vs {want}"
        );
    }
    // The attachment model carries the same weight on one element: M g / k.
    let mut att = Tether::new(&TetherConfig {
        time_step: 0.002,
        ..TetherConfig::table1()
    })
    .unwrap();
    att.set_state(TetherState::straight(n, reference::hanging_direction(), 0.0).unwrap())
        .unwrap();
    for _ in 0..2500 {
        att.step(&Vacuum).unwrap();
    }
    let att_s = att.state().q[0];
    let want = cfg.total_mass() * cfg.gravity / cfg.axial_stiffness;
    assert!((att_s - want).abs() < 1e-6 * want, "{att_s} vs {want}");
}

/// Root of beta tan beta = r in (0, pi/2) by bisection.
fn first_beta(r: f64) -> f64 {
    let (mut lo, mut hi) = (0.0f64, std::f64::consts::FRAC_PI_2);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid * mid.tan() < r {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The lowest axial angular frequency of the straight chain: the generalized eigenvalue of the
/// element stiffnesses against the stretch block of the mass matrix (for a straight chain at rest
/// the stretches decouple from the angles).
fn lowest_axial_frequency(cfg: &TetherConfig) -> f64 {
    let n = cfg.segments;
    let mut model = TetherModel::new(cfg).unwrap();
    let st = TetherState::straight(n, reference::hanging_direction(), 0.0)
        .unwrap()
        .to_distributed()
        .unwrap();
    let mass = model.mass_matrix(&st.q).unwrap();
    let idx: Vec<usize> = (0..n).map(|k| if k == 0 { 0 } else { 2 * n + k }).collect();
    let mss = DMatrix::from_fn(n, n, |r, c| mass[(idx[r], idx[c])]);
    // Symmetric form: K^-1/2 M K^-1/2 with K = k_e 1 has eigenvalues 1 / omega^2.
    let ev = (mss / cfg.element_stiffness()).symmetric_eigenvalues();
    1.0 / ev.max().sqrt()
}

/// The first longitudinal mode of a fixed-free bar with a tip mass (closed form), at growing n:
/// the discrete chain converges to it at first order.
#[test]
fn first_longitudinal_mode_matches_the_fixed_free_bar() {
    let base = distributed(TetherConfig {
        gravity: 0.0,
        ..TetherConfig::table1()
    });
    let c_wave = (base.axial_stiffness * base.length / base.mass_per_length).sqrt();
    for &tip_ratio in &[0.0f64, 0.5, 1.0, 4.0] {
        let m_bar = base.total_mass();
        let beta = if tip_ratio == 0.0 {
            std::f64::consts::FRAC_PI_2
        } else {
            first_beta(1.0 / tip_ratio)
        };
        let exact = beta * c_wave / base.length;
        let mut prev = f64::INFINITY;
        for &n in &[10usize, 40, 160] {
            let cfg = TetherConfig {
                segments: n,
                tip_mass: tip_ratio * m_bar,
                ..base.clone()
            };
            let omega = lowest_axial_frequency(&cfg);
            if tip_ratio == 0.0 {
                // The discrete chain's own closed form (n equal masses, n equal springs, fixed-free).
                let chain = 2.0
                    * (cfg.element_stiffness() / cfg.segment_mass()).sqrt()
                    * (std::f64::consts::PI / (4 * n + 2) as f64).sin();
                assert!((omega - chain).abs() < 1e-10 * chain, "{omega} vs {chain}");
            }
            let err = (omega - exact).abs() / exact;
            eprintln!("m_tip / m_bar = {tip_ratio}, n = {n}: relative error {err:.2e}");
            // Each rod's mass moves with its base, beyond its element (the last one at the free
            // end): a lumping of first order, error 1 / (2n + 1) without tip mass (the chain's
            // omega = 2 sqrt(k_e / m) sin(pi / (4n + 2))), less with one.
            assert!(err < 0.55 / n as f64, "n = {n}: {err:e}");
            assert!(
                err < prev / 3.5,
                "first-order convergence: {err:e} after {prev:e}"
            );
            prev = err;
        }
    }
    // In the time domain: a free axial oscillation of the undamped chain (no gravity) has that
    // period. Released from the first mode's static-load shape (a tip pull relaxed at t = 0).
    let n = 20;
    let cfg = TetherConfig {
        segments: n,
        tip_mass: base.total_mass(),
        axial_damping_per_mass: 0.0,
        joint_damping_per_mass: 0.0,
        time_step: 2e-4,
        ..base.clone()
    };
    let omega = lowest_axial_frequency(&cfg);
    let exact = first_beta(1.0) * c_wave / cfg.length;
    let mut tether = Tether::new(&cfg).unwrap();
    let pull = 0.01 * cfg.element_stiffness();
    tether
        .set_state(vertical_state(
            &cfg,
            &vec![pull / cfg.element_stiffness(); n],
        ))
        .unwrap();
    let (mut times, mut values) = (Vec::new(), Vec::new());
    for _ in 0..(4.0 * std::f64::consts::TAU / omega / cfg.time_step) as usize {
        tether.step(&Vacuum).unwrap();
        times.push(tether.state().time);
        values.push(tether.tip_state().0.z - cfg.length);
    }
    let crossings = common::upward_crossings(&times, &values);
    assert!(crossings.len() >= 3, "{crossings:?}");
    let period = (crossings[crossings.len() - 1] - crossings[0]) / (crossings.len() - 1) as f64;
    let measured = std::f64::consts::TAU / period;
    let rel = (measured - omega).abs() / omega;
    eprintln!(
        "time domain: omega {measured:.4} rad/s, eigenvalue {omega:.4}, bar {exact:.4} ({rel:.2e})"
    );
    assert!(rel < 1e-3, "{measured} vs {omega}");
    assert!((measured - exact).abs() / exact < 0.55 / n as f64);
}

/// Without damping or air, total energy (kinetic, gravity, the elements' strain, bending) stays
/// constant through a 3D swing released from phi = psi = pi/4 (the paper's Fig. 9(b) case).
#[test]
fn energy_is_conserved_without_damping() {
    let cfg = distributed(TetherConfig {
        flexural_rigidity: 5.0,
        axial_damping_per_mass: 0.0,
        joint_damping_per_mass: 0.0,
        time_step: 1e-3,
        ..TetherConfig::table1()
    });
    let n = cfg.segments;
    let d = direction(std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4);
    let st = TetherState::from_directions(&vec![d; n], &vec![Vector3::zeros(); n], 0.0, 0.0)
        .unwrap()
        .to_distributed()
        .unwrap();
    let mut tether = Tether::new(&cfg).unwrap();
    tether.set_state(st).unwrap();
    let e0 = tether.energy().total();
    let (mut dev, mut kin, mut strain) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..5000 {
        tether.step(&Vacuum).unwrap();
        let e = tether.energy();
        dev = dev.max((e.total() - e0).abs());
        kin = kin.max(e.kinetic);
        strain = strain.max(e.axial);
    }
    eprintln!(
        "drift {:.2e} of max kinetic {kin:.3} J (max strain {strain:.3e} J)",
        dev / kin
    );
    assert!(
        kin > 10.0 && strain > 1e-3,
        "the test must move and stretch"
    );
    assert!(dev < 1e-6 * kin, "drift {dev:e} of {kin}");
}

/// As the stiffness grows, the distributed and the attachment model approach each other (and
/// the inextensible chain): the tip's distance between them over a 1 s swing shrinks with 1/k.
#[test]
fn converges_to_the_attachment_model_as_the_stiffness_grows() {
    let mut prev = f64::INFINITY;
    for &k in &[1e5f64, 1e6, 1e7] {
        let att_cfg = TetherConfig {
            axial_stiffness: k,
            time_step: 1e-3,
            ..TetherConfig::table1()
        };
        let dis_cfg = distributed(att_cfg.clone());
        let n = att_cfg.segments;
        let d = direction(std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4);
        let st = TetherState::from_directions(&vec![d; n], &vec![Vector3::zeros(); n], 0.0, 0.0)
            .unwrap();
        let mut att = Tether::new(&att_cfg).unwrap();
        att.set_state(st.clone()).unwrap();
        let mut dis = Tether::new(&dis_cfg).unwrap();
        dis.set_state(st.to_distributed().unwrap()).unwrap();
        let mut gap = 0.0f64;
        for _ in 0..1000 {
            att.step(&Vacuum).unwrap();
            dis.step(&Vacuum).unwrap();
            gap = gap.max((att.tip_state().0 - dis.tip_state().0).norm());
        }
        eprintln!("k = {k:e}: max tip distance {gap:.3e} m");
        assert!(gap < prev / 5.0, "k = {k:e}: {gap:e} after {prev:e}");
        prev = gap;
    }
    assert!(prev < 1e-3);
}
