//! `accd_sim::task::linearize`: the linear model of one agent step against the nonlinear step it was
//! taken from. A first-order model's error of a perturbation `eps d` is `O(eps^2)` where the
//! dynamics are smooth: halving `eps` must quarter it (the ratio is checked in [3.3, 4.7] over
//! perturbations of 400 to 100 finite-difference steps, where the truncation error dominates the
//! finite differences' own), and it must be small next to the response itself.
//!
//! The default aerodynamic tables are bilinear in (alpha, beta) and linear in the deflection
//! with nodes at beta = 0 and deflection = 0, and the wake tables are trilinear: the default
//! dynamics have kinks at the trim, where the central differences give the mean of the two
//! one-sided slopes and a flap input's error is first order (halving it halves the error; its
//! size is bounded below). A configuration with tables whose nodes avoid the trim and no wake
//! shows the second order in every direction, flap inputs included.

use accd_sim::physics::aero::{AeroModel, CoefficientArrays, FinnedBody};
use accd_sim::{EnvConfig, Linearized, ACT_DIM};

fn model_of(config: EnvConfig) -> Linearized {
    Linearized::new(&config.validated().unwrap(), &mut || false).unwrap()
}

fn model() -> Linearized {
    model_of(EnvConfig::default())
}

/// The default finned body tabulated on axes shifted by 1.25 deg (no node at alpha, beta or a
/// deflection of 0), no wake: a configuration whose dynamics are smooth about the trim.
fn smooth_config() -> EnvConfig {
    let body = FinnedBody::accd();
    let mut data = AeroModel::accd().to_file_data();
    let axis = |lo: f64, n: usize| -> Vec<f64> { (0..n).map(|i| lo + 2.5 * i as f64).collect() };
    data.alpha_deg = axis(-28.75, 24);
    data.beta_deg = axis(-28.75, 24);
    data.deflection_deg = axis(-16.25, 14);
    let rad = |d: &f64| d.to_radians();
    let mut base = vec![];
    for a in data.alpha_deg.iter().map(rad) {
        for b in data.beta_deg.iter().map(rad) {
            base.push(body.base(a, b));
        }
    }
    let arrays = |v: &[[f64; 6]]| {
        let col = |c: usize| v.iter().map(|x| x[c]).collect();
        CoefficientArrays {
            cx: col(0),
            cy: col(1),
            cz: col(2),
            cl: col(3),
            cm: col(4),
            cn: col(5),
        }
    };
    data.base = arrays(&base);
    let mut flaps = vec![];
    for f in 0..4 {
        let mut v = vec![];
        for a in data.alpha_deg.iter().map(rad) {
            for b in data.beta_deg.iter().map(rad) {
                for d in data.deflection_deg.iter().map(rad) {
                    v.push(body.flap(f, a, b, d));
                }
            }
        }
        flaps.push(arrays(&v));
    }
    data.flaps.right = flaps[0].clone();
    data.flaps.left = flaps[1].clone();
    data.flaps.top = flaps[2].clone();
    data.flaps.bottom = flaps[3].clone();
    let mut config = EnvConfig::default();
    config.physics.accd.aero_table = Some(serde_json::to_string(&data).unwrap());
    config.physics.wake.enabled = false;
    config
}

/// A fixed perturbation direction: every state component a multiple (in [-1, 1]) of its
/// finite-difference step times `scale`, and a flap command.
fn direction(lin: &Linearized, scale: f64) -> (Vec<f64>, [f64; ACT_DIM]) {
    let steps = &lin.model.steps;
    let d = (0..steps.len())
        .map(|i| ((i as f64 * 0.618_034).fract() * 2.0 - 1.0) * steps[i] * scale)
        .collect();
    (d, [0.3, -0.2, 0.1, 0.25])
}

