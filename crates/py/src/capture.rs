//! `accd_gym.CaptureSim`: one capture episode's physics for scripted (non-RL) runs.

use accd_sim::accd::mix;
use accd_sim::{CaptureConfig, CaptureSim, Seeds, SimError};
use accd_tether::TetherConfig;
use nalgebra::Vector3;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyFloat};

use crate::arrays::{vector_to_py, vectors_to_py};
use crate::errors::{raise, IntoPy, Kind};

/// Maps every simulation error to its Python class.
pub fn sim_to_py(error: SimError) -> PyErr {
    match error {
        SimError::Tether(e) => crate::errors::to_py(e),
        SimError::InvalidConfig { .. } | SimError::InvalidTable { .. } | SimError::Io { .. } => {
            raise(Kind::Config, error.to_string())
        }
        SimError::Diverged { .. } => raise(Kind::Simulation, error.to_string()),
    }
}

fn merge(target: &mut serde_json::Value, patch: &serde_json::Value) {
    match (target.as_object_mut(), patch.as_object()) {
        (Some(t), Some(p)) => {
            for (k, v) in p {
                match t.get_mut(k) {
                    Some(existing) if existing.is_object() && v.is_object() => merge(existing, v),
                    _ => {
                        t.insert(k.clone(), v.clone());
                    }
                }
            }
        }
        _ => *target = patch.clone(),
    }
}

fn check_finite_floats(prefix: &str, dict: &Bound<'_, PyDict>) -> PyResult<()> {
    for (key, value) in dict.iter() {
        let name = if prefix.is_empty() {
            key.to_string()
        } else {
            format!("{prefix}.{key}")
        };
        if let Ok(f) = value.cast::<PyFloat>() {
            if !f.value().is_finite() {
                return Err(raise(
                    Kind::Config,
                    format!(
                        "invalid config: `{name}` = {} is not a finite number",
                        f.value()
                    ),
                ));
            }
        } else if let Ok(d) = value.cast::<PyDict>() {
            check_finite_floats(&name, d)?;
        }
    }
    Ok(())
}

fn build(
    py: Python<'_>,
    tether_preset: &str,
    calm: bool,
    overrides: Option<&Bound<'_, PyDict>>,
) -> PyResult<CaptureConfig> {
    let defaults = if calm {
        CaptureConfig::calm()
    } else {
        CaptureConfig::default()
    };
    let base = CaptureConfig {
        tether: TetherConfig::preset(tether_preset).py_err()?,
        ..defaults
    };
    let Some(overrides) = overrides else {
        base.validate().map_err(sim_to_py)?;
        return Ok(base);
    };
    check_finite_floats("", overrides)?;
    let text: String = py
        .import("json")?
        .call_method1("dumps", (overrides,))
        .map_err(|e| raise(Kind::Config, format!("invalid config: {e}")))?
        .extract()?;
    let patch: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| raise(Kind::Config, format!("invalid config: {e}")))?;
    let mut merged = serde_json::to_value(&base).expect("a config serializes");
    merge(&mut merged, &patch);
    let config: CaptureConfig = serde_json::from_value(merged).map_err(|e| {
        let message = e.to_string();
        let message = message
            .split(" at line ")
            .next()
            .unwrap_or(&message)
            .to_string();
        raise(Kind::Config, format!("invalid config: {message}"))
    })?;
    config.validate().map_err(sim_to_py)?;
    Ok(config)
}

/// Flap deflections (right, left, top, bottom) from pitch, yaw and roll commands, in the unit of
/// the inputs (paper Fig. 5): pitch (nose up) moves both horizontal flaps, yaw (nose right) both
/// vertical flaps, roll (right side down) all four differentially.
#[pyfunction]
pub fn mix_flaps(pitch: f64, yaw: f64, roll: f64) -> [f64; 4] {
    mix(pitch, yaw, roll)
}

/// The default aerodynamic tables of the ACCD as JSON in the documented file format (see
/// README, "ACCD aerodynamic tables"): a starting point for tables from your own CFD, which
/// ``CaptureSim({"accd": {"aero_table": path}})`` loads.
#[pyfunction]
pub fn default_aero_table_json() -> String {
    accd_sim::AeroModel::accd().to_json()
}

