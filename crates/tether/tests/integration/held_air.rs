//! `Surroundings::held_segment_air`: surroundings that hold the air at every segment centre
//! (sampled once per step) and hand it to the loads in one pass give the accelerations bit for
//! bit as surroundings whose field gives the same air at those centres, for the recursive
//! solver (the hot path) and the dense one; held samples of the wrong length are an error.

use crate::common;

use accd_tether::{
    reference, Solver, Surroundings, TetherConfig, TetherError, TetherModel, TetherState,
};
use nalgebra::Vector3;

type V3 = Vector3<f64>;

/// The air: uniform plus segment k's gust, held (`centres: None`) or as a field that gives
/// each point the gust of the nearest of `centres` (the segment centres).
struct Air {
    uniform: V3,
    gusts: Vec<V3>,
    centres: Option<Vec<V3>>,
}

impl Surroundings for Air {
    type TipReport = ();
    fn air_velocity(&self, _time: f64, p: &V3) -> V3 {
        let Some(centres) = &self.centres else {
            return self.uniform;
        };
        let nearest = (0..centres.len())
            .min_by(|&a, &b| (centres[a] - p).norm().total_cmp(&(centres[b] - p).norm()))
            .unwrap();
        self.uniform + self.gusts[nearest]
    }
    fn held_segment_air(&self, _time: f64) -> Option<(V3, &[V3])> {
        self.centres
            .is_none()
            .then_some((self.uniform, &self.gusts[..]))
    }
    fn air_density(&self, _time: f64, position: &V3) -> f64 {
        0.66 + 7e-5 * position.z
    }
    fn tip_force(&self, _t: f64, _p: &V3, v: &V3) -> V3 {
        let rel = self.uniform - v;
        rel * (0.5 * 0.66 * 0.042 * rel.norm())
    }
}

fn accelerations(
    cfg: &TetherConfig,
    solver: Solver,
    state: &TetherState,
    air: &Air,
) -> Result<Vec<u64>, TetherError> {
    let mut model = TetherModel::new(cfg).unwrap();
    model.set_solver(solver);
    let mut qdd = vec![0.0; state.q.len()];
    model.accelerations(0.0, &state.q, &state.qd, air, &mut qdd)?;
    assert!(qdd.iter().all(|x| x.is_finite()));
    Ok(qdd.iter().map(|x| x.to_bits()).collect())
}

#[test]
fn held_air_in_one_pass_gives_the_same_accelerations_bit_for_bit() {
    let (cfg, flow) =
        reference::towed(&TetherConfig::table3(), reference::StandInBody::accd()).unwrap();
    let n = cfg.segments;
    let state = common::bent_moving_state(&cfg);
    let (centres, _) = common::positions(&cfg, &state.q);
    let gusts: Vec<_> = (0..n)
        .map(|k| {
            let k = k as f64;
            V3::new(
                3.0 * (0.7 * k).sin(),
                2.0 * (1.3 * k).cos(),
                -1.5 * (0.4 * k).sin(),
            )
        })
        .collect();
    let air = |centres: Option<Vec<V3>>, gusts: Vec<V3>| Air {
        uniform: flow.velocity,
        gusts,
        centres,
    };
    for solver in [Solver::Recursive, Solver::Dense] {
        let one_pass = accelerations(&cfg, solver, &state, &air(None, gusts.clone())).unwrap();
        let field = air(Some(centres.clone()), gusts.clone());
        let per_segment = accelerations(&cfg, solver, &state, &field).unwrap();
        assert_eq!(one_pass, per_segment, "{solver:?}");
        // The gusts matter: the same state in the uniform air alone is another answer.
        let calm = accelerations(&cfg, solver, &state, &air(None, vec![V3::zeros(); n])).unwrap();
        assert_ne!(calm, one_pass, "{solver:?}");
        // Held samples must cover every segment.
        let short = accelerations(&cfg, solver, &state, &air(None, gusts[1..].to_vec()));
        assert!(
            matches!(short, Err(TetherError::WrongSize { expected, found, .. }) if expected == n && found == n - 1),
            "{short:?}"
        );
    }
}
