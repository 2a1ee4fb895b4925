//! The gyros of the ACCD's IMU, measuring the body rates (`rate_p/q/r`):
//! `omega_m = omega + b_g + sigma_g g` per axis, the bias `b_g ~ N(0, rate_bias^2)` per axis drawn
//! at the reset and constant over the episode (the turn-on bias of an uncalibrated MEMS gyro),
//! white noise per observation (IEEE Std 952-1997's rate white noise sampled at the
//! observation). Defaults: 0.002 rad/s noise and 0.005 rad/s bias (0.11 and 0.29 deg/s: an
//! uncalibrated MEMS gyro).
//!
//! Draws, from the stream of the name `gyro`: three normals at the reset (the biases), three at
//! every observation.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::rng::{Stream, StreamState};
use crate::state_format::StateError;
use crate::task::sensors::sensor::{noise_stream, restore_stream, Sensor, Truth};

/// The gyros of one episode (module docs).
#[derive(Debug, Clone)]
pub struct Gyro {
    /// Standard deviation of the white noise per axis, rad/s.
    noise: f64,
    /// Standard deviation of the per-episode bias per axis, rad/s.
    bias_spread: f64,
    /// Observation index of `rate_p` (three values).
    at: usize,
    stream: Stream,
    /// This episode's bias per body axis, rad/s.
    bias: Vector3<f64>,
}

impl Gyro {
    /// Gyros of white noise `noise` and bias spread `bias_spread` (rad/s, standard deviations),
    /// writing the body rates at observation index `at`. Reset before use.
    pub fn new(noise: f64, bias_spread: f64, at: usize) -> Self {
        Gyro {
            noise,
            bias_spread,
            at,
            stream: noise_stream(0, Self::NAME),
            bias: Vector3::zeros(),
        }
    }

    /// This episode's bias per body axis, rad/s.
    pub fn bias(&self) -> Vector3<f64> {
        self.bias
    }
}

impl Sensor for Gyro {
    const NAME: &'static str = "gyro";
    type State = GyroState;

    /// A fresh stream and the episode's biases.
    fn reset(&mut self, seed: u64, _truth: &Truth) {
        self.stream = noise_stream(seed, Self::NAME);
        let s = self.bias_spread;
        let g = &mut self.stream;
        self.bias = Vector3::new(s * g.gaussian(), s * g.gaussian(), s * g.gaussian());
    }

    fn sense(&mut self, raw: &mut [f64]) {
        for i in 0..3 {
            raw[self.at + i] += self.bias[i] + self.noise * self.stream.gaussian();
        }
    }

    fn state(&self) -> GyroState {
        GyroState {
            stream: self.stream.state(),
            bias: self.bias.into(),
        }
    }

    fn set_state(&mut self, state: &GyroState) -> Result<(), StateError> {
        self.stream = restore_stream(Self::NAME, &state.stream)?;
        self.bias = state.bias.into();
        Ok(())
    }
}

/// The dynamic state of [`Gyro`].
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GyroState {
    /// The gyros' noise stream.
    pub stream: StreamState,
    /// Body-rate biases, rad/s.
    pub bias: [f64; 3],
}
