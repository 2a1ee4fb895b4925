//! `Surroundings::held_segment_air`: surroundings that hold the air at every segment centre
//! (sampled once per step) and hand it to the loads in one pass give the accelerations and the
//! tip report bit for bit as when the loads ask `segment_air_velocity` segment by segment, for
//! the recursive solver (the hot path) and the dense one.

use accd_tether::direction::direction;
use accd_tether::{reference, Solver, Surroundings, TetherConfig, TetherModel, TetherState};
use nalgebra::Vector3;

/// Air held per segment: a uniform part and a different gust at every segment centre.
struct Held {
    uniform: Vector3<f64>,
    gusts: Vec<Vector3<f64>>,
    /// Whether the loads get the samples in one pass (`held_segment_air`).
    in_one_pass: bool,
}

impl Surroundings for Held {
    type TipReport = ();
    fn air_velocity(&self, _time: f64, _position: &Vector3<f64>) -> Vector3<f64> {
        self.uniform
    }
    fn segment_air_velocity(&self, _time: f64, segment: usize, _p: &Vector3<f64>) -> Vector3<f64> {
        self.uniform + self.gusts[segment]
    }
    fn held_segment_air(&self, _time: f64) -> Option<(Vector3<f64>, &[Vector3<f64>])> {
        self.in_one_pass.then_some((self.uniform, &self.gusts[..]))
    }
    fn air_density(&self, _time: f64, position: &Vector3<f64>) -> f64 {
        0.66 + 7e-5 * position.z
    }
    fn tip_force(&self, _t: f64, _p: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
        let rel = self.uniform - v;
        rel * (0.5 * 0.66 * 0.042 * rel.norm())
    }
}

#[test]
fn held_air_in_one_pass_gives_the_same_accelerations_bit_for_bit() {
    let (cfg, flow) =
        reference::towed(&TetherConfig::table3(), reference::StandInBody::accd()).unwrap();
    let n = cfg.segments;
    let dirs: Vec<_> = (0..n)
        .map(|k| direction(0.3 + 0.02 * k as f64, 0.1 - 0.01 * k as f64))
        .collect();
    let rates: Vec<_> = (0..n)
        .map(|k| Vector3::new(0.0, 0.2 * (k as f64).sin(), -0.15 * (k as f64).cos()))
        .collect();
    let state = TetherState::from_directions(&dirs, &rates, 0.01, 0.05).unwrap();
    let gusts: Vec<_> = (0..n)
        .map(|k| {
            let k = k as f64;
            Vector3::new(
                3.0 * (0.7 * k).sin(),
                2.0 * (1.3 * k).cos(),
                -1.5 * (0.4 * k).sin(),
            )
        })
        .collect();
    for solver in [Solver::Recursive, Solver::Dense] {
        let run = |in_one_pass: bool| {
            let air = Held {
                uniform: flow.velocity,
                gusts: gusts.clone(),
                in_one_pass,
            };
            let mut model = TetherModel::new(&cfg).unwrap();
            model.set_solver(solver);
            let mut qdd = vec![0.0; state.q.len()];
            model
                .accelerations(0.0, &state.q, &state.qd, &air, &mut qdd)
                .unwrap();
            qdd
        };
        let (one_pass, per_segment) = (run(true), run(false));
        assert!(one_pass.iter().all(|x| x.is_finite()));
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&one_pass), bits(&per_segment), "{solver:?}");
        // The gusts matter: the same state in the uniform air alone is another answer.
        let uniform = Held {
            uniform: flow.velocity,
            gusts: vec![Vector3::zeros(); n],
            in_one_pass: true,
        };
        let mut model = TetherModel::new(&cfg).unwrap();
        model.set_solver(solver);
        let mut calm = vec![0.0; state.q.len()];
        model
            .accelerations(0.0, &state.q, &state.qd, &uniform, &mut calm)
            .unwrap();
        assert_ne!(bits(&calm), bits(&one_pass), "{solver:?}");
    }
}
