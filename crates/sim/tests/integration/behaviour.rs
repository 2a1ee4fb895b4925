//! The ACCD responds to its flaps with the documented signs, is statically stable, conserves
//! rotational energy and angular momentum when no moment acts, and with zero flaps the whole
//! system settles where the paper's open-loop runs settle (no wake, as in the paper's section 4);
//! with the wake on, its mean downwash pushes the ACCD down.

use accd_sim::physics::accd::{mix, rotational_invariants};
use accd_sim::{AccdState, CaptureConfig, CaptureSim, Seeds};
use accd_tether::{TetherConfig, TetherState};
use nalgebra::{UnitQuaternion, Vector3};

const DEG: f64 = std::f64::consts::PI / 180.0;

/// An episode advanced `seconds` with neutral flaps from the straight trailing start.
fn settled(config: &CaptureConfig, seconds: f64) -> CaptureSim {
    let mut sim = CaptureSim::new(&config.clone().validated().unwrap(), Seeds::default()).unwrap();
    let steps = (seconds / sim.time_step()).round() as usize;
    sim.step_many(steps, [0.0; 4]).unwrap();
    sim
}

/// Position change of the ACCD after holding `command` for `seconds` from the settled state.
fn response(command: [f64; 4], seconds: f64) -> (Vector3<f64>, CaptureSim) {
    let mut sim = settled(&CaptureConfig::calm(), 40.0);
    let before = sim.snapshot().unwrap().position;
    let steps = (seconds / sim.time_step()).round() as usize;
    sim.step_many(steps, command).unwrap();
    let after = sim.snapshot().unwrap().position;
    (after - before, sim)
}

#[test]
fn neutral_flaps_settle_about_50_m_below_the_aircraft() {
    let mut sim = settled(&CaptureConfig::calm(), 60.0);
    let s = sim.snapshot().unwrap();
    eprintln!(
        "open loop: ACCD at ({:.2}, {:.2}, {:.2}) m, alpha {:.3} deg, speed {:.2e} m/s, tension {:.0} N",
        s.position.x,
        s.position.y,
        s.position.z,
        s.loads.alpha / DEG,
        s.velocity.norm(),
        s.attachment_tension
    );
    assert!((s.position.z / 50.0 - 1.0).abs() < 0.15);
    assert!(s.velocity.norm() < 0.05);
    assert!(
        s.loads.alpha.abs() < 0.1 * DEG && s.loads.beta.abs() < 0.1 * DEG,
        "trims at zero incidence"
    );
}

#[test]
fn pitch_command_moves_the_accd_vertically() {
    let up = mix(10.0 * DEG, 0.0, 0.0);
    let (d_up, mut sim) = response(up, 5.0);
    let alpha = sim.snapshot().unwrap().loads.alpha;
    let (d_down, _) = response(mix(-10.0 * DEG, 0.0, 0.0), 5.0);
    eprintln!(
        "pitch +10 deg for 5 s: dz = {:.2} m (alpha {:.2} deg); -10 deg: dz = {:.2} m",
        d_up.z,
        alpha / DEG,
        d_down.z
    );
    assert!(
        d_up.z < -5.0,
        "nose-up pitch lifts the ACCD (z is down): {d_up:?}"
    );
    assert!(d_down.z > 5.0, "nose-down pitch lowers it: {d_down:?}");
    assert!(alpha > 2.0 * DEG);
    assert!(
        d_up.y.abs() < 0.01 * d_up.z.abs(),
        "pure pitch stays in the plane of symmetry"
    );
}

#[test]
fn yaw_command_moves_the_accd_laterally() {
    let (d_right, _) = response(mix(0.0, 10.0 * DEG, 0.0), 5.0);
    let (d_left, _) = response(mix(0.0, -10.0 * DEG, 0.0), 5.0);
    eprintln!(
        "yaw +10 deg for 5 s: dy = {:.2} m; -10 deg: dy = {:.2} m",
        d_right.y, d_left.y
    );
    assert!(
        d_right.y > 5.0,
        "nose-right yaw moves the ACCD to starboard: {d_right:?}"
    );
    assert!(d_left.y < -5.0);
    assert!(
        (d_right.y + d_left.y).abs() < 1e-6 * d_right.y.abs(),
        "left and right mirror each other"
    );
}

#[test]
fn roll_command_rolls_the_accd() {
    let (_, mut sim) = response(mix(0.0, 0.0, 2.0 * DEG), 0.1);
    let s = sim.snapshot().unwrap();
    let (roll, pitch, yaw) = s.attitude.euler_angles();
    eprintln!(
        "roll +2 deg for 0.1 s: p = {:.2} rad/s, roll angle {:.1} deg",
        s.omega.x,
        roll / DEG
    );
    assert!(s.omega.x > 1.0, "positive roll rate");
    assert!(
        pitch.abs() < 1.0 * DEG && yaw.abs() < 1.0 * DEG,
        "roll alone does not pitch or yaw much"
    );
}

