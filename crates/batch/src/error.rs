//! Errors of the batch env. Every variant names what is wrong, where, and the values involved.

use accd_sim::SimError;
use thiserror::Error;

/// What can go wrong creating, stepping, resetting or restoring a batch.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum BatchError {
    /// An action is not finite.
    #[error("non-finite action {value} for env {env} (component {component}): actions must be finite (values outside [-1, 1] are clipped)")]
    Action {
        /// Env index.
        env: usize,
        /// Component (flap) index.
        component: usize,
        /// The value.
        value: f32,
    },
    /// A step of a batch whose env `env` ended, with autoreset disabled.
    #[error("env {env}'s episode ended and autoreset is disabled: reset it (reset with a mask selecting it) before the next step")]
    ResetNeeded {
        /// Env index.
        env: usize,
    },
    /// A step of a batch whose env `env` was part-way through an interrupted step
    /// ([`crate::BatchEnv::step_interruptible`]).
    #[error("env {env}: a step of this batch was interrupted part-way; reset() it (or set_state()) before stepping or saving again")]
    Interrupted {
        /// Env index.
        env: usize,
    },
    /// A buffer or input has the wrong length.
    #[error("`{what}` has {found} values, expected {expected}")]
    Shape {
        /// Which buffer or input.
        what: &'static str,
        /// Expected number of values.
        expected: usize,
        /// Found.
        found: usize,
    },
    /// True observations were read from a batch that does not keep them.
    #[error("true observations are off: enable them first (the env option true_observation=True)")]
    TrueObservationOff,
    /// Controller commands or states were read from a batch without controllers.
    #[error("this batch steps no controllers: set them first (BatchEnv.set_controller)")]
    NoController,
    /// One env failed.
    #[error("env {env}: {source}")]
    Env {
        /// Env index.
        env: usize,
        /// The error.
        source: Box<BatchError>,
    },
    /// A step or reset panicked: a bug, reported instead of hidden (never a divergence).
    #[error("{0}")]
    Internal(String),
    /// The thread pool could not be built.
    #[error("cannot start the thread pool: {0}")]
    Threads(String),
    /// The simulation reported an error (configuration, state).
    #[error(transparent)]
    Sim(#[from] SimError),
}

/// Result alias of this crate.
pub type Result<T, E = BatchError> = std::result::Result<T, E>;