/// One In-Air Capturing episode's physics, for scripted (non-RL) runs: Table 3's tether (or a
/// preset) with the 6-DoF capturing device (ACCD) at its tip, towed at 185 m/s, 6000 m through
/// the aircraft's wake (8 degrees angle of attack) and its turbulence, with the RLV's boom in
/// formation behind and below. ``calm=True`` switches wake and turbulence off, as in the paper's
/// open-loop studies.
///
/// All outputs are SI in the towing-aircraft (TA) frame (origin at the attachment, x forward,
/// y starboard, z down); angles named ``*_deg`` are degrees.
///
/// Args:
///     config: nested overrides of the defaults: ``{"tether": {...}, "accd": {...},
///         "aircraft": {...}, "boom": {...}, "wake": {...}, "turbulence": {...}}`` (see README
///         for every key).
///     calm: start from the no-wake, no-turbulence defaults.
///     tether_preset: preset of the tether before overrides (``"table3"``, ``"steel-250m-24mm"``, ...).
///     seed: the episode's seed (RLV motion, initial conditions).
///     wake_seed: the turbulence seed; defaults to ``seed``.
///
/// Raises:
///     ConfigError: an unknown key or a value out of range, named with its allowed range.
#[pyclass(name = "CaptureSim", module = "accd_gym._core")]
pub struct PyCaptureSim {
    inner: CaptureSim,
    seeds: Seeds,
}

#[pymethods]
impl PyCaptureSim {
    #[new]
    #[pyo3(signature = (config = None, *, tether_preset = "table3", calm = false, seed = 0, wake_seed = None))]
    fn new(
        py: Python<'_>,
        config: Option<&Bound<'_, PyDict>>,
        tether_preset: &str,
        calm: bool,
        seed: u64,
        wake_seed: Option<u64>,
    ) -> PyResult<Self> {
        let config = build(py, tether_preset, calm, config)?;
        let seeds = Seeds {
            initial: seed,
            wake: wake_seed.unwrap_or(seed),
            rlv: seed,
        };
        Ok(PyCaptureSim {
            inner: CaptureSim::new(&config, seeds).map_err(sim_to_py)?,
            seeds,
        })
    }

