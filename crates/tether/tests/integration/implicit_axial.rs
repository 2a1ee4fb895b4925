//! The linearly implicit scheme (`scheme: "implicit_axial"`, ROS34PW2 with the axial
//! spring-dampers in its matrix) against closed forms and against the explicit RK4 at small
//! steps:
//!
//! * its stage solve is the dense augmented system `(M + gamma h c + (gamma h)^2 k) x = Q~`,
//!   assembled here from the model's mass matrix and accelerations;
//! * on a vertical chain the axial motion is linear (`M_ss s'' = -K s - C s' + weight`), and
//!   the scheme advances it by its own amplification matrix `R(h A)` exactly: written here from
//!   the published coefficients, for a resolved, an undamped and a stiff (k = 1e12 N/m) element,
//!   and for the 30 stiff elements of the distributed Table 3 tether;
//! * the static stretch of a hanging chain (`(n + 1) / (2n) M g / k` distributed, `M g / k` at
//!   the attachment) is reached without ringing;
//! * swings, the hanging chain's lowest mode and the towed equilibrium agree with explicit
//!   RK4 at small steps within stated tolerances;
//! * configurations the explicit scheme refuses for their axial stiffness are accepted.

use crate::common;

use accd_tether::direction::direction;
use accd_tether::{
    reference, AxialStage, Elasticity, Scheme, Solver, Tether, TetherConfig, TetherModel,
    TetherState, Vacuum,
};
use common::{upward_crossings, SplitMix};
use nalgebra::{DMatrix, DVector, Vector3};

/// ROS34PW2 (Rang & Angermann 2005), written here from the paper's table (its 17 digits).
#[allow(clippy::excessive_precision)]
const GAMMA: f64 = 0.435_866_521_508_459;
#[allow(clippy::excessive_precision)]
const ALPHA: [[f64; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [0.871_733_043_016_918_01, 0.0, 0.0],
    [0.844_570_600_153_694_23, -0.112_990_642_364_841_85, 0.0],
    [0.0, 0.0, 1.0],
];
#[allow(clippy::excessive_precision)]
const GAMMAS: [[f64; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [-0.871_733_043_016_918_01, 0.0, 0.0],
    [-0.903_380_570_130_440_82, 0.054_180_672_388_095_326, 0.0],
    [
        0.242_123_807_060_953_46,
        -1.223_250_583_904_514_7,
        0.545_260_255_335_102_14,
    ],
];
#[allow(clippy::excessive_precision)]
const WEIGHTS: [f64; 4] = [
    0.242_123_807_060_953_46,
    -1.223_250_583_904_514_7,
    1.545_260_255_335_102_3,
    GAMMA,
];

/// The amplification matrix of one ROS34PW2 step on `y' = A y` with the exact Jacobian, for
/// `z = h A`: `K_i = (I - gamma z)^-1 z (I + sum_j (alpha_ij + gamma_ij) K_j)`,
/// `R = I + sum_i b_i K_i`.
fn amplification(z: &DMatrix<f64>) -> DMatrix<f64> {
    let dim = z.nrows();
    let id = DMatrix::<f64>::identity(dim, dim);
    let w = (&id - z * GAMMA).lu();
    let mut k: Vec<DMatrix<f64>> = Vec::new();
    for i in 0..4 {
        let mut arg = id.clone();
        for (j, kj) in k.iter().enumerate() {
            arg += kj * (ALPHA[i][j] + GAMMAS[i][j]);
        }
        k.push(w.solve(&(z * arg)).unwrap());
    }
    let mut r = id;
    for (i, ki) in k.iter().enumerate() {
        r += ki * WEIGHTS[i];
    }
    r
}

/// The scalar stability function R(z) (complex), for the decay rates reported.
fn stability(z: nalgebra::Complex<f64>) -> nalgebra::Complex<f64> {
    let one = nalgebra::Complex::new(1.0, 0.0);
    let mut k: Vec<nalgebra::Complex<f64>> = Vec::new();
    for i in 0..4 {
        let mut arg = one;
        for (j, kj) in k.iter().enumerate() {
            arg += kj * (ALPHA[i][j] + GAMMAS[i][j]);
        }
        k.push(z * arg / (one - z * GAMMA));
    }
    one + k
        .iter()
        .enumerate()
        .map(|(i, v)| v * WEIGHTS[i])
        .sum::<nalgebra::Complex<f64>>()
}

fn implicit(cfg: TetherConfig) -> TetherConfig {
    TetherConfig {
        scheme: Scheme::ImplicitAxial,
        ..cfg
    }
}

fn distributed(cfg: TetherConfig) -> TetherConfig {
    TetherConfig {
        elasticity: Elasticity::Distributed,
        ..cfg
    }
}

/// Indices of the stretch coordinates.
fn stretch_indices(cfg: &TetherConfig) -> Vec<usize> {
    let n = cfg.segments;
    if cfg.is_distributed() {
        std::iter::once(0).chain(2 * n + 1..3 * n).collect()
    } else {
        vec![0]
    }
}

/// Total elongation: the sum of the elements' stretches.
fn elongation(cfg: &TetherConfig, q: &[f64]) -> f64 {
    stretch_indices(cfg).iter().map(|&i| q[i]).sum()
}

/// A straight state along `dir` with the given element stretches and rates, in `cfg`'s layout.
fn straight(cfg: &TetherConfig, dir: Vector3<f64>, s: &[f64], sd: &[f64]) -> TetherState {
    let n = cfg.segments;
    let st = TetherState::straight(n, dir, 0.0).unwrap();
    let mut st = if cfg.is_distributed() {
        st.to_distributed().unwrap()
    } else {
        st
    };
    for (j, &i) in stretch_indices(cfg).iter().enumerate() {
        st.q[i] = s[j];
        st.qd[i] = sd[j];
    }
    st
}

/// The stretches of a vertical chain hanging at rest: element k carries the weight below it.
fn hanging_stretches(cfg: &TetherConfig) -> Vec<f64> {
    let n = cfg.segments;
    let count = if cfg.is_distributed() { n } else { 1 };
    (0..count)
        .map(|k| {
            let below = cfg.segment_mass() * (n - k) as f64 + cfg.tip_mass;
            below * cfg.gravity / cfg.element_stiffness()
        })
        .collect()
}

fn run(cfg: &TetherConfig, start: &TetherState, seconds: f64) -> Tether {
    let mut t = Tether::new(cfg).unwrap();
    t.set_state(start.clone()).unwrap();
    t.step_many((seconds / cfg.time_step).round() as usize, &Vacuum)
        .unwrap();
    t
}

/// Tip positions every `every` seconds over `seconds`.
fn tip_track(
    cfg: &TetherConfig,
    start: &TetherState,
    seconds: f64,
    every: f64,
) -> Vec<Vector3<f64>> {
    let mut t = Tether::new(cfg).unwrap();
    t.set_state(start.clone()).unwrap();
    let per = (every / cfg.time_step).round() as usize;
    (0..(seconds / every).round() as usize)
        .map(|_| {
            t.step_many(per, &Vacuum).unwrap();
            t.tip_state().0
        })
        .collect()
}

fn max_distance(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).norm()))
}

