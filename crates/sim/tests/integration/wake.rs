//! The mean wake: the analytic default's features (paper section 2.2), interpolation in space and
//! angle of attack, free stream outside, the JSON format and its errors.

use accd_sim::physics::wake::{
    AnalyticWake, Wake, WakeConfig, WakeTable, WakeTableData, WakeTables, TA_LENGTH_M,
};
use accd_sim::SimError;
use nalgebra::Vector3;

const U: f64 = 185.0;
const L: f64 = TA_LENGTH_M;

fn wake(alpha_deg: f64) -> Wake {
    let config = WakeConfig {
        alpha_deg,
        ..WakeConfig::default()
    };
    Wake::from_config(&config, U).unwrap()
}

/// A point in the TA frame from table coordinates (x from the nose, in L), with the default
/// attachment 60 m behind the nose.
fn at(x_over_l: f64, y_over_l: f64, z_over_l: f64) -> Vector3<f64> {
    Vector3::new(60.0 + x_over_l * L, y_over_l * L, z_over_l * L)
}

/// Deterministic pseudo-random numbers in [0, 1) for sampling points.
fn uniforms(n: usize) -> Vec<f64> {
    let mut s: u64 = 0x1234_5678;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect()
}

#[test]
fn attachment_is_60_m_behind_the_nose_by_default() {
    let w = wake(8.0);
    let q = w.table_coordinates(&Vector3::zeros());
    assert_eq!(q, [-60.0 / 70.0, 0.0, 0.0]);
    assert_eq!(w.length(), 70.0);
    assert_eq!(w.airspeed(), 185.0);
}

#[test]
fn deficit_is_confined_to_a_quarter_length_and_decays_downstream() {
    for alpha in [0.0, 8.0] {
        let w = wake(alpha);
        let mut previous = f64::INFINITY;
        for x in [-1.5, -2.0, -3.0, -4.5, -6.0, -7.9] {
            let axis = w.sample(&at(x, 0.0, 0.0)).velocity.x / U;
            assert!(axis > 0.005, "deficit on the axis at x/L {x}: {axis}");
            assert!(
                axis < previous,
                "deficit grows from {previous} to {axis} at x/L {x}"
            );
            previous = axis;
            for z in [0.26, 0.3, 0.4, 0.5, 0.75, 1.0, 1.5] {
                for sign in [-1.0, 1.0] {
                    let u = w.sample(&at(x, 0.0, sign * z)).velocity.x;
                    assert_eq!(u, 0.0, "deficit {u} at x/L {x}, z/L {}", sign * z);
                }
            }
            for z in [-0.2, -0.1, 0.1, 0.2] {
                assert!(w.sample(&at(x, 0.0, z)).velocity.x > 0.0);
            }
        }
    }
    // The documented numbers (8 deg): 3.3 % at 315 m, 1.9 % at 560 m.
    let w = wake(8.0);
    let at_315 = w.sample(&at(-4.5, 0.0, 0.0)).velocity.x / U;
    let at_560 = w.sample(&at(-8.0, 0.0, 0.0)).velocity.x / U;
    assert!((at_315 - 0.0333).abs() < 1e-3, "{at_315}");
    assert!((at_560 - 0.01875).abs() < 1e-3, "{at_560}");
}

#[test]
fn downwash_is_eight_percent_at_315_m_for_8_deg_and_wide() {
    let w = wake(8.0);
    let p = Vector3::new(60.0 - 315.0, 0.0, 0.0);
    let down = w.sample(&p).velocity.z / U;
    assert!((down - 0.08).abs() < 1e-9, "downwash at 315 m: {down}");
    // Present beyond |z/L| = 0.5: 64 % of the axis value at 0.5, 50 % at 0.625.
    for z in [-0.625, -0.5, 0.5, 0.625] {
        let wz = w.sample(&at(-4.5, 0.0, z)).velocity.z / U;
        assert!(wz > 0.45 * down && wz > 0.035, "downwash {wz} at z/L {z}");
    }
    // Still well present at |z/L| = 1 and persisting far behind.
    assert!(w.sample(&at(-4.5, 0.0, 1.0)).velocity.z / U > 0.01);
    assert!(w.sample(&at(-8.0, 0.0, 0.0)).velocity.z / U > 0.065);
    // Where the ACCD settles (about 300 m behind the nose, 50 m down): 3.3 % (6 m/s).
    let accd = w.sample(&Vector3::new(-240.0, 0.0, 50.0)).velocity.z / U;
    assert!((accd - 0.033).abs() < 0.002, "downwash at the ACCD: {accd}");
}

