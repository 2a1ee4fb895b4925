//! Regression tests for the capture simulation: configuration errors name the field,
//! cross-field rules hold, the coupled step substeps fine tethers and never the default one, and
//! an empty gust history is not filled grid time by grid time.

use accd_sim::{CaptureConfig, CaptureSim, EnvConfig, Seeds, TurbulenceConfig};

#[test]
fn a_value_of_the_wrong_type_is_named_by_its_field() {
    for (doc, field) in [
        (r#"{"capture_window": "long"}"#, "`capture_window`"),
        (r#"{"tether": {"segments": -1}}"#, "`tether.segments`"),
        (r#"{"reward": {"capture": [1]}}"#, "`reward.capture`"),
        (r#"{"capture_windw": 3}"#, "`capture_windw`"),
    ] {
        let e = EnvConfig::from_json(doc).unwrap_err().to_string();
        assert!(
            e.contains(field) && !e.contains("line 1 column"),
            "{doc}: {e}"
        );
    }
    let e = EnvConfig::from_json("[1]").unwrap_err().to_string();
    assert!(e.contains("JSON object"), "{e}");
}

#[test]
fn a_flap_limit_beyond_the_default_table_is_refused() {
    let mut c = CaptureConfig::default();
    c.accd.flap_limit_deg = 20.0;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("accd.flap_limit_deg") && e.contains("15"), "{e}");
    c.accd.flap_limit_deg = 15.0;
    c.validate().unwrap();
}

#[test]
fn the_default_step_is_one_rk4_step_and_fine_tethers_substep() {
    let mut sim = CaptureSim::new(
        &CaptureConfig::default().validated().unwrap(),
        Seeds::default(),
    )
    .unwrap();
    for _ in 0..2000 {
        assert_eq!(sim.substeps().unwrap(), 1, "t = {}", sim.time());
        sim.step([0.0; 4]).unwrap();
    }
    let mut fine = CaptureConfig::calm();
    fine.tether.segments = 300;
    let mut sim = CaptureSim::new(&fine.clone().validated().unwrap(), Seeds::default()).unwrap();
    let mut most = 1;
    for _ in 0..2000 {
        most = most.max(sim.substeps().unwrap());
        sim.step([0.0; 4]).unwrap();
    }
    assert!(most >= 2 && sim.attachment_tension().is_finite());
}

#[test]
fn no_gust_channels_keep_no_history() {
    let calm = TurbulenceConfig {
        wake_turbulence: false,
        ..TurbulenceConfig::default()
    };
    assert_eq!(calm.channels(), 0);
    assert_eq!(calm.history_slots(1e-6), 1);
    assert_eq!(calm.history_bytes(1e-6), 0);
    assert!(TurbulenceConfig::default().history_slots(185.0) > 100);
}

#[test]
fn an_equilibrium_outside_the_episode_limits_is_reported_naming_the_limit() {
    use accd_sim::Equilibrium;
    // A tangential drag coefficient of 1 hung the ACCD about 62 m from a boom placed
    // at a fixed position (the default allows 60 m): every episode ended at its first step,
    // silently. Placed relative to the equilibrium (the default) the boom follows.
    let mut c = EnvConfig::default();
    c.physics.tether.tangential_drag_coefficient = 1.0;
    let eq = Equilibrium::settle(&c.clone().validated().unwrap()).unwrap();
    assert_eq!(eq.outside_limits, None);
    c.physics.boom.placement = accd_sim::BoomPlacement::Absolute;
    let eq = Equilibrium::settle(&c.clone().validated().unwrap()).unwrap();
    let why = eq.outside_limits.expect("reported");
    assert!(
        why.contains("limits.max_distance = 60") && why.contains("first step"),
        "{why}"
    );
    c.limits.max_distance = 80.0;
    let eq = Equilibrium::settle(&c.validated().unwrap()).unwrap();
    assert_eq!(eq.outside_limits, None);
    let mut c = EnvConfig::default();
    c.physics.boom.offset_from_equilibrium = Some([0.0, 0.0, 70.0]);
    let why = Equilibrium::settle(&c.validated().unwrap())
        .unwrap()
        .outside_limits
        .expect("reported");
    assert!(why.contains("limits.max_distance = 60"), "{why}");
    let mut c = EnvConfig::default();
    c.limits.overload_fraction = 1e-3; // 550 N: below the default's 2.9 kN
    let eq = Equilibrium::settle(&c.validated().unwrap()).unwrap();
    assert!(eq
        .outside_limits
        .unwrap()
        .contains("limits.overload_fraction = 0.001"));
    let eq = Equilibrium::settle(&EnvConfig::default().validated().unwrap()).unwrap();
    assert_eq!(eq.outside_limits, None);
}