#[test]
fn scheme_parses_is_omitted_by_default_and_names_bad_values() {
    let default = TetherConfig::table3();
    assert_eq!(default.scheme, Scheme::Explicit);
    assert!(
        !default.to_json().contains("scheme"),
        "{}",
        default.to_json()
    );
    let c = TetherConfig::from_json(r#"{"scheme": "implicit_axial"}"#).unwrap();
    assert_eq!(c.scheme, Scheme::ImplicitAxial);
    assert_eq!(TetherConfig::from_json(&c.to_json()).unwrap(), c);
    let err = TetherConfig::from_json(r#"{"scheme": "implicit"}"#)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("`scheme`") && err.contains("\"implicit\"") && err.contains("implicit_axial"),
        "{err}"
    );
}

/// The configurations of the brief refused at 0.01 s for their axial stiffness step under the
/// implicit scheme with one substep; the refusal points to it.
#[test]
fn axially_stiff_configs_refused_explicitly_are_accepted_implicitly() {
    let stiff_attachment = TetherConfig {
        segments: 4,
        axial_stiffness: 1e12,
        ..TetherConfig::table3()
    };
    for cfg in [distributed(TetherConfig::table3()), stiff_attachment] {
        let err = Tether::new(&cfg).unwrap_err().to_string();
        assert!(
            err.contains("time_step") && err.contains("scheme = \"implicit_axial\""),
            "{err}"
        );
        let cfg = implicit(cfg);
        let mut t = Tether::new(&cfg).unwrap();
        assert_eq!(t.substeps(&Vacuum).unwrap(), 1);
        // The towed case too: the capture's flight condition.
        let (towed, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
        let mut t = Tether::new(&towed).unwrap();
        assert_eq!(t.substeps(&flow).unwrap(), 1);
        t.step_many(100, &flow).unwrap();
    }
    // A refusal the axial elements are not the cause of (the zig-zag of 1000 segments at
    // 0.1 s) names no scheme to switch to, and the implicit scheme refuses it too.
    let fine = TetherConfig {
        segments: 1000,
        time_step: 0.1,
        ..TetherConfig::table3()
    };
    let err = Tether::new(&fine).unwrap_err().to_string();
    assert!(
        err.contains("RK4 substeps") && !err.contains("implicit_axial"),
        "{err}"
    );
    let err = Tether::new(&implicit(fine)).unwrap_err().to_string();
    assert!(err.contains("ROS34PW2 substeps"), "{err}");
}

/// The stage solve, recursive and dense, against the augmented system assembled here: `M`
/// from the model's mass matrix, `Q = M q''` from its dense accelerations, the stretch rows'
/// forces moved to the stage's arguments and `gamma_h c + gamma_h^2 k` added to their diagonal.
/// With `gamma_h = 0` at the state's own stretches it is the right-hand side, bit for bit.
#[test]
fn stage_solve_is_the_augmented_mass_matrix_system() {
    let mut rng = SplitMix(0xA61A);
    for elasticity in [Elasticity::Attachment, Elasticity::Distributed] {
        for n in [1usize, 3, 12] {
            let cfg = TetherConfig {
                segments: n,
                elasticity,
                ..TetherConfig::table3()
            };
            let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
            let dim = cfg.dofs();
            let mut model = TetherModel::new(&cfg).unwrap();
            for case in 0..6 {
                let dirs: Vec<_> = (0..n)
                    .map(|_| direction(rng.range(0.2, 1.4), rng.range(-0.5, 0.5)))
                    .collect();
                let rates: Vec<_> = (0..n)
                    .map(|_| Vector3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.0))
                    .collect();
                let st = TetherState::from_directions(&dirs, &rates, 0.01, 0.1).unwrap();
                let mut st = if cfg.is_distributed() {
                    st.to_distributed().unwrap()
                } else {
                    st
                };
                for &i in &stretch_indices(&cfg)[1..] {
                    st.q[i] = rng.range(-0.01, 0.03);
                    st.qd[i] = rng.range(-0.3, 0.3);
                }
                let (q, qd) = (&st.q, &st.qd);
                let stretch: Vec<f64> = q.iter().map(|v| v + rng.range(-0.02, 0.02)).collect();
                let rate: Vec<f64> = qd.iter().map(|v| v + rng.range(-0.5, 0.5)).collect();
                let gamma_h = [0.0, 4.4e-3, 0.1][case % 3];
                let stage = AxialStage {
                    stretch: &stretch,
                    stretch_rate: &rate,
                    gamma_h,
                };
                // The oracle.
                let mass = model.mass_matrix(q).unwrap();
                let mut acc = vec![0.0; dim];
                model
                    .accelerations_dense(0.3, q, qd, &flow, &mut acc)
                    .unwrap();
                let mut rhs = &mass * DVector::from_column_slice(&acc);
                let mut augmented = mass.clone();
                let (k, c) = (cfg.element_stiffness(), cfg.element_damping());
                for &i in &stretch_indices(&cfg) {
                    rhs[i] += k * (q[i] - stretch[i]) + c * (qd[i] - rate[i]);
                    augmented[(i, i)] += gamma_h * c + gamma_h * gamma_h * k;
                }
                let want = augmented.cholesky().unwrap().solve(&rhs);
                let scale = want.amax().max(1.0);
                for solver in [Solver::Recursive, Solver::Dense] {
                    model.set_solver(solver);
                    let mut got = vec![0.0; dim];
                    model
                        .accelerations_axial(0.3, q, qd, &stage, &flow, &mut got)
                        .unwrap();
                    let err = got
                        .iter()
                        .zip(want.iter())
                        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                    assert!(
                        err < 1e-9 * scale,
                        "{elasticity:?} n = {n} case {case} {solver:?}: {err:e} of {scale:e}"
                    );
                }
                model.set_solver(Solver::Recursive);
                // The right-hand side itself.
                let own = AxialStage {
                    stretch: q,
                    stretch_rate: qd,
                    gamma_h: 0.0,
                };
                let (mut a, mut b) = (vec![0.0; dim], vec![0.0; dim]);
                model
                    .accelerations_axial(0.3, q, qd, &own, &flow, &mut a)
                    .unwrap();
                model.accelerations(0.3, q, qd, &flow, &mut b).unwrap();
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a), bits(&b), "{elasticity:?} n = {n}");
            }
        }
    }
}

