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

/// Maps every core error variant to its Python class.
pub fn to_py(error: TetherError) -> PyErr {
    let kind = match &error {
        TetherError::InvalidConfig { .. } | TetherError::ConfigParse { .. } => Kind::Config,
        TetherError::WrongSize { .. } | TetherError::InvalidState { .. } => Kind::State,
        TetherError::Diverged { .. } | TetherError::Interrupted { .. } => Kind::Simulation,
    };
    raise(kind, error.to_string())
}

/// `Result` conversion into `PyResult`.
pub trait IntoPy<T> {
    /// Converts the error, if any, with [`to_py`].
    fn py_err(self) -> PyResult<T>;
}

impl<T> IntoPy<T> for Result<T, TetherError> {
    fn py_err(self) -> PyResult<T> {
        self.map_err(to_py)
    }
}
