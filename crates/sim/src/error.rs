//! Errors of the capture simulation. Every variant names what is wrong and the values involved.

use thiserror::Error;

/// Everything that can go wrong when configuring, loading data for, or stepping an episode.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SimError {
    /// A configuration value is outside its allowed range.
    #[error("invalid config: `{field}` = {value} is outside the allowed range {allowed}")]
    InvalidConfig {
        /// Dotted name of the field.
        field: String,
        /// The offending value, printed.
        value: String,
        /// The allowed range or set, in words.
        allowed: String,
    },
    /// Every value is inside its declared range, but the simulation diverged while settling the
    /// open-loop equilibrium ([`crate::Equilibrium::settle`]): one of the values set away from
    /// its default, or their combination, is more than the simulation can run. The error names
    /// those fields, since no single range says which.
    #[error(
        "invalid config: the open-loop equilibrium of this configuration diverged while settling \
         ({reason}); the fields set away from their defaults, one of which or whose combination \
         the simulation cannot run: {fields}"
    )]
    Unsettled {
        /// The fields set away from their defaults, as `name = value` (or a note that there are
        /// none).
        fields: String,
        /// The divergence.
        reason: String,
    },
    /// A data table (aerodynamic coefficients, wake) is malformed.
    #[error("invalid table `{table}`: {reason}")]
    InvalidTable {
        /// Name of the table or file.
        table: String,
        /// What is wrong: wrong shape, non-finite value, non-monotonic axis (with indices).
        reason: String,
    },
    /// A file could not be read or parsed.
    #[error("cannot read `{path}`: {reason}")]
    Io {
        /// The path.
        path: String,
        /// The reason.
        reason: String,
    },
    /// The simulation left the region where it can be trusted.
    #[error("capture simulation diverged at t = {time:.4} s: {reason}")]
    Diverged {
        /// Simulation time of detection, s.
        time: f64,
        /// What was detected.
        reason: String,
    },
    /// A long loop was stopped by its interruption check (e.g. Ctrl+C between steps).
    #[error("interrupted at t = {time:.4} s ({what})")]
    Interrupted {
        /// Simulation time reached, s.
        time: f64,
        /// What was running.
        what: String,
    },
    /// A controller design found no acceptable solution (a Riccati equation without a
    /// stabilizing solution, a singular reference problem).
    #[error("invalid config: no stabilizing {what} for this configuration ({reason})")]
    Design {
        /// What was designed (the LQR, the Kalman filter, the reference).
        what: String,
        /// Why it failed, with the values that show it.
        reason: String,
    },
    /// The tether model reported an error.
    #[error(transparent)]
    Tether(#[from] accd_tether::TetherError),
    /// A saved state is malformed, corrupted or of another object
    /// ([`crate::state_format::StateError`]).
    #[error(transparent)]
    State(#[from] crate::state_format::StateError),
}

impl SimError {
    /// Shorthand for [`SimError::InvalidConfig`].
    pub fn invalid_config(field: &str, value: impl std::fmt::Display, allowed: &str) -> Self {
        SimError::InvalidConfig {
            field: field.to_owned(),
            value: value.to_string(),
            allowed: allowed.to_owned(),
        }
    }

    /// Shorthand for [`SimError::InvalidTable`].
    pub fn invalid_table(table: &str, reason: impl Into<String>) -> Self {
        SimError::InvalidTable {
            table: table.to_owned(),
            reason: reason.into(),
        }
    }
}

impl From<accd_spec::OutOfRange> for SimError {
    /// A field outside its declared range ([`accd_spec::Fields::check_fields`]).
    fn from(e: accd_spec::OutOfRange) -> Self {
        SimError::InvalidConfig {
            field: e.field,
            value: e.value,
            allowed: e.allowed,
        }
    }
}

/// Result alias of this crate.
pub type Result<T, E = SimError> = std::result::Result<T, E>;