/// A vertical chain's axial motion is linear, `M_ss s'' = -K s - C s' + weight` (the stretch
/// block of `M` is constant and decoupled from the angles on a straight chain), so the scheme
/// must advance the deviation from the hanging stretches by its own amplification matrix,
/// `y_N - y* = R(h A)^N (y_0 - y*)`, `A = [[0, I], [-M_ss^-1 K, -M_ss^-1 C]]`. Checked for the
/// attachment element resolved (Table 3 with its tip mass), undamped and stiff (k = 1e12 N/m),
/// and for the distributed Table 3 tether (30 elements, the fastest about 3.6e5 1/s).
#[test]
fn vertical_axial_motion_follows_the_schemes_amplification_matrix() {
    let table3 = TetherConfig {
        tip_mass: 50.0,
        ..TetherConfig::table3()
    };
    let cases = [
        ("attachment, Table 3", table3.clone()),
        (
            "attachment, undamped",
            TetherConfig {
                axial_damping_per_mass: 0.0,
                ..table3.clone()
            },
        ),
        (
            "attachment, k = 1e12",
            TetherConfig {
                segments: 4,
                axial_stiffness: 1e12,
                ..table3.clone()
            },
        ),
        ("distributed, Table 3", distributed(table3.clone())),
        (
            "distributed, undamped",
            distributed(TetherConfig {
                axial_damping_per_mass: 0.0,
                segments: 10,
                ..table3.clone()
            }),
        ),
    ];
    for (name, cfg) in cases {
        let cfg = implicit(cfg);
        let h = cfg.time_step;
        let idx = stretch_indices(&cfg);
        let m = idx.len();
        let hang = hanging_stretches(&cfg);
        let down = reference::hanging_direction();
        // Released from 1.5x the hanging stretches, moving at 0.2 m/s.
        let s0: Vec<f64> = hang.iter().map(|s| 1.5 * s).collect();
        let sd0 = vec![0.2 / m as f64; m];
        let start = straight(&cfg, down, &s0, &sd0);
        let mut model = TetherModel::new(&cfg).unwrap();
        let mass = model.mass_matrix(&start.q).unwrap();
        let mss = DMatrix::from_fn(m, m, |r, c| mass[(idx[r], idx[c])]);
        let inv = mss.try_inverse().unwrap();
        let (k, c) = (cfg.element_stiffness(), cfg.element_damping());
        let mut a = DMatrix::zeros(2 * m, 2 * m);
        for r in 0..m {
            a[(r, m + r)] = 1.0;
            for j in 0..m {
                a[(m + r, j)] = -inv[(r, j)] * k;
                a[(m + r, m + j)] = -inv[(r, j)] * c;
            }
        }
        let r = amplification(&(&a * h));
        let mut dev = DVector::zeros(2 * m);
        for j in 0..m {
            dev[j] = s0[j] - hang[j];
            dev[m + j] = sd0[j];
        }
        let scale = dev.amax();
        let mut tether = Tether::new(&cfg).unwrap();
        tether.set_state(start).unwrap();
        let mut worst = 0.0f64;
        for _ in 0..200 {
            tether.step(&Vacuum).unwrap();
            dev = &r * dev;
            let q = &tether.state().q;
            let qd = &tether.state().qd;
            for j in 0..m {
                worst = worst.max((q[idx[j]] - hang[j] - dev[j]).abs());
                worst = worst.max((qd[idx[j]] - dev[m + j]).abs() * h);
            }
        }
        // Per-step decay of the lowest axial mode: the scheme's |R(h lambda)| against the
        // exact exp(h Re lambda).
        let eig = a.clone().complex_eigenvalues();
        let (mut slowest, mut stiff) = (f64::INFINITY, 0.0f64);
        let (mut slow_exact, mut slow_scheme) = (0.0, 0.0);
        for lambda in eig.iter() {
            if lambda.norm() < slowest {
                slowest = lambda.norm();
                slow_exact = (lambda.re * h).exp();
                slow_scheme = stability(lambda * h).norm();
            }
            stiff = stiff.max(lambda.norm() * h);
        }
        eprintln!(
            "{name}: |state - R^N prediction| {worst:.2e} m of {scale:.2e}; lowest axial mode \
             decays per step by {slow_scheme:.6} (exact {slow_exact:.6}); fastest |lambda h| = \
             {stiff:.3e}"
        );
        assert!(worst < 1e-9 * scale.max(hang[0]), "{name}: {worst:e}");
        // The motion reached: the stretches settled on the hanging ones to rounding when
        // damped.
        if cfg.axial_damping_per_mass > 0.0 {
            let q = &tether.state().q;
            for j in 0..m {
                assert!(
                    (q[idx[j]] / hang[j] - 1.0).abs() < 1e-9,
                    "{name}: element {j}"
                );
            }
        }
    }
    // The stability function itself: L-stable (R(-inf) = 0), and the energy factor per step of
    // an undamped oscillator at Table 3's attachment mode (omega h = 0.345), below one where
    // RK4's is not far from it.
    assert!(stability(nalgebra::Complex::new(-1e12, 0.0)).norm() < 1e-9);
    let z = nalgebra::Complex::new(0.0, 0.345);
    let rk4 =
        nalgebra::Complex::new(1.0, 0.0) + z + z * z / 2.0 + z * z * z / 6.0 + z * z * z * z / 24.0;
    let (ros, rk) = (stability(z).norm_sqr(), rk4.norm_sqr());
    eprintln!("energy factor per step at omega h = 0.345: ROS34PW2 {ros:.8}, RK4 {rk:.8}");
    assert!(ros < 1.0 && ros > 0.99 && (rk - 1.0).abs() < 1e-4);
}

