//! The interface of one sensor of the sensor model ([`crate::task::sensors`]): what it does at
//! the reset, after each physics step and at each observation, and its saved state. Each sensor
//! owns its noise stream, keyed by the episode's initial-conditions seed and the sensor's name
//! ([`crate::rng::sensor_stream`]), so what one sensor draws never moves another's numbers.

use nalgebra::Vector3;

use crate::rng::{sensor_stream, NormalSampler, Stream, StreamState};
use crate::state_format::StateError;

/// The true quantities a sensor may record after a physics step, beyond the observation's own
/// values (which [`Sensor::sense`] receives).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// The boom tip minus the capture point, TA frame, m.
    pub boom_rel: Vector3<f64>,
}

/// One sensor: a component of [`crate::task::sensors::Sensors`], called in a fixed order but
/// independent of the others (its own stream, its own observation values, its own state).
pub trait Sensor {
    /// The sensor's name: the key of its noise stream and the prefix of its state's fields in
    /// error messages (`sensors.<name>.…`).
    const NAME: &'static str;

    /// Its dynamic state: part of the state format (a change is a change of
    /// [`crate::state_format::FORMAT_VERSION`]).
    type State;

    /// Starts an episode: a fresh noise stream ([`noise_stream`] of `seed`, the episode's
    /// initial-conditions seed), the per-episode draws (biases) and the history filled with
    /// the initial `truth`.
    fn reset(&mut self, seed: u64, truth: &Truth);

    /// After a physics step: records `truth` and takes a measurement if one is due. Sensors
    /// sampled at the observation do nothing here.
    #[inline]
    fn physics_step(&mut self, _truth: &Truth) {}

    /// Replaces the true values of the sensor's quantities in `raw` (the observation's physical
    /// values, in the places of [`crate::task::sensors::SensedLayout`]) by their measurements.
    fn sense(&mut self, raw: &mut [f64]);

    /// The dynamic state.
    fn state(&self) -> Self::State;

    /// Restores a state of [`Sensor::state`] of the same sensor and configuration, checked whole
    /// first: on an error nothing changed.
    fn set_state(&mut self, state: &Self::State) -> Result<(), StateError>;
}

/// The noise stream of the sensor `name` for the episode's initial-conditions seed `seed`:
/// ChaCha8 stream [`sensor_stream`]`(name)` of `seed`, normals by the ziggurat.
pub fn noise_stream(seed: u64, name: &str) -> Stream {
    Stream::with_sampler(seed, sensor_stream(name), NormalSampler::Ziggurat)
}

/// The stream of a saved state of the sensor `name`, refused (field
/// `sensors.<name>.stream.chacha.stream`) if its label is not that sensor's.
pub fn restore_stream(name: &str, state: &StreamState) -> Result<Stream, StateError> {
    let label = sensor_stream(name);
    if state.chacha.stream != label {
        return Err(StateError::invalid(
            &format!("sensors.{name}.stream.chacha.stream"),
            state.chacha.stream,
            format!("the label of the {name} sensor's stream, {label}"),
        ));
    }
    Ok(Stream::from_state(state, NormalSampler::Ziggurat))
}