#[test]
fn disturbed_attitude_returns() {
    let mut sim = settled(&CaptureConfig::calm(), 40.0);
    let tilted = UnitQuaternion::from_euler_angles(0.0, 12.0 * DEG, -8.0 * DEG);
    sim.set_accd_state(AccdState {
        attitude: tilted,
        omega: Vector3::zeros(),
    })
    .unwrap();
    let first = sim.snapshot().unwrap().loads;
    assert!(first.alpha.abs() > 10.0 * DEG && first.beta.abs() > 5.0 * DEG);
    sim.step_many(500, [0.0; 4]).unwrap();
    let s = sim.snapshot().unwrap();
    eprintln!(
        "after 5 s: alpha {:.3} deg, beta {:.3} deg",
        s.loads.alpha / DEG,
        s.loads.beta / DEG
    );
    assert!(s.loads.alpha.abs() < 0.5 * DEG && s.loads.beta.abs() < 0.5 * DEG);
}

#[test]
fn torque_free_accd_conserves_rotational_energy_and_angular_momentum() {
    // Below 1 m/s of airspeed the ACCD feels no aerodynamic moment; the tether joins it at its
    // centre of gravity, so nothing else exerts a moment. A hanging tether at rest in a 0.5 m/s
    // breeze keeps the ACCD there while it tumbles.
    let mut config = CaptureConfig::calm();
    config.aircraft.airspeed = 0.5;
    config.accd.inertia = Some([2.0, 9.0, 8.0]);
    config.tether = TetherConfig {
        time_step: 0.002,
        ..config.tether
    };
    let mut sim = CaptureSim::new(&config.clone().validated().unwrap(), Seeds::default()).unwrap();
    let tether = config.tether_with_tip();
    let s_eq = (tether.total_mass() + tether.tip_mass) * tether.gravity / tether.axial_stiffness;
    sim.set_tether_state(
        TetherState::straight(tether.segments, Vector3::new(0.0, 0.0, 1.0), s_eq).unwrap(),
    )
    .unwrap();
    let start = AccdState {
        attitude: UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0),
        omega: Vector3::new(2.0, 0.4, -0.7),
    };
    sim.set_accd_state(start).unwrap();
    let inertia = config.accd.principal_inertia();
    let (e0, h0) = rotational_invariants(&inertia, &start);
    let (mut worst_e, mut worst_h) = (0.0f64, 0.0f64);
    for _ in 0..5000 {
        sim.step([0.0; 4]).unwrap();
        assert!(sim.snapshot().unwrap().loads.airspeed < 1.0);
        let (e, h) = rotational_invariants(&inertia, sim.accd_state());
        worst_e = worst_e.max((e / e0 - 1.0).abs());
        worst_h = worst_h.max((h - h0).norm() / h0.norm());
    }
    eprintln!("torque-free 10 s: energy drift {worst_e:.2e}, angular momentum drift {worst_h:.2e}");
    assert!(worst_e < 1e-8 && worst_h < 1e-8);
}

#[test]
fn calibrated_depths_match_the_paper() {
    // The expected settling within 15 %: 250 m UHMWPE about 50 m, steel more than 100 m,
    // 300 m UHMWPE about 70 m below the towing aircraft, open loop, no wake.
    let depth = |preset: &str| {
        let config = CaptureConfig {
            tether: TetherConfig::preset(preset).unwrap(),
            ..CaptureConfig::calm()
        };
        let mut sim = settled(&config, 90.0);
        sim.snapshot().unwrap().position.z
    };
    let (uhmwpe, steel, long) = (
        depth("uhmwpe-250m-24mm"),
        depth("steel-250m-24mm"),
        depth("uhmwpe-300m-24mm"),
    );
    eprintln!("calibrated depths: 250 m UHMWPE {uhmwpe:.1} m, steel {steel:.1} m, 300 m UHMWPE {long:.1} m");
    assert!((uhmwpe / 50.0 - 1.0).abs() < 0.15);
    assert!(steel > 100.0);
    assert!((long / 70.0 - 1.0).abs() < 0.15);
}

#[test]
fn wake_downwash_at_8_degrees_pushes_the_accd_down() {
    let depth = |alpha: f64, turbulence: bool| {
        let mut config = CaptureConfig::default();
        config.wake.alpha_deg = alpha;
        config.turbulence.wake_turbulence = turbulence;
        let mut sim = CaptureSim::new(
            &config.validated().unwrap(),
            Seeds {
                initial: 0,
                wake: 7,
                rlv: 0,
            },
        )
        .unwrap();
        sim.step_many(4000, [0.0; 4]).unwrap();
        // Average the last 20 s so that turbulence does not decide the comparison.
        let mut mean = 0.0;
        for _ in 0..200 {
            sim.step_many(10, [0.0; 4]).unwrap();
            mean += sim.snapshot().unwrap().position.z / 200.0;
        }
        mean
    };
    let calm = settled(&CaptureConfig::calm(), 60.0)
        .snapshot()
        .unwrap()
        .position
        .z;
    let (d0, d8) = (depth(0.0, false), depth(8.0, false));
    let d8_turbulent = depth(8.0, true);
    eprintln!("mean ACCD depth: no wake {calm:.1} m, 0 deg wake {d0:.1} m, 8 deg wake {d8:.1} m, with turbulence {d8_turbulent:.1} m");
    assert!(d8 > d0 + 2.0, "the 8 degree downwash pushes the ACCD down");
    assert!(d0 > calm, "even the 0 degree wake has some downwash");
    assert!(
        (d8_turbulent - d8).abs() < 2.0,
        "turbulence averages out around the mean wake"
    );
}
