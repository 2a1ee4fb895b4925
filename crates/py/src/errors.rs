//! The one mapping from core errors to the Python exception tree of `accd_gym.errors`:
//!
//! ```text
//! AccdError
//!  +-- ConfigError (also ValueError)      invalid configuration: field, value, allowed range
//!  +-- StateError (also ValueError)       invalid state or array argument
//!  +-- SimulationError (also RuntimeError) the simulation diverged
//! ```
//!
//! An interrupted loop raises what the signal handler raised (see [`crate::signals`]); a bug
//! (a panic) is a `RuntimeError`, never one of these.
//!
//! The classes are defined in Python (multiple inheritance from the built-ins) and looked up here
//! when an error is raised, which is rare, so no caching is needed.

use accd_batch::BatchError;
use accd_sim::{SimError, StateError};
use accd_tether::TetherError;
use pyo3::prelude::*;
use pyo3::types::PyType;

/// Which class of `accd_gym.errors` an error maps to.
#[derive(Clone, Copy)]
pub enum Kind {
    Config,
    State,
    Simulation,
}

impl Kind {
    fn class_name(self) -> &'static str {
        match self {
            Kind::Config => "ConfigError",
            Kind::State => "StateError",
            Kind::Simulation => "SimulationError",
        }
    }
}

/// A Python exception of `kind` with `message`.
pub fn raise(kind: Kind, message: impl Into<String>) -> PyErr {
    let message = message.into();
    Python::attach(|py| {
        let class = py
            .import("accd_gym.errors")
            .and_then(|m| m.getattr(kind.class_name()))
            .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
        match class {
            Ok(class) => PyErr::from_type(class, message),
            Err(import_error) => import_error,
        }
    })
}

/// A core error with its place in the Python exception tree: every crate's error enum is mapped
/// here and nowhere else.
pub trait ToPy {
    /// The class of `accd_gym.errors` this error raises; `None` for a bug (a `RuntimeError`).
    fn kind(&self) -> Option<Kind>;

    /// The Python exception: the class of [`ToPy::kind`] with the error's message.
    fn to_py(&self) -> PyErr
    where
        Self: std::fmt::Display,
    {
        match self.kind() {
            Some(kind) => raise(kind, self.to_string()),
            None => pyo3::exceptions::PyRuntimeError::new_err(self.to_string()),
        }
    }
}

impl ToPy for TetherError {
    fn kind(&self) -> Option<Kind> {
        Some(match self {
            TetherError::InvalidConfig { .. } | TetherError::ConfigParse { .. } => Kind::Config,
            TetherError::WrongSize { .. } | TetherError::InvalidState { .. } => Kind::State,
            TetherError::Diverged { .. } | TetherError::Interrupted { .. } => Kind::Simulation,
        })
    }
}

impl ToPy for StateError {
    fn kind(&self) -> Option<Kind> {
        Some(Kind::State)
    }
}

impl ToPy for SimError {
    fn kind(&self) -> Option<Kind> {
        match self {
            SimError::Tether(e) => e.kind(),
            SimError::InvalidConfig { .. }
            | SimError::Unsettled { .. }
            | SimError::InvalidTable { .. }
            | SimError::Io { .. }
            | SimError::Design { .. } => Some(Kind::Config),
            SimError::Diverged { .. } | SimError::Interrupted { .. } => Some(Kind::Simulation),
            SimError::State(e) => e.kind(),
        }
    }
}

impl ToPy for BatchError {
    /// Bad actions and shapes are `StateError` (a `ValueError`); one env's error maps as its
    /// cause does; a panic in a step (a bug) is a `RuntimeError`.
    fn kind(&self) -> Option<Kind> {
        match self {
            BatchError::Sim(e) => e.kind(),
            BatchError::Action { .. }
            | BatchError::Shape { .. }
            | BatchError::ResetNeeded { .. }
            | BatchError::Interrupted { .. }
            | BatchError::TrueObservationOff
            | BatchError::NoController => Some(Kind::State),
            BatchError::Env { source, .. } => source.kind(),
            BatchError::Threads(_) => Some(Kind::Simulation),
            BatchError::Internal(_) => None,
        }
    }
}

/// `Result` conversion into `PyResult`.
pub trait IntoPy<T> {
    /// Converts the error, if any, with [`ToPy::to_py`].
    fn py_err(self) -> PyResult<T>;
}

impl<T, E: ToPy + std::fmt::Display> IntoPy<T> for Result<T, E> {
    fn py_err(self) -> PyResult<T> {
        self.map_err(|e| e.to_py())
    }
}
