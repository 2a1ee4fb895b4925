//! The wake field as the tether's surroundings: composition, and Table 3's tether flying in it.

use crate::support;
use accd_sim::physics::turbulence::{AmbientTurbulence, TurbulenceConfig};
use accd_sim::physics::wake::WakeConfig;

use accd_sim::SimError;
use accd_tether::{reference, Surroundings, Tether};
use nalgebra::Vector3;
use support::wake_field::{wake_field, WakeFieldConfig};

fn config(alpha_deg: f64, ambient: AmbientTurbulence) -> WakeFieldConfig {
    WakeFieldConfig {
        wake: WakeConfig {
            alpha_deg,
            ..WakeConfig::default()
        },
        turbulence: TurbulenceConfig {
            ambient,
            ..TurbulenceConfig::default()
        },
        ..WakeFieldConfig::default()
    }
}

#[test]
fn air_is_free_stream_plus_wake_plus_turbulence() {
    let mut field = wake_field(&config(8.0, AmbientTurbulence::Light), 17).unwrap();
    field.advance(0.01).unwrap();
    assert!((field.density() - 0.6601).abs() < 1e-4);
    assert_eq!(field.free_stream(), Vector3::new(-185.0, 0.0, 0.0));
    for p in [
        Vector3::new(-10.0, 0.0, 2.0),
        Vector3::new(-240.0, 3.0, 50.0),
        Vector3::new(-1000.0, 0.0, 0.0),
    ] {
        let w = field.wake().sample(&p);
        let expected =
            Vector3::new(-185.0, 0.0, 0.0) + w.velocity + field.turbulence().sample(&p, w.tke);
        assert_eq!(field.air_velocity(3.7, &p), expected);
        assert_eq!(field.air_velocity_at(&p), expected);
        assert_eq!(
            field.mean_air_velocity_at(&p),
            Vector3::new(-185.0, 0.0, 0.0) + w.velocity
        );
        assert_eq!(field.air_density(0.0, &p), field.density());
    }
    // Far behind (outside the tables) only the ambient turbulence is left.
    let far = Vector3::new(-1000.0, 0.0, 0.0);
    assert_eq!(field.wake().sample(&far).tke, 0.0);
    assert_ne!(field.air_velocity_at(&far), field.free_stream());
}

#[test]
fn without_wake_and_turbulence_the_field_is_the_uniform_reference_flow() {
    let (cfg, flow) = reference::towed_table3();
    let field_config = WakeFieldConfig {
        wake: WakeConfig {
            enabled: false,
            ..WakeConfig::default()
        },
        ..WakeFieldConfig::default()
    };
    let mut field = wake_field(&field_config, 0)
        .unwrap()
        .with_tip_drag_area(flow.tip_drag_area);
    assert_eq!(field.turbulence().wake_lanes(), 0);
    assert_eq!(field.density(), flow.density);
    let mut a = Tether::new(&cfg).unwrap();
    let mut b = Tether::new(&cfg).unwrap();
    for _ in 0..200 {
        a.step(&flow).unwrap();
        b.step(&field).unwrap();
        field.advance(cfg.time_step).unwrap();
    }
    assert_eq!(a.state().q, b.state().q);
    assert_eq!(a.state().qd, b.state().qd);
}

/// Steps Table 3's tether with the stand-in ACCD for `seconds` in the field; returns the tip's
/// mean depth over the last 5 s and the field.
fn fly(config: &WakeFieldConfig, seed: u64, seconds: f64) -> (f64, Tether) {
    let (cfg, flow) = reference::towed_table3();
    let mut field = wake_field(config, seed)
        .unwrap()
        .with_tip_drag_area(flow.tip_drag_area);
    let mut tether = Tether::new(&cfg).unwrap();
    let steps = (seconds / cfg.time_step).round() as usize;
    let last = (5.0 / cfg.time_step) as usize;
    let mut depth = 0.0;
    for i in 0..steps {
        tether.step(&field).unwrap();
        field.advance(cfg.time_step).unwrap();
        let tip = tether.tip_state().0;
        assert!(tip.iter().all(|v| v.is_finite()));
        if i >= steps - last {
            depth += tip.z / last as f64;
        }
    }
    (depth, tether)
}

#[test]
fn table3_tether_flies_in_the_wake_and_settles_lower_with_more_downwash() {
    let start = std::time::Instant::now();
    // 10 s in the 8 deg wake with wake and severe ambient turbulence: no error.
    let (_, tether) = fly(&config(8.0, AmbientTurbulence::Severe), 1, 10.0);
    assert!(tether.state().time > 9.99);
    let tension = tether.attachment_tension();
    assert!(tension.is_finite() && tension > 0.0, "tension {tension}");
    // Settling (as in accd-tether's statics tests): the 8 deg wake's downwash pushes the tip
    // down compared with the 0 deg wake's.
    let (depth_0, _) = fly(&config(0.0, AmbientTurbulence::None), 1, 40.0);
    let (depth_8, t8) = fly(&config(8.0, AmbientTurbulence::None), 1, 40.0);
    let (tip, _) = t8.clone().tip_state();
    println!(
        "tip depth over the last 5 s of 40 s: 0 deg {depth_0:.2} m, 8 deg {depth_8:.2} m \
         (8 deg tip at x {:.1} m); {:.2} s",
        tip.x,
        start.elapsed().as_secs_f64()
    );
    assert!(
        depth_8 > depth_0 + 2.0,
        "8 deg {depth_8} m vs 0 deg {depth_0} m"
    );
}

#[test]
fn config_errors_name_the_field() {
    let c = WakeFieldConfig {
        altitude_m: 30_000.0,
        ..WakeFieldConfig::default()
    };
    let err = wake_field(&c, 0).unwrap_err();
    assert!(
        matches!(&err, SimError::InvalidConfig { field, .. } if field == "altitude_m"),
        "{err}"
    );
    let mut c = WakeFieldConfig::default();
    c.wake.alpha_deg = 9.0;
    let err = wake_field(&c, 0).unwrap_err();
    assert!(err.to_string().contains("wake.alpha_deg"), "{err}");
    let mut c = WakeFieldConfig::default();
    c.turbulence.time_step_s = 0.0;
    let err = wake_field(&c, 0).unwrap_err();
    assert!(err.to_string().contains("turbulence.time_step_s"), "{err}");
    // Serde: unknown keys are rejected, defaults fill the rest.
    let c: WakeFieldConfig =
        serde_json::from_str(r#"{"wake": {"alpha_deg": 4.0}, "turbulence": {"ambient": "light"}}"#)
            .unwrap();
    assert_eq!(c.wake.alpha_deg, 4.0);
    assert_eq!(c.airspeed_mps, 185.0);
    assert!(serde_json::from_str::<WakeFieldConfig>(r#"{"wake": {"alpha": 4.0}}"#).is_err());
}
