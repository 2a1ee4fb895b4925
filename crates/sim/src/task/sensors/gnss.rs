//! Relative (moving-baseline) GNSS between the aircraft and the ACCD, measuring the ACCD's
//! position offset and velocity relative to the aircraft (`accd_dx/dy/dz`, `accd_vx/vy/vz`):
//! white noise per axis, 5 cm and 5 cm/s by default (RTK accuracy is 1-2 cm horizontally and
//! about twice that vertically; the default allows for the antenna lever arm and multipath
//! under the aircraft). Sampled at the observation: no rate, latency or dropout of its own (the
//! whole-vector delay covers a common pipeline delay).
//!
//! Draws, from the stream of the name `gnss`: six normals at every observation (position x, y,
//! z, then velocity x, y, z).

use serde::{Deserialize, Serialize};

use crate::rng::{Stream, StreamState};
use crate::state_format::StateError;
use crate::task::sensors::sensor::{noise_stream, restore_stream, Sensor, Truth};
use accd_spec::Rules;

accd_spec::config_struct! {
    /// Relative GNSS between the aircraft and the ACCD (module docs).
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct GnssConfig {
        pub position_noise: f64 = 0.05, "m", "[0, 10]",
            "standard deviation of the white noise of each component of the ACCD's position";
        pub velocity_noise: f64 = 0.05, "m/s", "[0, 10]",
            "standard deviation of the white noise of each component of the ACCD's velocity";
    }
}

/// Each field's range is all there is to check.
impl Rules for GnssConfig {}

/// The relative GNSS of one episode (module docs).
#[derive(Debug, Clone)]
pub struct Gnss {
    config: GnssConfig,
    /// Observation index of `accd_dx` and of `accd_vx` (three values each).
    position_at: usize,
    velocity_at: usize,
    stream: Stream,
}

impl Gnss {
    /// The GNSS of `config`, writing the position at observation index `position_at` and the
    /// velocity at `velocity_at`. Reset before use.
    pub fn new(config: &GnssConfig, position_at: usize, velocity_at: usize) -> Self {
        Gnss {
            config: config.clone(),
            position_at,
            velocity_at,
            stream: noise_stream(0, Self::NAME),
        }
    }
}

impl Sensor for Gnss {
    const NAME: &'static str = "gnss";
    type State = GnssState;

    /// A fresh stream.
    fn reset(&mut self, seed: u64, _truth: &Truth) {
        self.stream = noise_stream(seed, Self::NAME);
    }

    fn sense(&mut self, raw: &mut [f64]) {
        let (sp, sv) = (self.config.position_noise, self.config.velocity_noise);
        for i in 0..3 {
            raw[self.position_at + i] += sp * self.stream.gaussian();
        }
        for i in 0..3 {
            raw[self.velocity_at + i] += sv * self.stream.gaussian();
        }
    }

    fn state(&self) -> GnssState {
        GnssState {
            stream: self.stream.state(),
        }
    }

    fn set_state(&mut self, state: &GnssState) -> Result<(), StateError> {
        self.stream = restore_stream(Self::NAME, &state.stream)?;
        Ok(())
    }
}

/// The dynamic state of [`Gnss`].
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GnssState {
    /// The GNSS's noise stream.
    pub stream: StreamState,
}
