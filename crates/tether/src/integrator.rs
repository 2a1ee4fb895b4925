//! Classical fixed-step fourth-order Runge-Kutta for the second-order system q'' = a(t, q, q'),
//! with its stage buffers allocated once.

use crate::dynamics::TetherModel;
use crate::error::{Result, TetherError};
use crate::state::TetherState;
use crate::surroundings::Surroundings;

/// The largest magnitude a coordinate (m, rad) or rate (m/s, rad/s) may reach: beyond it a state
/// is a divergence, even where it is still finite (a state of 1e63 gives infinite energies).
pub const STATE_BOUND: f64 = 1e6;

/// Whether any entry is NaN or beyond `bound` in magnitude (for positive `bound`, the bits of
/// `|x|` compare as the values do; NaN and infinity compare above every finite bound).
#[inline]
fn any_beyond(v: &[f64], bound: f64) -> bool {
    const MAGNITUDE: u64 = 0x7FFF_FFFF_FFFF_FFFF;
    let limit = bound.to_bits();
    let mut any = 0u64;
    for x in v {
        any |= u64::from(x.to_bits() & MAGNITUDE > limit);
    }
    any != 0
}

/// RK4 stage buffers for one model size.
#[derive(Debug, Clone)]
pub struct Rk4 {
    q_stage: Vec<f64>,
    qd_stage: Vec<f64>,
    qd2: Vec<f64>,
    qd3: Vec<f64>,
    qd4: Vec<f64>,
    a1: Vec<f64>,
    a2: Vec<f64>,
    a3: Vec<f64>,
    a4: Vec<f64>,
}

impl Rk4 {
    /// Buffers for `dofs` generalized coordinates.
    pub fn new(dofs: usize) -> Self {
        let z = vec![0.0; dofs];
        Rk4 {
            q_stage: z.clone(),
            qd_stage: z.clone(),
            qd2: z.clone(),
            qd3: z.clone(),
            qd4: z.clone(),
            a1: z.clone(),
            a2: z.clone(),
            a3: z.clone(),
            a4: z,
        }
    }

    /// Advances `state` by `dt` seconds. On error the state is left unchanged.
    pub fn step<S: Surroundings + ?Sized>(
        &mut self,
        model: &mut TetherModel,
        state: &mut TetherState,
        surroundings: &S,
        dt: f64,
    ) -> Result<()> {
        let dim = model.dofs();
        if state.q.len() != dim || state.qd.len() != dim {
            return Err(TetherError::WrongSize {
                what: "state",
                expected: dim,
                found: state.q.len(),
            });
        }
        let t = state.time;
        let h = 0.5 * dt;
        let (q, qd) = (&state.q, &state.qd);

        model.accelerations(t, q, qd, surroundings, &mut self.a1)?;

        for i in 0..dim {
            self.q_stage[i] = q[i] + h * qd[i];
            self.qd2[i] = qd[i] + h * self.a1[i];
        }
        model.accelerations(t + h, &self.q_stage, &self.qd2, surroundings, &mut self.a2)?;

        for i in 0..dim {
            self.q_stage[i] = q[i] + h * self.qd2[i];
            self.qd3[i] = qd[i] + h * self.a2[i];
        }
        model.accelerations(t + h, &self.q_stage, &self.qd3, surroundings, &mut self.a3)?;

        for i in 0..dim {
            self.q_stage[i] = q[i] + dt * self.qd3[i];
            self.qd4[i] = qd[i] + dt * self.a3[i];
        }
        model.accelerations(t + dt, &self.q_stage, &self.qd4, surroundings, &mut self.a4)?;

        let w = dt / 6.0;
        for i in 0..dim {
            self.q_stage[i] = q[i] + w * (qd[i] + 2.0 * (self.qd2[i] + self.qd3[i]) + self.qd4[i]);
            self.qd_stage[i] =
                qd[i] + w * (self.a1[i] + 2.0 * (self.a2[i] + self.a3[i]) + self.a4[i]);
        }
        let new_time = t + dt;
        if any_beyond(&self.q_stage, STATE_BOUND) || any_beyond(&self.qd_stage, STATE_BOUND) {
            let (i, v) = self
                .q_stage
                .iter()
                .chain(self.qd_stage.iter())
                .copied()
                .enumerate()
                .find(|(_, v)| v.is_nan() || v.abs() > STATE_BOUND)
                .unwrap_or((0, f64::NAN));
            let what = if i < dim { "q" } else { "qd" };
            return Err(TetherError::Diverged {
                time: new_time,
                reason: format!(
                    "{what}[{}] = {v:e} is non-finite or beyond {STATE_BOUND:e}",
                    i % dim
                ),
            });
        }
        std::mem::swap(&mut state.q, &mut self.q_stage);
        std::mem::swap(&mut state.qd, &mut self.qd_stage);
        state.time = new_time;
        Ok(())
    }
}