#[test]
fn zero_degrees_is_weaker_than_eight() {
    let (w0, w8) = (wake(0.0), wake(8.0));
    let down0 = w0.sample(&Vector3::new(60.0 - 315.0, 0.0, 0.0)).velocity.z / U;
    assert!(
        (down0 - 0.015).abs() < 1e-9,
        "0 deg downwash at 315 m: {down0}"
    );
    for x in [-1.0, -2.0, -4.5, -7.0] {
        for z in [-0.5, 0.0, 0.125, 0.5, 1.0] {
            let (s0, s8) = (w0.sample(&at(x, 0.1, z)), w8.sample(&at(x, 0.1, z)));
            assert!(s0.velocity.z < s8.velocity.z, "downwash at {x}, {z}");
            assert!(s0.tke < s8.tke, "k at {x}, {z}");
            assert!(s0.velocity.x <= s8.velocity.x, "deficit at {x}, {z}");
        }
    }
}

#[test]
fn turbulent_kinetic_energy_peaks_in_the_wake_and_decays() {
    let w = wake(8.0);
    let intensity = |x: f64, z: f64| (2.0 * w.sample(&at(x, 0.0, z)).tke / 3.0).sqrt() / U;
    // The documented levels on the axis: 3.5 %, 2.2 %, 1.7 %.
    assert!((intensity(-1.0, 0.0) - 0.0346).abs() < 1e-3);
    assert!((intensity(-4.5, 0.0) - 0.0219).abs() < 1e-3);
    assert!((intensity(-8.0, 0.0) - 0.0169).abs() < 1e-3);
    let mut previous = f64::INFINITY;
    for x in [-1.0, -2.0, -3.0, -4.5, -6.0, -8.0] {
        let axis = intensity(x, 0.0);
        assert!(axis < previous);
        previous = axis;
        assert!(intensity(x, 0.5) < axis && intensity(x, 1.0) < intensity(x, 0.5));
    }
    // About 1 % at the settled ACCD.
    let accd = (2.0 * w.sample(&Vector3::new(-240.0, 0.0, 50.0)).tke / 3.0).sqrt() / U;
    assert!((0.007..0.015).contains(&accd), "u'/U at the ACCD: {accd}");
}

#[test]
fn four_degrees_is_the_mean_of_zero_and_eight() {
    let (w0, w4, w8) = (wake(0.0), wake(4.0), wake(8.0));
    let r = uniforms(600);
    for c in r.chunks(3) {
        let p = at(-8.2 + 8.4 * c[0], -2.1 + 4.2 * c[1], -2.1 + 4.2 * c[2]);
        let (s0, s4, s8) = (w0.sample(&p), w4.sample(&p), w8.sample(&p));
        let mean = (s0.velocity + s8.velocity) / 2.0;
        assert!((s4.velocity - mean).norm() <= 1e-12 * (1.0 + mean.norm()));
        assert!((s4.tke - (s0.tke + s8.tke) / 2.0).abs() <= 1e-12 * (1.0 + s8.tke));
    }
    // And 2 deg is a quarter of the way.
    let w2 = wake(2.0);
    let p = at(-3.3, 0.05, 0.4);
    let expected = 0.75 * w0.sample(&p).velocity.z + 0.25 * w8.sample(&p).velocity.z;
    assert!((w2.sample(&p).velocity.z - expected).abs() < 1e-12);
}

#[test]
fn angle_outside_the_tables_is_an_error_naming_field_value_and_range() {
    for alpha in [-1.0, 8.5, f64::NAN] {
        let config = WakeConfig {
            alpha_deg: alpha,
            ..WakeConfig::default()
        };
        let err = Wake::from_config(&config, U).unwrap_err();
        let SimError::InvalidConfig { field, .. } = &err else {
            panic!("{err}")
        };
        assert_eq!(field, "wake.alpha_deg");
        let msg = err.to_string();
        assert!(msg.contains("wake.alpha_deg"), "{msg}");
        if alpha.is_finite() {
            assert!(
                msg.contains(&alpha.to_string()) && msg.contains("[0, 8]"),
                "{msg}"
            );
        }
    }
    let err = Wake::from_config(&WakeConfig::default(), -5.0).unwrap_err();
    assert!(err.to_string().contains("airspeed_mps"), "{err}");
    let config = WakeConfig {
        attachment_from_nose_m: [-60.0, 0.0, f64::INFINITY],
        ..WakeConfig::default()
    };
    let err = Wake::from_config(&config, U).unwrap_err();
    assert!(
        err.to_string().contains("attachment_from_nose_m[2]"),
        "{err}"
    );
}

