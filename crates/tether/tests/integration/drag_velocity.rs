//! `drag_velocity: "free_stream"` (the paper's Eq. 9 read literally: the segments' drag from the
//! air velocity alone): it parses, serializes only when chosen, leaves the default bit for bit,
//! and makes the drag a function of the configuration only (not of the rates).

use crate::common;

use accd_tether::{reference, DragVelocity, TetherConfig, TetherModel, UniformFlow, Vacuum};
use nalgebra::Vector3;

/// Table 3's tether towed with the stand-in ACCD, bent and moving (every drag term is on).
fn bent_moving(cfg: &TetherConfig) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let moving = common::bent_moving_state(cfg);
    let still = vec![0.0; moving.qd.len()];
    (moving.q, moving.qd, still)
}

fn accelerations<S: accd_tether::Surroundings>(
    cfg: &TetherConfig,
    q: &[f64],
    qd: &[f64],
    s: &S,
) -> Vec<f64> {
    let mut model = TetherModel::new(cfg).unwrap();
    let mut out = vec![0.0; q.len()];
    model.accelerations(0.0, q, qd, s, &mut out).unwrap();
    out
}

fn towed(drag_velocity: DragVelocity) -> (TetherConfig, UniformFlow) {
    let cfg = TetherConfig {
        drag_velocity,
        ..TetherConfig::table3()
    };
    let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
    (
        cfg,
        UniformFlow {
            velocity: flow.velocity + Vector3::new(0.0, 5.0, -2.0),
            ..flow
        },
    )
}

#[test]
fn option_parses_and_the_default_serializes_as_before() {
    let default = TetherConfig::table3();
    assert_eq!(default.drag_velocity, DragVelocity::Relative);
    assert!(!default.to_json().contains("drag_velocity"));
    let f = TetherConfig::from_json(r#"{"drag_velocity": "free_stream"}"#).unwrap();
    assert_eq!(f.drag_velocity, DragVelocity::FreeStream);
    assert!(f.to_json().contains("\"drag_velocity\":\"free_stream\""));
    assert_eq!(TetherConfig::from_json(&f.to_json()).unwrap(), f);
    let err = TetherConfig::from_json(r#"{"drag_velocity": "still"}"#)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("drag_velocity") && err.contains("free_stream") && err.contains("still"),
        "{err}"
    );
}

#[test]
fn free_stream_drag_does_not_depend_on_the_rates() {
    let (cfg, flow) = towed(DragVelocity::FreeStream);
    // The tip body's drag stays relative (it is the body's aerodynamics): leave it out here.
    let flow = UniformFlow {
        tip_drag_area: 0.0,
        ..flow
    };
    let (q, qd, still) = bent_moving(&cfg);
    // q'' = M^-1 (Q_rest(q, q') + Q_drag(q)): the air's share must be the same moving or still.
    let moving: Vec<f64> = accelerations(&cfg, &q, &qd, &flow)
        .iter()
        .zip(accelerations(&cfg, &q, &qd, &Vacuum))
        .map(|(a, b)| a - b)
        .collect();
    let resting: Vec<f64> = accelerations(&cfg, &q, &still, &flow)
        .iter()
        .zip(accelerations(&cfg, &q, &still, &Vacuum))
        .map(|(a, b)| a - b)
        .collect();
    let scale = resting.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    assert!(scale > 1e-3, "the air acts ({scale})");
    for (a, b) in moving.iter().zip(&resting) {
        assert!((a - b).abs() <= 1e-9 * scale, "{a} vs {b}");
    }
    // With the relative velocity the motion changes the drag (the test can fail).
    let (rel, _) = towed(DragVelocity::Relative);
    let flow_r = flow;
    let d_moving: Vec<f64> = accelerations(&rel, &q, &qd, &flow_r)
        .iter()
        .zip(accelerations(&rel, &q, &qd, &Vacuum))
        .map(|(a, b)| a - b)
        .collect();
    let worst = d_moving
        .iter()
        .zip(&resting)
        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(worst > 1e-3 * scale, "{worst}");
}

#[test]
fn at_rest_both_readings_agree_bit_for_bit_and_the_default_is_unchanged() {
    let (free, flow) = towed(DragVelocity::FreeStream);
    let (rel, _) = towed(DragVelocity::Relative);
    let (q, qd, still) = bent_moving(&rel);
    assert_eq!(
        accelerations(&free, &q, &still, &flow),
        accelerations(&rel, &q, &still, &flow)
    );
    // The default config is the one without the field.
    let plain = TetherConfig::from_json(&TetherConfig::table3().to_json()).unwrap();
    let (plain, _) = reference::towed(&plain, reference::StandInBody::accd()).unwrap();
    assert_eq!(
        accelerations(&plain, &q, &qd, &flow),
        accelerations(&rel, &q, &qd, &flow)
    );
}
