//! Errors of the tether model. Every variant carries the values a user needs to fix the cause.

use thiserror::Error;

/// Everything that can go wrong when configuring, setting up or stepping a tether.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TetherError {
    /// A configuration value is outside its allowed range.
    #[error("invalid tether config: `{field}` = {value} is outside the allowed range {allowed}")]
    InvalidConfig {
        /// Dotted name of the field, as in the serialized config.
        field: String,
        /// The offending value, printed.
        value: String,
        /// The allowed range or set, in words (e.g. "(0, 2000] m").
        allowed: String,
    },
    /// A configuration document could not be parsed (unknown key, wrong type, bad syntax).
    #[error("invalid tether config: {message}")]
    ConfigParse {
        /// The parser's message, naming the key or position.
        message: String,
    },
    /// An array handed to the model has the wrong length.
    #[error("`{what}` has length {found}, expected {expected}")]
    WrongSize {
        /// Name of the argument.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Length received.
        found: usize,
    },
    /// A state value handed to the model is not usable (non-finite, not a unit vector, ...).
    #[error("invalid tether state: `{field}` = {value}: {reason}")]
    InvalidState {
        /// Name of the state field (with index where relevant).
        field: String,
        /// The offending value, printed.
        value: String,
        /// Why it is rejected.
        reason: String,
    },
    /// The simulation left the region where it can be trusted.
    #[error("tether simulation diverged at t = {time:.4} s: {reason}")]
    Diverged {
        /// Simulation time of detection, s.
        time: f64,
        /// What was detected (non-finite state, coordinate singularity, mass matrix not positive definite).
        reason: String,
    },
    /// A long loop was stopped by its interruption check (e.g. Ctrl+C); the state is the one
    /// reached after the last whole step.
    #[error("interrupted at t = {time:.4} s after {done} of {requested} steps")]
    Interrupted {
        /// Simulation time reached, s.
        time: f64,
        /// Whole steps taken.
        done: usize,
        /// Steps asked for.
        requested: usize,
    },
}

impl TetherError {
    /// Shorthand for [`TetherError::InvalidConfig`].
    pub fn invalid_config(field: &str, value: impl std::fmt::Display, allowed: &str) -> Self {
        TetherError::InvalidConfig {
            field: field.to_owned(),
            value: value.to_string(),
            allowed: allowed.to_owned(),
        }
    }
}

impl From<accd_spec::OutOfRange> for TetherError {
    /// A field outside its declared range ([`accd_spec::Fields::check_fields`]).
    fn from(e: accd_spec::OutOfRange) -> Self {
        TetherError::InvalidConfig {
            field: e.field,
            value: e.value,
            allowed: e.allowed,
        }
    }
}

/// Result alias of this crate.
pub type Result<T, E = TetherError> = std::result::Result<T, E>;
