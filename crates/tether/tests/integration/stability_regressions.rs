//! Regression tests for the tether alone: every valid discretization steps stably
//! (auto-substepping from the chain's fastest mode), an unstable one is refused with the largest
//! stable step, Table 3's step stays a plain RK4 step, long loops stop when asked, and a
//! divergence leaves the last bounded state.

use accd_tether::config::{StepLoad, MAX_SUBSTEPS};
use accd_tether::{reference, InSurroundings, Rk4, Tether, TetherConfig, TetherError, TetherModel};

fn towed(segments: usize) -> (Tether, accd_tether::UniformFlow) {
    let cfg = TetherConfig {
        segments,
        ..TetherConfig::table3()
    };
    let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
    (Tether::new(&cfg).unwrap(), flow)
}

#[test]
fn table3_steps_are_single_rk4_steps() {
    let (mut t, flow) = towed(30);
    for _ in 0..6000 {
        assert_eq!(t.substeps(&flow).unwrap(), 1, "at t = {}", t.state().time);
        t.step(&flow).unwrap();
    }
}

#[test]
fn three_hundred_segments_substep_and_stay_stable_at_the_default_step() {
    let (mut t, flow) = towed(300);
    let mut most = 1;
    for _ in 0..3000 {
        most = most.max(t.substeps(&flow).unwrap());
        t.step(&flow).unwrap();
    }
    assert!(
        most >= 2,
        "n = 300 needs substeps at 0.01 s (fastest mode ~480 rad/s)"
    );
    assert!(t.attachment_tension().is_finite() && t.attachment_tension() > 1e3);
}

#[test]
fn three_hundred_segments_diverge_without_substeps() {
    // The regression: plain RK4 at 0.01 s is outside its stability region at n = 300.
    let (t, flow) = towed(300);
    let mut model = TetherModel::new(t.config()).unwrap();
    let mut state = t.state().clone();
    let mut rk4 = Rk4::new(model.dofs(), 0);
    let mut system = InSurroundings {
        model: &mut model,
        surroundings: &flow,
    };
    let diverged = (0..3000).any(|i| {
        let t = i as f64 * 0.01;
        rk4.advance(
            &mut system,
            t,
            0.01,
            1,
            &mut state.q,
            &mut state.qd,
            &mut [],
        )
        .is_err()
    });
    assert!(
        diverged,
        "without substeps n = 300 at 0.01 s should diverge"
    );
}

#[test]
fn the_fastest_mode_estimate_matches_the_issue() {
    let cfg = TetherConfig {
        segments: 300,
        ..TetherConfig::table3()
    };
    let rate = cfg.fastest_rate(&StepLoad::at_rest(&cfg, 3.4e3, 0.66, 185.0, 50.0));
    assert!(
        (420.0..560.0).contains(&rate),
        "{rate} rad/s (the regression: near 470)"
    );
    let table3 = TetherConfig::table3();
    let slow = table3.fastest_rate(&StepLoad::at_rest(&table3, 3.4e3, 0.66, 185.0, 50.0));
    assert!(slow * table3.time_step < 1.0, "{slow}");
}

#[test]
fn an_unstable_discretization_is_refused_with_the_largest_stable_step() {
    let cfg = TetherConfig {
        segments: 1000,
        time_step: 1.0,
        ..TetherConfig::table3()
    };
    cfg.validate().unwrap(); // the model alone may be built (linearisations need no step)
    let message = cfg.validate_for_stepping().unwrap_err().to_string();
    assert_eq!(Tether::new(&cfg).unwrap_err().to_string(), message);
    assert!(
        message.contains("`time_step`") && message.contains("largest stable step"),
        "{message}"
    );
    assert!(
        message.contains(&format!("at most {MAX_SUBSTEPS}")),
        "{message}"
    );
}

#[test]
fn a_long_loop_stops_after_the_step_at_which_it_is_interrupted() {
    let (mut t, flow) = towed(30);
    let mut calls = 0;
    let err = t
        .step_many_interruptible(1_000_000, &flow, &mut || {
            calls += 1;
            calls == 3
        })
        .unwrap_err();
    assert!(matches!(
        err,
        TetherError::Interrupted {
            done: 3,
            requested: 1_000_000,
            ..
        }
    ));
    assert!((t.state().time - 0.03).abs() < 1e-12);
    t.step(&flow).unwrap();
}

#[test]
fn a_divergence_keeps_a_bounded_state() {
    let (mut t, flow) = towed(300);
    let n = 300;
    let mut state = t.state().clone();
    for k in 0..n {
        state.q[1 + 2 * k] = if k % 2 == 0 { 0.3 } else { -0.3 };
        state.qd[1 + 2 * k] = if k % 2 == 0 { 50.0 } else { -50.0 };
    }
    t.set_state(state).unwrap();
    let result = t.step_many(10_000, &flow);
    assert!(result.is_err(), "the folded start diverges");
    let s = t.state();
    let bound = accd_tether::integrator::STATE_BOUND;
    assert!(s.q.iter().chain(&s.qd).all(|v| v.abs() <= bound));
    assert!(t.energy().total().is_finite());
    let mut out = vec![0.0; n + 1];
    t.tensions(&flow, &mut out).unwrap();
    assert!(out.iter().all(|v| v.is_finite()));
}
