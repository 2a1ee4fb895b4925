//! The attitude estimate of the ACCD's AHRS (`quat_w/x/y/z`): `q_m = q (x) exp(delta / 2)` with
//! the body-axes rotation vector `delta = b_a + sigma_a g` (the bias `b_a` per axis drawn at the
//! reset and constant over the episode, white noise per observation), normalised and put in the
//! hemisphere w >= 0 like the true one. Defaults: 0.1 deg noise and 0.5 deg bias per axis (MEMS
//! AHRS datasheets give about 0.1-0.5 deg in roll and pitch and 0.5-2 deg in heading in dynamic
//! conditions; one value for the three axes here).
//!
//! Draws, from the stream of the name `ahrs`: three normals at the reset (the biases), three at
//! every observation.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::rng::{Stream, StreamState};
use crate::rotation;
use crate::state_format::StateError;
use crate::task::sensors::sensor::{noise_stream, restore_stream, Sensor, Truth};

/// The attitude estimate of one episode (module docs).
#[derive(Debug, Clone)]
pub struct Ahrs {
    /// Standard deviation of the white error per body axis, rad.
    noise: f64,
    /// Standard deviation of the per-episode bias per body axis, rad.
    bias_spread: f64,
    /// Observation index of `quat_w` (four values, w x y z).
    at: usize,
    stream: Stream,
    /// This episode's bias, a rotation vector in body axes, rad.
    bias: Vector3<f64>,
}

impl Ahrs {
    /// An attitude estimate of white error `noise` and bias spread `bias_spread` (rad, standard
    /// deviations per body axis), writing the quaternion at observation index `at`. Reset before
    /// use.
    pub fn new(noise: f64, bias_spread: f64, at: usize) -> Self {
        Ahrs {
            noise,
            bias_spread,
            at,
            stream: noise_stream(0, Self::NAME),
            bias: Vector3::zeros(),
        }
    }

    /// This episode's bias, a rotation vector in body axes, rad.
    pub fn bias(&self) -> Vector3<f64> {
        self.bias
    }
}

impl Sensor for Ahrs {
    const NAME: &'static str = "ahrs";
    type State = AhrsState;

    /// A fresh stream and the episode's biases.
    fn reset(&mut self, seed: u64, _truth: &Truth) {
        self.stream = noise_stream(seed, Self::NAME);
        let s = self.bias_spread;
        let g = &mut self.stream;
        self.bias = Vector3::new(s * g.gaussian(), s * g.gaussian(), s * g.gaussian());
    }

    fn sense(&mut self, raw: &mut [f64]) {
        let s = self.noise;
        let g = &mut self.stream;
        let delta = self.bias + Vector3::new(s * g.gaussian(), s * g.gaussian(), s * g.gaussian());
        let a = self.at;
        let q = UnitQuaternion::new_normalize(Quaternion::new(
            raw[a],
            raw[a + 1],
            raw[a + 2],
            raw[a + 3],
        ));
        let m = (q * rotation::from_scaled_axis(delta)).into_inner();
        let sign = if m.w < 0.0 { -1.0 } else { 1.0 };
        raw[a] = sign * m.w;
        raw[a + 1] = sign * m.i;
        raw[a + 2] = sign * m.j;
        raw[a + 3] = sign * m.k;
    }

    fn state(&self) -> AhrsState {
        AhrsState {
            stream: self.stream.state(),
            bias: self.bias.into(),
        }
    }

    fn set_state(&mut self, state: &AhrsState) -> Result<(), StateError> {
        self.stream = restore_stream(Self::NAME, &state.stream)?;
        self.bias = state.bias.into();
        Ok(())
    }
}

/// The dynamic state of [`Ahrs`].
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AhrsState {
    /// The AHRS's noise stream.
    pub stream: StreamState,
    /// Attitude bias (a rotation vector in body axes), rad.
    pub bias: [f64; 3],
}
