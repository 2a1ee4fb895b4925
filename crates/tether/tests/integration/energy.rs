//! Conservation and balance of energy.
//!
//! * With damping and aerodynamics off, total energy is conserved: RK4 at dt = 1 ms keeps the
//!   drift under 1e-6 of the largest kinetic energy reached, over 20 s.
//! * With everything on, the rate of change of energy equals the power of the non-conservative
//!   forces (damping, aerodynamics, tip force, apparent force), at random states: this checks every
//!   term of the right-hand side against an independent expression.

use crate::common;

use accd_tether::direction::direction;
use accd_tether::{
    Surroundings, Tether, TetherConfig, TetherModel, TetherState, UniformFlow, Vacuum,
};
use common::{directions, positions, SplitMix, V3};
use nalgebra::Vector3;

/// Runs `config` from `state` for 20 s in vacuum with step `dt`; returns the largest |E - E0|
/// relative to the largest kinetic energy seen.
fn relative_drift(config: TetherConfig, state: TetherState, dt: f64) -> f64 {
    let config = TetherConfig {
        joint_damping_per_mass: 0.0,
        axial_damping_per_mass: 0.0,
        time_step: dt,
        ..config
    };
    let mut tether = Tether::new(&config).unwrap();
    tether.set_state(state).unwrap();
    let e0 = tether.energy().total();
    let (mut max_dev, mut max_kin) = (0.0f64, 0.0f64);
    let steps = (20.0 / dt).round() as usize;
    for _ in 0..steps {
        tether.step(&Vacuum).unwrap();
        let e = tether.energy();
        max_dev = max_dev.max((e.total() - e0).abs());
        max_kin = max_kin.max(e.kinetic);
    }
    assert!(
        max_kin > 1.0,
        "the test must move: max kinetic energy {max_kin} J"
    );
    max_dev / max_kin
}

#[test]
fn table1_tether_conserves_energy() {
    // Released from phi = psi = pi/4, as in the paper's Fig. 9(b), stretched by 1 cm.
    let cfg = TetherConfig {
        flexural_rigidity: 5.0,
        ..TetherConfig::table1()
    };
    let n = cfg.segments;
    let d = direction(std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4);
    let st =
        TetherState::from_directions(&vec![d; n], &vec![Vector3::zeros(); n], 0.01, 0.0).unwrap();
    let drift = relative_drift(cfg, st, 1e-3);
    eprintln!("relative energy drift {drift:e}");
    assert!(drift < 1e-6, "relative energy drift {drift:e}");
}

#[test]
fn table3_tether_with_tip_mass_conserves_energy() {
    // Table 3's tether with a 50 kg tip, bent into an arc from 30 to 75 degrees below the trailing
    // direction with a lateral component, released from rest: it swings, bends and stretches.
    let cfg = TetherConfig {
        tip_mass: 50.0,
        ..TetherConfig::table3()
    };
    let n = cfg.segments;
    let dirs: Vec<_> = (0..n)
        .map(|k| {
            let f = k as f64 / (n - 1) as f64;
            direction((30.0 + 45.0 * f).to_radians(), (10.0 * f).to_radians())
        })
        .collect();
    let st = TetherState::from_directions(&dirs, &vec![Vector3::zeros(); n], 0.0, 0.0).unwrap();
    let drift = relative_drift(cfg, st, 1e-3);
    eprintln!("relative energy drift {drift:e}");
    assert!(drift < 1e-6, "relative energy drift {drift:e}");
}

/// Surroundings with everything switched on: uniform wind with a cross component, a frame
/// acceleration and a velocity-dependent tip force.
struct Busy {
    flow: UniformFlow,
}

impl Surroundings for Busy {
    type TipReport = ();
    fn air_velocity(&self, t: f64, p: &V3) -> V3 {
        self.flow.velocity
            + Vector3::new(0.0, 0.3 * p.z, -0.2 * p.x) * 0.01
            + Vector3::new(0.0, t.sin(), 0.0)
    }
    fn air_density(&self, _t: f64, p: &V3) -> f64 {
        self.flow.density * (1.0 + 1e-4 * p.z)
    }
    fn frame_acceleration(&self, _t: f64) -> V3 {
        self.flow.frame_acceleration
    }
    fn tip_force(&self, t: f64, p: &V3, v: &V3) -> V3 {
        self.flow.tip_force(t, p, v) + Vector3::new(0.0, 10.0, -5.0)
    }
}