fn linear_table(x: Vec<f64>, y: Vec<f64>, z: Vec<f64>) -> WakeTable {
    let f = |x: f64, y: f64, z: f64| {
        [
            0.1 + 0.2 * x - 0.3 * y + 0.05 * z,
            -0.02 + 0.01 * x + 0.03 * y,
            0.04 - 0.015 * z + 0.002 * x,
            0.001 + 0.0001 * (x + 9.0) + 0.0002 * (y + 3.0) + 0.0003 * (z + 3.0),
        ]
    };
    let mut fields = [vec![], vec![], vec![], vec![]];
    for &a in &x {
        for &b in &y {
            for &c in &z {
                for (field, v) in fields.iter_mut().zip(f(a, b, c)) {
                    field.push(v);
                }
            }
        }
    }
    let [u, v, w, k] = fields;
    WakeTable::new(WakeTableData {
        description: "linear".into(),
        alpha_deg: 0.0,
        length_scale_m: 70.0,
        x_over_l: x,
        y_over_l: y,
        z_over_l: z,
        u,
        v,
        w,
        k,
    })
    .unwrap()
}

#[test]
fn trilinear_interpolation_reproduces_a_linear_field() {
    let exact = |x: f64, y: f64, z: f64| {
        [
            0.1 + 0.2 * x - 0.3 * y + 0.05 * z,
            -0.02 + 0.01 * x + 0.03 * y,
            0.04 - 0.015 * z + 0.002 * x,
            0.001 + 0.0001 * (x + 9.0) + 0.0002 * (y + 3.0) + 0.0003 * (z + 3.0),
        ]
    };
    // Uniform axes and non-uniform ones (binary search path).
    let tables = [
        linear_table(
            (0..9).map(|i| -8.0 + i as f64).collect(),
            (0..5).map(|i| -2.0 + i as f64).collect(),
            (0..7).map(|i| -1.5 + 0.5 * i as f64).collect(),
        ),
        linear_table(
            vec![-8.0, -7.7, -5.0, -4.9, -2.0, 0.0],
            vec![-2.0, -0.3, 0.0, 1.1, 2.0],
            vec![-1.5, -1.4, 0.2, 0.25, 1.5],
        ),
    ];
    let r = uniforms(3000);
    for table in &tables {
        for c in r.chunks(3) {
            let (x, y, z) = (-8.0 + 8.0 * c[0], -2.0 + 4.0 * c[1], -1.5 + 3.0 * c[2]);
            let got = table.sample(x, y, z);
            for (g, e) in got.iter().zip(exact(x, y, z)) {
                assert!((g - e).abs() < 1e-13, "{g} vs {e} at {x}, {y}, {z}");
            }
        }
        // Nodes and the boundary are inside.
        let corner = table.sample(0.0, 2.0, 1.5);
        assert!((corner[0] - exact(0.0, 2.0, 1.5)[0]).abs() < 1e-14);
    }
}

#[test]
fn outside_the_table_is_free_stream() {
    let w = wake(8.0);
    for p in [
        at(0.1, 0.0, 0.0),   // ahead of the nose
        at(-8.01, 0.0, 0.0), // beyond the table's end
        at(-4.0, 2.05, 0.0),
        at(-4.0, -2.05, 0.0),
        at(-4.0, 0.0, 2.05),
        at(-4.0, 0.0, -2.05),
        Vector3::new(f64::NAN, 0.0, 0.0),
    ] {
        let s = w.sample(&p);
        assert_eq!(s.velocity, Vector3::zeros(), "at {p:?}");
        assert_eq!(s.tke, 0.0);
    }
    let table = AnalyticWake::alpha_8().table();
    assert_eq!(table.sample(-9.0, 0.0, 0.0), [0.0; 4]);
    // A disabled wake is free stream everywhere.
    let none = Wake::none(U).unwrap();
    let s = none.sample(&Vector3::new(-240.0, 0.0, 50.0));
    assert_eq!((s.velocity, s.tke), (Vector3::zeros(), 0.0));
}

