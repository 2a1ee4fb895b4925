//! `accd_gym._core.EnvConfig`: a validated environment configuration. Python's keyword
//! arguments cross into Rust once, as one JSON document, and are parsed and validated there
//! once; the envs are built from this object without validating again. It pickles as its JSON
//! (unpickling validates it, as any new configuration is).

use std::sync::Arc;

use accd_sim::{EnvConfig, Valid};
use pyo3::prelude::*;
use pyo3::types::{PyTuple, PyType};

use crate::errors::{raise, IntoPy, Kind};

/// A validated environment configuration (defaults filled in). Build it from JSON; read it with
/// ``to_json()``.
#[pyclass(name = "EnvConfig", module = "accd_gym._core", frozen)]
pub struct PyEnvConfig {
    pub(crate) inner: Arc<Valid<EnvConfig>>,
}

#[pymethods]
impl PyEnvConfig {
    /// Parses and validates ``config_json`` (an ``EnvConfig`` document; missing keys take their
    /// defaults, unknown keys are errors). Raises ConfigError naming the field, the value and the
    /// allowed range.
    #[new]
    fn new(config_json: &str) -> PyResult<Self> {
        Ok(PyEnvConfig {
            inner: Arc::new(EnvConfig::from_json(config_json).py_err()?),
        })
    }

    /// The full configuration as JSON.
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(&**self.inner).map_err(|e| raise(Kind::Config, e.to_string()))
    }

    /// Agent steps of one episode: ``capture_window / agent_step``, rounded.
    #[getter]
    fn episode_steps(&self) -> u64 {
        self.inner.episode_steps()
    }

    /// Lowest and highest reward of one agent step.
    #[getter]
    fn reward_bounds(&self) -> (f64, f64) {
        self.inner.reward.bounds(self.inner.episode_steps())
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other
            .cast::<PyEnvConfig>()
            .map(|o| **o.get().inner == **self.inner)
            .unwrap_or(false)
    }

    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyType>, Bound<'py, PyTuple>)> {
        let json = slf.get().to_json()?;
        Ok((slf.get_type(), PyTuple::new(slf.py(), [json])?))
    }

    fn __repr__(&self) -> String {
        format!(
            "EnvConfig(<{} segments, {} s window, agent step {} s>)",
            self.inner.physics.tether.segments, self.inner.capture_window, self.inner.agent_step
        )
    }
}

/// The configuration's declarations, one row a key in document order (sections before their
/// fields): ``(dotted key, unit, range, description, is_section, declared default)`` (the
/// default as Rust source; ``default_config()`` has its JSON). The env docstrings' Arguments
/// tables and ``docs/environment.md`` are generated from them.
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn config_fields() -> Vec<(
    String,
    &'static str,
    &'static str,
    &'static str,
    bool,
    &'static str,
)> {
    use accd_spec::Fields;
    accd_spec::walk(EnvConfig::FIELDS)
        .into_iter()
        .map(|(key, f)| {
            (
                key,
                f.unit,
                f.range,
                f.description,
                !f.nested.is_empty(),
                f.default,
            )
        })
        .collect()
}

/// Full validations of a physics configuration so far in this process (a diagnostic: one per
/// env construction).
#[pyfunction]
pub fn validation_passes() -> u64 {
    accd_sim::valid::validation_passes()
}