    /// The configuration in force, as a nested dict.
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = serde_json::to_string(self.inner.config()).expect("a config serializes");
        py.import("json")?.call_method1("loads", (text,))
    }

    /// The seeds: a dict with ``initial``, ``wake`` and ``rlv``.
    #[getter]
    fn seeds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("initial", self.seeds.initial)?;
        d.set_item("wake", self.seeds.wake)?;
        d.set_item("rlv", self.seeds.rlv)?;
        Ok(d)
    }

    /// Simulation time, s.
    #[getter]
    fn time(&self) -> f64 {
        self.inner.time()
    }

    /// Fixed physics step, s.
    #[getter]
    fn time_step(&self) -> f64 {
        self.inner.time_step()
    }

    /// Advances ``steps`` physics steps holding the flap commands ``flap_commands_deg`` (right,
    /// left, top, bottom; degrees, clipped to the flap limit; default all zero), releasing the
    /// GIL, and returns :meth:`state`.
    ///
    /// Raises:
    ///     StateError: a non-finite or wrongly sized command.
    ///     SimulationError: the simulation diverged (the episode keeps its last good state).
    #[pyo3(signature = (flap_commands_deg = None, steps = 1))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        flap_commands_deg: Option<Vec<f64>>,
        steps: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let command = match flap_commands_deg {
            None => [0.0; 4],
            Some(v) => {
                let arr: [f64; 4] = v.clone().try_into().map_err(|_| {
                    raise(
                        Kind::State,
                        format!("`flap_commands_deg` has {} values, expected 4", v.len()),
                    )
                })?;
                if let Some(i) = arr.iter().position(|x| !x.is_finite()) {
                    return Err(raise(
                        Kind::State,
                        format!("`flap_commands_deg[{i}]` = {} must be finite", arr[i]),
                    ));
                }
                arr.map(f64::to_radians)
            }
        };
        let inner = &mut self.inner;
        py.detach(|| inner.step_many(steps, command))
            .map_err(sim_to_py)?;
        self.state(py)
    }

    /// Advances ``duration`` seconds (rounded to whole steps) with neutral flaps; returns
    /// :meth:`state`. Use it to let the tether settle before an experiment.
    fn settle<'py>(&mut self, py: Python<'py>, duration: f64) -> PyResult<Bound<'py, PyDict>> {
        if !(duration.is_finite() && duration >= 0.0) {
            return Err(raise(
                Kind::State,
                format!("`duration` = {duration} must be finite and >= 0"),
            ));
        }
        let steps = (duration / self.inner.time_step()).round() as usize;
        self.step(py, None, steps)
    }

    /// The full state as a dict (SI units, TA frame):
    ///
    /// ``time`` (s); ``position``, ``velocity`` of the ACCD's centre of gravity (m, m/s);
    /// ``attitude`` quaternion (w, x, y, z; body to TA frame) and ``euler`` (roll, pitch, yaw, rad);
    /// ``omega`` body rates (rad/s); ``flap_deflection_deg``, ``flap_command_deg`` (right, left,
    /// top, bottom); ``alpha``, ``beta`` (rad), ``airspeed`` (m/s) and the aerodynamic ``force``
    /// (N, TA frame) and ``moment`` (N m, body axes) on the ACCD; ``capture_point`` and its
    /// velocity; ``boom_tip`` and ``boom_velocity``; ``distance`` and ``relative_speed`` between
    /// them and ``captured``; ``attachment_tension`` (N); ``aircraft_velocity`` (m/s).
    fn state<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.inner.snapshot().map_err(sim_to_py)?;
        let d = PyDict::new(py);
        let q = s.attitude.quaternion();
        let (roll, pitch, yaw) = s.attitude.euler_angles();
        d.set_item("time", s.time)?;
        d.set_item("position", vector_to_py(py, &s.position))?;
        d.set_item("velocity", vector_to_py(py, &s.velocity))?;
        d.set_item("attitude", [q.w, q.i, q.j, q.k])?;
        d.set_item("euler", [roll, pitch, yaw])?;
        d.set_item("omega", vector_to_py(py, &s.omega))?;
        d.set_item("flap_deflection_deg", s.deflection.map(f64::to_degrees))?;
        d.set_item("flap_command_deg", s.command.map(f64::to_degrees))?;
        d.set_item("alpha", s.loads.alpha)?;
        d.set_item("beta", s.loads.beta)?;
        d.set_item("airspeed", s.loads.airspeed)?;
        d.set_item("force", vector_to_py(py, &s.loads.force))?;
        d.set_item("moment", vector_to_py(py, &s.loads.moment))?;
        d.set_item("capture_point", vector_to_py(py, &s.capture_point))?;
        d.set_item(
            "capture_point_velocity",
            vector_to_py(py, &s.capture_point_velocity),
        )?;
        d.set_item("boom_tip", vector_to_py(py, &s.boom_tip))?;
        d.set_item("boom_velocity", vector_to_py(py, &s.boom_velocity))?;
        d.set_item("distance", s.capture.distance)?;
        d.set_item("relative_speed", s.capture.relative_speed)?;
        d.set_item("captured", s.capture.captured)?;
        d.set_item("attachment_tension", s.attachment_tension)?;
        d.set_item("aircraft_velocity", vector_to_py(py, &s.aircraft_velocity))?;
        Ok(d)
    }

    /// Tether joint positions, shape (n + 1, 3), m (see :attr:`Tether.joint_positions`).
    #[getter]
    fn joint_positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
        let n = self.inner.config().tether.segments;
        let mut out = vec![Vector3::zeros(); n + 1];
        self.inner.joint_positions(&mut out).map_err(sim_to_py)?;
        Ok(vectors_to_py(py, &out))
    }

    /// Tension along the chain, shape (n + 1,), N (see :meth:`Tether.tensions`).
    fn tensions<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
        let n = self.inner.config().tether.segments;
        let mut out = vec![0.0; n + 1];
        self.inner.tensions(&mut out).map_err(sim_to_py)?;
        Ok(numpy::PyArray1::from_vec(py, out))
    }

    fn __repr__(&self) -> String {
        format!(
            "CaptureSim(time={:.3} s, seeds={:?})",
            self.inner.time(),
            self.seeds
        )
    }
}