#[test]
fn json_round_trip_is_exact() {
    for table in [
        AnalyticWake::alpha_0().table(),
        AnalyticWake::alpha_8().table(),
    ] {
        let text = table.to_json_string();
        let back = WakeTable::from_json_str(&text).unwrap();
        assert_eq!(back, table);
        assert_eq!(back.to_json_string(), text);
    }
    // Through a file, and as the pair a Wake loads.
    let dir = std::env::temp_dir().join(format!("accd-sim-wake-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (low, high) = (dir.join("alpha0.json"), dir.join("alpha8.json"));
    std::fs::write(&low, AnalyticWake::alpha_0().table().to_json_string()).unwrap();
    std::fs::write(&high, AnalyticWake::alpha_8().table().to_json_string()).unwrap();
    let config = WakeConfig {
        alpha_deg: 5.0,
        tables: Some(accd_sim::WakeTableFiles {
            low: low.display().to_string(),
            high: high.display().to_string(),
        }),
        ..WakeConfig::default()
    };
    let from_files = Wake::from_config(&config, U).unwrap();
    let default = Wake::new(&config, U, WakeTables::analytic()).unwrap();
    for x in [-1.0, -3.3, -6.1] {
        let p = at(x, 0.1, 0.3);
        assert_eq!(from_files.sample(&p), default.sample(&p));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

fn small() -> WakeTableData {
    let n = 2 * 3 * 2;
    WakeTableData {
        description: String::new(),
        alpha_deg: 8.0,
        length_scale_m: 70.0,
        x_over_l: vec![-1.0, 0.0],
        y_over_l: vec![-1.0, 0.0, 1.0],
        z_over_l: vec![-1.0, 1.0],
        u: vec![0.0; n],
        v: vec![0.0; n],
        w: vec![0.0; n],
        k: vec![0.0; n],
    }
}

fn table_error(data: WakeTableData) -> String {
    match WakeTable::new(data).unwrap_err() {
        SimError::InvalidTable { reason, .. } => reason,
        e => panic!("not an InvalidTable: {e}"),
    }
}

#[test]
fn loader_errors_name_the_problem() {
    assert!(WakeTable::new(small()).is_ok());

    let mut d = small();
    d.v.pop();
    let msg = table_error(d);
    assert!(
        msg.contains("`v`") && msg.contains("11 values") && msg.contains("= 12"),
        "{msg}"
    );

    let mut d = small();
    d.w[7] = f64::NAN;
    let msg = table_error(d);
    assert!(
        msg.contains("`w`") && msg.contains("non-finite") && msg.contains("index 7"),
        "{msg}"
    );

    let mut d = small();
    d.k[3] = -0.1;
    let msg = table_error(d);
    assert!(msg.contains("`k`") && msg.contains("index 3"), "{msg}");

    let mut d = small();
    d.y_over_l = vec![-1.0, 0.5, 0.5];
    let msg = table_error(d);
    assert!(
        msg.contains("`y_over_l`") && msg.contains("index 2") && msg.contains("increasing"),
        "{msg}"
    );

    let mut d = small();
    d.x_over_l = vec![0.0, -1.0];
    let msg = table_error(d);
    assert!(
        msg.contains("`x_over_l`") && msg.contains("index 1"),
        "{msg}"
    );

    let mut d = small();
    d.z_over_l = vec![0.0];
    d.u = vec![0.0; 6];
    let msg = table_error(d);
    assert!(
        msg.contains("`z_over_l`") && msg.contains("1 point") && msg.contains("at least 2"),
        "{msg}"
    );

    let mut d = small();
    d.length_scale_m = 0.0;
    assert!(table_error(d).contains("length_scale_m"));

    // JSON: the same checks, plus syntax, unknown and missing keys.
    let mut d = small();
    d.u.push(0.0);
    let text = serde_json::to_string(&d).unwrap();
    let err = WakeTable::from_json_str(&text).unwrap_err().to_string();
    assert!(err.contains("`u`") && err.contains("13 values"), "{err}");
    let err = WakeTable::from_json_str("{").unwrap_err().to_string();
    assert!(err.contains("bad JSON"), "{err}");
    let text = serde_json::to_string(&small())
        .unwrap()
        .replace("\"alpha_deg\"", "\"alpha\"");
    let err = WakeTable::from_json_str(&text).unwrap_err().to_string();
    assert!(err.contains("alpha"), "{err}");

    // Files: a missing file is Io, bad content is InvalidTable named by the path.
    let err = WakeTable::from_file("/nonexistent/wake.json", "wake.tables.low").unwrap_err();
    assert!(
        matches!(&err, SimError::Io { path, .. } if path == "/nonexistent/wake.json"),
        "{err}"
    );
    let path = std::env::temp_dir().join(format!("accd-sim-bad-{}.json", std::process::id()));
    let mut d = small();
    d.z_over_l = vec![1.0, -1.0];
    std::fs::write(&path, serde_json::to_string(&d).unwrap()).unwrap();
    let err = WakeTable::from_file(&path, "wake.tables.low").unwrap_err();
    std::fs::remove_file(&path).unwrap();
    let SimError::InvalidTable { table, reason } = err else {
        panic!()
    };
    assert_eq!(table, path.display().to_string());
    assert!(reason.contains("`z_over_l`"), "{reason}");
}

#[test]
fn a_pair_needs_shared_axes_and_increasing_angles() {
    let low = WakeTable::new(WakeTableData {
        alpha_deg: 0.0,
        ..small()
    })
    .unwrap();
    let high = WakeTable::new(small()).unwrap();
    assert!(WakeTables::new(low.clone(), high.clone()).is_ok());
    let err = WakeTables::new(high.clone(), low.clone())
        .unwrap_err()
        .to_string();
    assert!(err.contains("alpha_deg"), "{err}");
    let mut shifted = small();
    shifted.y_over_l[1] = 0.1;
    let err = WakeTables::new(low, WakeTable::new(shifted).unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("`y_over_l`") && err.contains("index 1"),
        "{err}"
    );
}

#[test]
fn default_table_covers_the_documented_grid() {
    let t = AnalyticWake::alpha_8().table();
    let d = t.data();
    assert_eq!(
        (d.x_over_l.len(), d.y_over_l.len(), d.z_over_l.len()),
        (65, 33, 33)
    );
    assert_eq!(d.x_over_l[0], -8.0);
    assert_eq!(*d.x_over_l.last().unwrap(), 0.0);
    assert_eq!((d.z_over_l[0], d.z_over_l[32]), (-2.0, 2.0));
    assert_eq!(t.alpha_deg(), 8.0);
    // Nearly zero at the lateral and vertical edges (no jump to free stream there).
    for &x in &d.x_over_l {
        for e in [-2.0, 2.0] {
            let edge = t.sample(x, e, 0.0);
            let edge_z = t.sample(x, 0.0, e);
            assert!(edge.iter().chain(&edge_z).all(|v| v.abs() < 1e-4));
        }
    }
}

#[test]
fn strength_scales_the_perturbation_linearly_and_the_tke_quadratically() {
    let base = wake(8.0);
    for s in [0.0, 0.7, 1.3] {
        let config = WakeConfig {
            strength: s,
            ..WakeConfig::default()
        };
        let scaled = Wake::from_config(&config, U).unwrap();
        let mut checked = 0;
        for (i, u) in uniforms(300).chunks(3).enumerate() {
            let p = at(-8.0 + 7.0 * u[0], -0.6 + 1.2 * u[1], -0.2 + 0.8 * u[2]);
            let (a, b) = (base.sample(&p), scaled.sample(&p));
            let tol = 1e-12 * (1.0 + a.velocity.norm());
            assert!((b.velocity - a.velocity * s).norm() <= tol, "{s} at {i}");
            assert!(
                (b.tke - a.tke * s * s).abs() <= 1e-12 * (1.0 + a.tke),
                "{s} at {i}"
            );
            checked += (a.velocity.norm() > 0.1) as usize;
        }
        assert!(checked > 20, "the points must lie in the wake: {checked}");
    }
    // Strength 1 is the wake bit for bit.
    let one = Wake::from_config(&WakeConfig::default(), U).unwrap();
    let p = at(-4.5, 0.1, 0.1);
    assert_eq!(one.sample(&p), base.sample(&p));
}