/// Released unstretched, a hanging chain stretches to the closed form at 0.01 s steps without
/// ringing: Table 3 distributed (overdamped elements: the total approaches monotonically) and
/// stiff elements (k = 1e12 N/m, their mode at |lambda h| near 900: within 1e-9 of `s*` after
/// four steps, falling at each).
#[test]
fn hanging_chain_settles_on_the_static_stretch_without_ringing() {
    let table3 = implicit(TetherConfig::table3());
    let stiff = |cfg: TetherConfig| TetherConfig {
        axial_stiffness: 1e12,
        ..cfg
    };
    let cases = [
        ("distributed Table 3", distributed(table3.clone())),
        (
            "attachment k = 1e12, n = 4",
            stiff(TetherConfig {
                segments: 4,
                ..table3.clone()
            }),
        ),
        ("distributed k = 1e12", stiff(distributed(table3.clone()))),
    ];
    for (name, cfg) in cases {
        let n = cfg.segments;
        let down = reference::hanging_direction();
        let m = stretch_indices(&cfg).len();
        let start = straight(&cfg, down, &vec![0.0; m], &vec![0.0; m]);
        let want = hanging_stretches(&cfg);
        let total: f64 = want.iter().sum();
        let closed = cfg.total_mass() * cfg.gravity / cfg.axial_stiffness
            * if cfg.is_distributed() {
                (n as f64 + 1.0) / (2.0 * n as f64)
            } else {
                1.0
            };
        assert!((total / closed - 1.0).abs() < 1e-12);
        let mut t = Tether::new(&cfg).unwrap();
        t.set_state(start).unwrap();
        let mut devs = Vec::new();
        for _ in 0..3000 {
            t.step(&Vacuum).unwrap();
            devs.push((elongation(&cfg, &t.state().q) / total - 1.0).abs());
        }
        let q = &t.state().q;
        for (j, &i) in stretch_indices(&cfg).iter().enumerate() {
            assert!(
                (q[i] / want[j] - 1.0).abs() < 1e-9,
                "{name}: element {j}: {} vs {}",
                q[i],
                want[j]
            );
        }
        eprintln!(
            "{name}: relative deviation of the elongation after steps 1-6: {:?}",
            devs[..6]
                .iter()
                .map(|d| format!("{d:.2e}"))
                .collect::<Vec<_>>()
        );
        if cfg.axial_stiffness > 1e9 {
            assert!(devs[3] < 1e-9, "{name}: {devs:?}");
            assert!(devs[..4].windows(2).all(|w| w[1] < w[0]), "{name}");
        } else {
            // Overdamped: the deviation falls step by step until rounding.
            let until = devs.iter().position(|d| *d < 1e-12).unwrap();
            assert!(devs[..until].windows(2).all(|w| w[1] < w[0]), "{name}");
        }
    }
}