#[test]
fn power_balance_at_random_states() {
    let mut rng = SplitMix(7);
    for trial in 0..40 {
        let n = 1 + (rng.next() * 15.0) as usize;
        let cfg = TetherConfig {
            segments: n,
            length: 8.0 * n as f64,
            tip_mass: rng.range(0.0, 80.0),
            flexural_rigidity: rng.range(0.0, 400.0),
            joint_damping_per_mass: rng.range(0.0, 5.0),
            ..TetherConfig::table3()
        };
        let flow = UniformFlow {
            velocity: Vector3::new(
                -rng.range(0.0, 185.0),
                rng.range(-5.0, 5.0),
                rng.range(-5.0, 5.0),
            ),
            density: 0.66,
            frame_acceleration: Vector3::new(
                rng.range(-3.0, 3.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ),
            tip_force: Vector3::zeros(),
            tip_drag_area: rng.range(0.0, 0.1),
        };
        let env = Busy { flow };
        let mut q = vec![rng.range(-0.01, 0.05)];
        let mut qd = vec![rng.range(-0.5, 0.5)];
        for _ in 0..n {
            q.extend([rng.range(-0.5, 2.0), rng.range(-0.8, 0.8)]);
            qd.extend([rng.range(-0.5, 0.5), rng.range(-0.5, 0.5)]);
        }
        let t = rng.range(0.0, 10.0);
        let mut model = TetherModel::new(&cfg).unwrap();
        let mut qdd = vec![0.0; cfg.dofs()];
        model.accelerations(t, &q, &qd, &env, &mut qdd).unwrap();

        // dE/dt by central differences along the trajectory direction (q', q'').
        let h = 1e-6;
        let shifted = |sign: f64, model: &mut TetherModel| {
            let qs: Vec<f64> = q.iter().zip(&qd).map(|(a, b)| a + sign * h * b).collect();
            let qds: Vec<f64> = qd.iter().zip(&qdd).map(|(a, b)| a + sign * h * b).collect();
            model.energy(&qs, &qds).unwrap().total()
        };
        let de_dt = (shifted(1.0, &mut model) - shifted(-1.0, &mut model)) / (2.0 * h);

        // Power of the non-conservative forces, written from their definitions.
        let l = cfg.segment_length();
        let m = cfg.segment_mass();
        let (centres, tip) = positions(&cfg, &q);
        let dirs = directions(&cfg, &q);
        let vel = |qv: &Vec<f64>| {
            let plus: Vec<f64> = qv.iter().zip(&qd).map(|(a, b)| a + h * b).collect();
            let minus: Vec<f64> = qv.iter().zip(&qd).map(|(a, b)| a - h * b).collect();
            let (cp, tp) = positions(&cfg, &plus);
            let (cm, tm) = positions(&cfg, &minus);
            let (ep, em) = (directions(&cfg, &plus), directions(&cfg, &minus));
            let vc: Vec<V3> = cp
                .iter()
                .zip(&cm)
                .map(|(a, b)| (a - b) / (2.0 * h))
                .collect();
            let ed: Vec<V3> = ep
                .iter()
                .zip(&em)
                .map(|(a, b)| (a - b) / (2.0 * h))
                .collect();
            (vc, (tp - tm) / (2.0 * h), ed)
        };
        let (vc, vtip, edot) = vel(&q);
        let a0 = env.frame_acceleration(t);
        let mut power = -cfg.axial_damping() * qd[0] * qd[0];
        for j in 0..n.saturating_sub(1) {
            let rel = dirs[j + 1].cross(&edot[j + 1]) - dirs[j].cross(&edot[j]);
            power -= cfg.joint_damping() * rel.norm_squared();
        }
        for k in 0..n {
            let rho = env.air_density(t, &centres[k]);
            let v = env.air_velocity(t, &centres[k]) - vc[k];
            let vt = dirs[k] * v.dot(&dirs[k]);
            let vn = v - vt;
            let f = (vn * (cfg.normal_drag_coefficient * vn.norm())
                + vt * (std::f64::consts::PI * cfg.tangential_drag_coefficient * vt.norm()))
                * (0.5 * rho * cfg.diameter * l);
            power += f.dot(&vc[k]) - m * a0.dot(&vc[k]);
        }
        power += env.tip_force(t, &tip, &vtip).dot(&vtip) - cfg.tip_mass * a0.dot(&vtip);
        let scale = power.abs().max(1.0);
        assert!(
            (de_dt - power).abs() < 1e-5 * scale,
            "trial {trial} (n = {n}): dE/dt = {de_dt} but the forces deliver {power} W"
        );
    }
}
