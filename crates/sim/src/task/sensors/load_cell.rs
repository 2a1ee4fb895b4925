//! The load cell at the attachment, measuring the tether tension (`tension`): white noise,
//! 100 N by default (0.02 % of the tether's 550 kN breaking tension; a load cell of 0.1 %
//! full-scale accuracy sized for the 275 kN overload limit gives about 275 N of bias-type error,
//! of which the white part here is a fraction). Sampled at the observation: no rate, latency or
//! dropout of its own.
//!
//! Draws, from the stream of the name `load_cell`: one normal at every observation.

use serde::{Deserialize, Serialize};

use crate::rng::{Stream, StreamState};
use crate::state_format::StateError;
use crate::task::sensors::sensor::{noise_stream, restore_stream, Sensor, Truth};

/// The load cell of one episode (module docs).
#[derive(Debug, Clone)]
pub struct LoadCell {
    /// Standard deviation of the white noise, N.
    noise: f64,
    /// Observation index of `tension`.
    at: usize,
    stream: Stream,
}

impl LoadCell {
    /// A load cell of white noise `noise` (N, standard deviation), writing the tension at
    /// observation index `at`. Reset before use.
    pub fn new(noise: f64, at: usize) -> Self {
        LoadCell {
            noise,
            at,
            stream: noise_stream(0, Self::NAME),
        }
    }
}

impl Sensor for LoadCell {
    const NAME: &'static str = "load_cell";
    type State = LoadCellState;

    /// A fresh stream.
    fn reset(&mut self, seed: u64, _truth: &Truth) {
        self.stream = noise_stream(seed, Self::NAME);
    }

    fn sense(&mut self, raw: &mut [f64]) {
        raw[self.at] += self.noise * self.stream.gaussian();
    }

    fn state(&self) -> LoadCellState {
        LoadCellState {
            stream: self.stream.state(),
        }
    }

    fn set_state(&mut self, state: &LoadCellState) -> Result<(), StateError> {
        self.stream = restore_stream(Self::NAME, &state.stream)?;
        Ok(())
    }
}

/// The dynamic state of [`LoadCell`].
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoadCellState {
    /// The load cell's noise stream.
    pub stream: StreamState,
}