/// Fig. 9's cases (Table 1's chain, n = 4, c1 = 20 on joints and elements): (a) hanging,
/// released unstretched; (b) released from phi = psi = pi/4, swinging. The implicit scheme at
/// 0.01 s against explicit RK4 at 1e-4 s over 3 s: tip positions every 0.05 s within 20 um of
/// a 10 m chain (measured: 2-4 um), the elongation's static level within 1e-6 of it. A stiff
/// chain (k = 1e12 N/m) under the implicit scheme, either elasticity, swings within 10 um of
/// what RK4 at 5e-6 s gives the attachment model (measured: 1 um).
#[test]
fn fig9_cases_match_small_step_rk4() {
    let base = TetherConfig::table1();
    let n = base.segments;
    let d = direction(std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4);
    let hanging = TetherState::straight(n, reference::hanging_direction(), 0.0).unwrap();
    let swing =
        TetherState::from_directions(&vec![d; n], &vec![Vector3::zeros(); n], 0.0, 0.0).unwrap();
    let seconds = 3.0;
    for (case, start, tolerance) in [("a_vertical", hanging, 2e-5), ("b_swing", swing, 2e-5)] {
        for elasticity in [Elasticity::Attachment, Elasticity::Distributed] {
            let cfg = TetherConfig {
                elasticity,
                ..base.clone()
            };
            let start = if cfg.is_distributed() {
                start.to_distributed().unwrap()
            } else {
                start.clone()
            };
            let fast = implicit(cfg.clone());
            let reference = TetherConfig {
                time_step: 1e-4,
                ..cfg.clone()
            };
            let a = tip_track(&fast, &start, seconds, 0.05);
            let b = tip_track(&reference, &start, seconds, 0.05);
            let err = max_distance(&a, &b);
            let (ta, tb) = (
                run(&fast, &start, seconds),
                run(&reference, &start, seconds),
            );
            let (ea, eb) = (
                elongation(&fast, &ta.state().q),
                elongation(&cfg, &tb.state().q),
            );
            eprintln!(
                "Fig. 9 {case}, {}: tip within {err:.2e} m of RK4 at 1e-4 s; elongation at \
                 {seconds} s {ea:.6e} vs {eb:.6e} m",
                elasticity.name()
            );
            assert!(err < tolerance, "{case} {elasticity:?}: {err:e}");
            if case == "a_vertical" {
                assert!((ea / eb - 1.0).abs() < 1e-6, "{ea} vs {eb}");
            }
        }
    }
    // Stiff: k = 1e12 N/m, the attachment model, RK4 at its stable 5e-6 s; and the distributed
    // model under the implicit scheme, which tends to the same inextensible chain.
    let stiff = TetherConfig {
        axial_stiffness: 1e12,
        ..base.clone()
    };
    let swing =
        TetherState::from_directions(&vec![d; n], &vec![Vector3::zeros(); n], 0.0, 0.0).unwrap();
    let reference = TetherConfig {
        time_step: 5e-6,
        ..stiff.clone()
    };
    let b = tip_track(&reference, &swing, 1.0, 0.05);
    let a = tip_track(&implicit(stiff.clone()), &swing, 1.0, 0.05);
    let dist = implicit(distributed(stiff.clone()));
    let c = tip_track(&dist, &swing.to_distributed().unwrap(), 1.0, 0.05);
    let (ea, ec) = (max_distance(&a, &b), max_distance(&c, &b));
    eprintln!(
        "stiff swing (k = 1e12 N/m): implicit attachment within {ea:.2e} m, implicit \
         distributed within {ec:.2e} m of RK4 at 5e-6 s over 1 s"
    );
    assert!(ea < 1e-5 && ec < 1e-5, "{ea:e} {ec:e}");
}

