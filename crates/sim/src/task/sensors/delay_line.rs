//! The delay line of the whole observation: the scaled observation handed to the agent is the
//! one of `delay_steps` agent steps ago (a common pipeline delay of every sensor); the first
//! observations of an episode repeat its initial one. A ring of `delay_steps + 1` observations
//! allocated at construction.

use serde::{Deserialize, Serialize};

use crate::state_format::{check_len, StateError};

/// The delay line of one episode (module docs).
#[derive(Debug, Clone)]
pub struct DelayLine {
    /// Values per observation.
    dim: usize,
    /// The last `slots` observations, `dim` values each.
    observations: Vec<f32>,
    /// `delay_steps + 1`.
    slots: usize,
    /// Index (in observations) of the newest entry.
    head: usize,
    /// `observations` holds this episode's observations (false after a reset until the first).
    filled: bool,
}

impl DelayLine {
    /// A delay of `delay_steps` agent steps for observations of `dim` values.
    pub fn new(delay_steps: usize, dim: usize) -> Self {
        DelayLine {
            dim,
            observations: vec![0.0; (delay_steps + 1) * dim],
            slots: delay_steps + 1,
            head: 0,
            filled: false,
        }
    }

    /// Starts an episode: the next observation fills the line.
    pub fn reset(&mut self) {
        self.filled = false;
        self.head = 0;
    }

    /// Puts `obs` (one scaled observation) into the line and replaces it by the one of
    /// `delay_steps` calls ago (the first of the episode while there are fewer).
    pub fn delay(&mut self, obs: &mut [f32]) {
        let dim = self.dim;
        if !self.filled {
            for slot in self.observations.chunks_exact_mut(dim) {
                slot.copy_from_slice(obs);
            }
            self.filled = true;
            self.head = 0;
            return;
        }
        self.head = (self.head + 1) % self.slots;
        let at = self.head * dim;
        self.observations[at..at + dim].copy_from_slice(obs);
        let oldest = ((self.head + 1) % self.slots) * dim;
        obs.copy_from_slice(&self.observations[oldest..oldest + dim]);
    }

    /// The dynamic state.
    pub fn state(&self) -> DelayLineState {
        DelayLineState {
            observations: self.observations.clone(),
            head: self.head as u64,
            filled: self.filled,
        }
    }

    /// Restores a state of [`DelayLine::state`] of a line of the same length, checked whole
    /// first: on an error nothing changed.
    pub fn set_state(&mut self, state: &DelayLineState) -> Result<(), StateError> {
        check_len(
            "sensors.delay.observations",
            state.observations.len(),
            self.observations.len(),
        )?;
        if state.head >= self.slots as u64 {
            return Err(StateError::invalid(
                "sensors.delay.head",
                state.head,
                format!("below {}", self.slots),
            ));
        }
        self.observations.copy_from_slice(&state.observations);
        self.head = state.head as usize;
        self.filled = state.filled;
        Ok(())
    }
}

/// The dynamic state of [`DelayLine`].
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DelayLineState {
    /// The scaled observations (a ring of `delay_steps + 1`).
    pub observations: Vec<f32>,
    /// Index of the newest observation.
    pub head: u64,
    /// The line holds this episode's observations.
    pub filled: bool,
}
