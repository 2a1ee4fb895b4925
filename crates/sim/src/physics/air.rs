//! The air around the tether and the ACCD, beyond the free stream: [`AirDisturbance`], what
//! the capture simulation samples (the wake field of [`crate::physics::wake_field`] is the one in use).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::physics::turbulence::TurbulenceState;
use crate::state_format::StateError;

type V3 = Vector3<f64>;

/// The time-dependent state of an air disturbance ([`AirDisturbance`]).
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum AirState {
    /// A steady disturbance (or none): nothing changes with time.
    Steady,
    /// A wake with turbulence ([`crate::WakeField`]).
    Turbulence(Box<TurbulenceState>),
}

/// Disturbances of the air relative to the free stream (wake, turbulence), anywhere in the TA
/// frame. `velocity` must be a pure function during a step; `advance` moves time-dependent
/// parts (turbulence) forward once per step.
pub trait AirDisturbance: Send + Sync {
    /// Velocity added to the free stream at `position` (TA frame, m), m/s.
    fn velocity(&self, time: f64, position: &V3) -> V3;

    /// [`AirDisturbance::velocity`] at each of `positions` into `out` (as long), m/s: one call
    /// for the points of a step, so that a field samples them in one inlined loop.
    fn velocities(&self, time: f64, positions: &[V3], out: &mut [V3]) {
        for (v, p) in out.iter_mut().zip(positions) {
            *v = self.velocity(time, p);
        }
    }

    /// Advances internal state from `time` to `time + dt`.
    fn advance(&mut self, _time: f64, _dt: f64) -> Result<()> {
        Ok(())
    }

    /// Restarts at time 0 with the random streams of `wake_seed`. Must not allocate.
    fn reset(&mut self, _wake_seed: u64) {}

    /// Declares points that will be sampled during the coming step (before any of them is):
    /// a disturbance that generates its field lazily generates it there. Must not allocate.
    fn prepare(&mut self, _points: &[V3]) {}

    /// Declares that the disturbance may be sampled anywhere (the stepper cannot say where
    /// beforehand). Must not allocate.
    fn prepare_all(&mut self) {}

    /// A boxed copy (the episode is cloned for snapshots).
    fn clone_box(&self) -> Box<dyn AirDisturbance>;

    /// The time-dependent state ([`AirState::Steady`] for a steady disturbance).
    fn state(&self) -> AirState {
        AirState::Steady
    }

    /// Restores a state from `state` of a disturbance built from the same config; checks it
    /// first and changes nothing on an error.
    fn set_state(&mut self, state: AirState) -> Result<(), StateError> {
        match state {
            AirState::Steady => Ok(()),
            AirState::Turbulence(_) => Err(StateError::invalid(
                "air",
                "the state of a turbulent wake",
                "the state of a steady disturbance",
            )),
        }
    }
}