/// The hanging chain's lowest mode (the bare 10 m chain of `oscillation.rs`, released in its
/// first mode shape): period and tip track under the implicit scheme at 0.01 s, both
/// elasticities, against RK4 at 1e-3 s: periods within 1e-5, tips within 5e-4 of the amplitude
/// (measured: 2e-4, the swing integrated by the explicit stages alone).
#[test]
fn hanging_mode_matches_rk4() {
    let bare = TetherConfig {
        segments: 10,
        length: 10.0,
        mass_per_length: 0.1,
        axial_stiffness: 1e6,
        axial_damping_per_mass: 0.0,
        flexural_rigidity: 0.0,
        joint_damping_per_mass: 0.0,
        normal_drag_coefficient: 0.0,
        tangential_drag_coefficient: 0.0,
        tip_mass: 0.0,
        ..TetherConfig::table3()
    };
    let n = bare.segments;
    // A bow of the lower half: the first mode dominates.
    let dirs: Vec<_> = (0..n)
        .map(|k| Vector3::new(-0.01 * (k as f64 / n as f64), 0.0, 1.0))
        .collect();
    let s_eq = bare.total_mass() * bare.gravity / bare.axial_stiffness;
    let start = TetherState::from_directions(&dirs, &vec![Vector3::zeros(); n], s_eq, 0.0).unwrap();
    let reference = TetherConfig {
        time_step: 1e-3,
        ..bare.clone()
    };
    let seconds = 15.0;
    let track = |cfg: &TetherConfig, st: &TetherState| {
        let mut t = Tether::new(cfg).unwrap();
        t.set_state(st.clone()).unwrap();
        let per = (0.01 / cfg.time_step).round() as usize;
        let (mut times, mut xs) = (vec![], vec![]);
        while t.state().time < seconds - 1e-9 {
            t.step_many(per, &Vacuum).unwrap();
            times.push(t.state().time);
            xs.push(t.tip_state().0.x);
        }
        let c = upward_crossings(&times, &xs);
        let period = (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
        (period, xs)
    };
    let (want, xs_ref) = track(&reference, &start);
    let amplitude = xs_ref.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for cfg in [implicit(bare.clone()), implicit(distributed(bare.clone()))] {
        let st = if cfg.is_distributed() {
            let mut st = start.to_distributed().unwrap();
            let per = s_eq / n as f64;
            st.q[0] = per;
            for k in 1..n {
                st.q[2 * n + k] = per;
            }
            st
        } else {
            start.clone()
        };
        let (got, xs) = track(&cfg, &st);
        let err = xs
            .iter()
            .zip(&xs_ref)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        eprintln!(
            "hanging mode, {}: period {got:.5} s (RK4 at 1e-3 s: {want:.5} s), tip x within \
             {err:.2e} m of an amplitude {amplitude:.2e} m",
            cfg.elasticity.name()
        );
        assert!((got / want - 1.0).abs() < 1e-5, "{got} vs {want}");
        assert!(err < 5e-4 * amplitude, "{err:e}");
    }
}

/// Towed Table 3 tether with the stand-in ACCD from straight trailing, 120 s at 0.01 s: the
/// implicit attachment model follows RK4's settling within 0.5 mm (measured: 0.06 mm) and
/// settles on its equilibrium within 1 um; the implicit distributed model settles on an
/// equilibrium of its own equations (rates and accelerations vanish there), within 2 cm of the
/// attachment model's tip (measured: 7 mm, the stretch spread along the chain).
#[test]
fn towed_equilibria_match() {
    let settle = |cfg: &TetherConfig| {
        let (cfg, flow) = reference::towed(cfg, reference::StandInBody::accd()).unwrap();
        let mut t = Tether::new(&cfg).unwrap();
        let mut tips = Vec::new();
        for _ in 0..1200 {
            t.step_many(10, &flow).unwrap();
            tips.push(t.tip_state().0);
        }
        (t, tips, flow)
    };
    let (_, explicit_tips, _) = settle(&TetherConfig::table3());
    let (_, attachment_tips, _) = settle(&implicit(TetherConfig::table3()));
    let (mut dist, dist_tips, flow) = settle(&implicit(distributed(TetherConfig::table3())));
    let transient = max_distance(&attachment_tips, &explicit_tips);
    let settled = (attachment_tips[1199] - explicit_tips[1199]).norm();
    let between = (dist_tips[1199] - explicit_tips[1199]).norm();
    let rates = dist.state().qd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let acc = dist
        .accelerations(&flow)
        .unwrap()
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    eprintln!(
        "towed Table 3: implicit attachment within {transient:.2e} m of RK4 over 120 s, \
         {settled:.2e} m settled; distributed tip {between:.3} m from the attachment model's \
         (tip at {:.3?} vs {:.3?}); its largest rate {rates:.1e}, acceleration {acc:.1e}",
        dist_tips[1199].as_slice(),
        explicit_tips[1199].as_slice()
    );
    assert!(
        transient < 5e-4 && settled < 1e-6,
        "{transient:e} {settled:e}"
    );
    assert!(
        between < 0.02 && rates < 1e-6 && acc < 1e-6,
        "{between} {rates:e} {acc:e}"
    );
}

/// Without damping, drag or bending losses (Table 1's chain swinging from pi/4, stretched
/// 1 cm), both schemes at 0.01 s lose energy that the equations conserve: measured over 20 s,
/// relative to the largest kinetic energy, the implicit scheme loses under 1 % and gains none,
/// and at most 5 times what RK4 loses (its axial mode, omega h = 0.45 here, is damped by
/// |R(i omega h)| < 1; the closed form is in the amplification-matrix test).
#[test]
fn undamped_energy_loss_is_measured() {
    let cfg = TetherConfig {
        joint_damping_per_mass: 0.0,
        axial_damping_per_mass: 0.0,
        flexural_rigidity: 5.0,
        ..TetherConfig::table1()
    };
    let n = cfg.segments;
    let d = direction(std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4);
    let st =
        TetherState::from_directions(&vec![d; n], &vec![Vector3::zeros(); n], 0.01, 0.0).unwrap();
    let mut out = Vec::new();
    for c in [cfg.clone(), implicit(cfg.clone())] {
        let mut t = Tether::new(&c).unwrap();
        t.set_state(st.clone()).unwrap();
        let e0 = t.energy().total();
        let (mut lost, mut gained, mut kin) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..2000 {
            t.step(&Vacuum).unwrap();
            let e = t.energy();
            lost = lost.max(e0 - e.total());
            gained = gained.max(e.total() - e0);
            kin = kin.max(e.kinetic);
        }
        let end = (e0 - t.energy().total()) / kin;
        eprintln!(
            "{}: over 20 s at 0.01 s, energy lost {:.3e}, gained {:.3e}, at the end {end:.3e} \
             (of the largest kinetic energy, {kin:.1} J)",
            c.scheme.name(),
            lost / kin,
            gained / kin
        );
        out.push((lost / kin, gained / kin));
    }
    assert!(out[1].0 < 1e-2 && out[1].1 == 0.0, "{out:?}");
    assert!(out[1].0 < 5.0 * out[0].0, "{out:?}");
}

/// Two runs of the same configuration give the same bits.
#[test]
fn implicit_steps_are_deterministic() {
    let (cfg, flow) = reference::towed(
        &implicit(distributed(TetherConfig::table3())),
        reference::StandInBody::accd(),
    )
    .unwrap();
    let go = || {
        let mut t = Tether::new(&cfg).unwrap();
        t.step_many(300, &flow).unwrap();
        t.state().q.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    };
    assert_eq!(go(), go());
}

/// Undamped chains bent into a zig-zag (their fastest bending mode), the attachment and the
/// distributed elasticity, hanging at their static stretch, 20 s at 0.01 s: the implicit
/// scheme's energy must not grow (the swing and bending modes see the explicit stages alone;
/// a Rosenbrock matrix coupling `q' = v` on every coordinate makes them grow, its stability
/// function exceeding 1 on the whole imaginary axis). Allowed: a gain of 1e-6 of the energy
/// above the hanging rest state.
#[test]
fn undamped_zigzag_does_not_grow() {
    let bare = implicit(TetherConfig {
        joint_damping_per_mass: 0.0,
        axial_damping_per_mass: 0.0,
        normal_drag_coefficient: 0.0,
        tangential_drag_coefficient: 0.0,
        segments: 10,
        ..TetherConfig::table1()
    });
    let n = bare.segments;
    let dirs: Vec<_> = (0..n)
        .map(|k| Vector3::new(if k % 2 == 0 { 0.01 } else { -0.01 }, 0.0, 1.0))
        .collect();
    let mut gains = Vec::new();
    for cfg in [bare.clone(), distributed(bare.clone())] {
        let hanging = hanging_stretches(&cfg);
        let bent =
            TetherState::from_directions(&dirs, &vec![Vector3::zeros(); n], 0.0, 0.0).unwrap();
        let mut st = if cfg.is_distributed() {
            bent.to_distributed().unwrap()
        } else {
            bent
        };
        for (j, &i) in stretch_indices(&cfg).iter().enumerate() {
            st.q[i] = hanging[j];
        }
        let rest = {
            let mut t = Tether::new(&cfg).unwrap();
            t.set_state(straight(
                &cfg,
                Vector3::z(),
                &hanging,
                &vec![0.0; hanging.len()],
            ))
            .unwrap();
            t.energy().total()
        };
        let mut t = Tether::new(&cfg).unwrap();
        t.set_state(st).unwrap();
        let e0 = t.energy().total();
        let mut gained = f64::NEG_INFINITY;
        for _ in 0..2000 {
            t.step(&Vacuum).unwrap();
            gained = gained.max(t.energy().total() - e0);
        }
        let lost = e0 - t.energy().total();
        eprintln!(
            "undamped zig-zag, {}: {:.2e} J above rest; over 20 s at 0.01 s the energy gained \
             at most {:.2e} of it, lost {:.2e} at the end",
            cfg.elasticity.name(),
            e0 - rest,
            gained / (e0 - rest),
            lost / (e0 - rest)
        );
        gains.push(gained / (e0 - rest));
    }
    assert!(gains.iter().all(|&g| g < 1e-6), "{gains:?}");
}

/// Order of the implicit scheme on a smooth case (Table 1's damped chain swinging from pi/4,
/// stretched 1 cm, 1 s): the tip's error against RK4 at 1e-5 s falls by 2^3 = 8 on halving the
/// step, required within a factor 2^(3 +- 0.5) at 4, 2 and 1 ms (steps the swing's stability
/// needs no substeps at), both elasticities.
#[test]
fn implicit_scheme_converges_at_third_order() {
    let base = TetherConfig::table1();
    let n = base.segments;
    let d = direction(std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4);
    let start =
        TetherState::from_directions(&vec![d; n], &vec![Vector3::zeros(); n], 0.01, 0.0).unwrap();
    for cfg in [base.clone(), distributed(base.clone())] {
        let st = if cfg.is_distributed() {
            straight_like(&cfg, &start)
        } else {
            start.clone()
        };
        let tip = |c: &TetherConfig| run(c, &st, 1.0).tip_state().0;
        let want = tip(&TetherConfig {
            time_step: 1e-5,
            ..cfg.clone()
        });
        let errors: Vec<f64> = [0.004, 0.002, 0.001]
            .iter()
            .map(|&h| {
                (tip(&implicit(TetherConfig {
                    time_step: h,
                    ..cfg.clone()
                })) - want)
                    .norm()
            })
            .collect();
        let ratios: Vec<f64> = errors.windows(2).map(|e| e[0] / e[1]).collect();
        eprintln!(
            "order, {}: tip errors {errors:?} m at 4, 2, 1 ms; ratios {ratios:.2?}",
            cfg.elasticity.name()
        );
        for r in ratios {
            assert!(
                (2f64.powf(2.5)..2f64.powf(3.5)).contains(&r),
                "{errors:?} {r}"
            );
        }
    }
}

/// `start` (attachment layout) in the distributed layout, its stretch spread evenly.
fn straight_like(cfg: &TetherConfig, start: &TetherState) -> TetherState {
    let n = cfg.segments;
    let mut st = start.to_distributed().unwrap();
    let per = start.q[0] / n as f64;
    for &i in &stretch_indices(cfg) {
        st.q[i] = per;
    }
    st
}