fn norm(v: &[f64], w: &[f64]) -> f64 {
    v.iter()
        .zip(w)
        .map(|(a, s)| (a / s).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn the_trim_is_a_fixed_point_of_the_agent_step() {
    let lin = model();
    let m = &lin.model;
    println!(
        "settle residual {:.3e}, trim residual {:.3e} after {} Newton iterations",
        m.settle_residual, m.trim_residual, m.newton_iterations
    );
    let zero = vec![0.0; m.trim.len()];
    let next = lin.step(&zero, &[0.0; ACT_DIM], &[0.0; 2]).unwrap();
    let worst = next.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(worst < 1e-9, "x_k+1 - x_k = {worst:.3e} at the trim");
    assert!((worst - m.trim_residual).abs() < 1e-15);
}

/// `|f(x* + eps d, eps u) - (A eps d + B eps u)|` and `|f|` (in units of the finite-difference
/// steps) for perturbations of `scales` finite-difference steps, eps = scale / 400 * 0.02 for
/// the flap command (state perturbations `with_state`, flap input `with_input`).
fn errors(lin: &Linearized, scales: &[f64], with_state: bool, with_input: bool) -> Vec<(f64, f64)> {
    let m = &lin.model;
    let dim = m.trim.len();
    let mut out = vec![];
    for &scale in scales {
        let eps = scale / 400.0 * 0.02;
        let (mut dx, u0) = direction(lin, scale);
        if !with_state {
            dx.fill(0.0);
        }
        let u = if with_input {
            u0.map(|v| v * eps)
        } else {
            [0.0; ACT_DIM]
        };
        let next = lin.step(&dx, &u, &[0.0; 2]).unwrap();
        let mut err = vec![0.0; dim];
        for i in 0..dim {
            err[i] = next[i]
                - (0..dim).map(|j| m.a[(i, j)] * dx[j]).sum::<f64>()
                - (0..ACT_DIM).map(|j| m.b[(i, j)] * u[j]).sum::<f64>();
        }
        let (e, size) = (norm(&err, &m.steps), norm(&next, &m.steps));
        println!("scale {scale}: |f - (A dx + B u)| = {e:.4e}, |f| = {size:.4e} (in FD steps)");
        out.push((e, size));
    }
    out
}

fn assert_second_order(errors: &[(f64, f64)]) {
    for w in errors.windows(2) {
        let ratio = w[0].0 / w[1].0;
        assert!(
            (3.3..4.7).contains(&ratio),
            "error ratio {ratio} on halving the perturbation"
        );
    }
    // Relative error O(eps): below 1e-3 at the smallest perturbation (100 steps: 1e-4 rad of
    // every angle, 1.6 mm of tip motion per angle).
    let (e, size) = errors[errors.len() - 1];
    assert!(e < 1e-3 * size, "error {e} vs response {size}");
}

#[test]
fn a_small_state_perturbation_follows_a_to_second_order() {
    let lin = model();
    assert_second_order(&errors(&lin, &[400.0, 200.0, 100.0], true, false));
}

#[test]
fn a_small_flap_input_follows_b_to_first_order_across_the_tables_kink_at_zero() {
    // The tables are linear in the deflection with a node at 0 (even terms such as the flap
    // drag have a kink there): the error halves with the input and stays below 1e-3 of the
    // response.
    let lin = model();
    let errs = errors(&lin, &[400.0, 200.0, 100.0], false, true);
    for w in errs.windows(2) {
        let ratio = w[0].0 / w[1].0;
        assert!(
            (1.8..2.6).contains(&ratio),
            "error ratio {ratio} on halving the input"
        );
    }
    for (e, size) in &errs {
        assert!(*e < 1e-3 * size, "error {e} vs response {size}");
    }
}

#[test]
fn with_smooth_tables_a_perturbation_and_a_flap_input_follow_a_b_to_second_order() {
    let lin = model_of(smooth_config());
    assert!(
        lin.model.trim_residual < 1e-9,
        "{}",
        lin.model.trim_residual
    );
    assert_second_order(&errors(&lin, &[400.0, 200.0, 100.0], true, true));
}

#[test]
fn the_observation_follows_c_to_second_order() {
    let lin = model();
    let m = &lin.model;
    let dim = m.trim.len();
    let y0 = lin.observe(&vec![0.0; dim]).unwrap();
    for (a, b) in y0.iter().zip(&m.trim_observation) {
        assert_eq!(a, b);
    }
    // The boom tip sits at the trim capture point: the six boom entries are 0 at the trim.
    assert!(y0[..6].iter().all(|v| v.abs() < 1e-9), "{:?}", &y0[..6]);
    let mut errs = vec![];
    for scale in [400.0, 200.0, 100.0] {
        let (dx, _) = direction(&lin, scale);
        let y = lin.observe(&dx).unwrap();
        let mut e2 = 0.0;
        let mut s2 = 0.0;
        for i in 0..y.len() {
            let lin_y: f64 = (0..dim).map(|j| m.c[(i, j)] * dx[j]).sum();
            e2 += (y[i] - y0[i] - lin_y).powi(2);
            s2 += (y[i] - y0[i]).powi(2);
        }
        println!(
            "scale {scale}: |y - y* - C dx| = {:.4e}, |y - y*| = {:.4e}",
            e2.sqrt(),
            s2.sqrt()
        );
        errs.push((e2.sqrt(), s2.sqrt()));
    }
    assert_second_order(&errs);
}

#[test]
fn c_reads_known_entries_of_the_observation_table() {
    // Independent of the finite differences: the tension row is (k, c) on (s, s_dot) times its
    // scale, a flap row is 1 / flap limit on its deflection, the boom rows minus the capture
    // point's (the ACCD's x offset from the equilibrium and boom_rel_x: opposite signs at the tip).
    let config = EnvConfig::default();
    let lin = model();
    let m = &lin.model;
    let t = &config.physics.tether;
    let idx = |name: &str| m.state_names.iter().position(|n| n == name).unwrap();
    let tension = accd_sim::observation_index("tension").unwrap();
    let scale = accd_sim::OBSERVATION[tension].scale;
    let k = m.c[(tension, idx("s"))] / scale;
    let c = m.c[(tension, idx("s_dot"))] / scale;
    assert!((k / t.element_stiffness() - 1.0).abs() < 1e-6, "{k}");
    assert!((c / t.element_damping() - 1.0).abs() < 1e-6, "{c}");
    let flap = accd_sim::observation_index("flap_top").unwrap();
    let limit = config.physics.accd.flap_limit_deg.to_radians();
    assert!((m.c[(flap, idx("flap_top"))] * limit - 1.0).abs() < 1e-6);
    let bx = accd_sim::observation_index("boom_rel_y").unwrap();
    let ay = accd_sim::observation_index("accd_dy").unwrap();
    let j = idx(&format!("psi_{}", t.segments));
    let ratio = m.c[(bx, j)]
        / accd_sim::OBSERVATION[bx].scale
        / (m.c[(ay, j)] / accd_sim::OBSERVATION[ay].scale);
    assert!((ratio + 1.0).abs() < 1e-6, "{ratio}");
}
