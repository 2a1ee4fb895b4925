//! `accd_gym.CaptureSim`: one capture episode's physics for scripted (non-RL) runs.

use accd_sim::physics::accd::mix;
use accd_sim::{CaptureConfig, CaptureSim, Seeds, SimError, Snapshot, Valid};
use accd_tether::TetherConfig;
use nalgebra::Vector3;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat};

use crate::arrays::{vector_to_py, vectors_to_py};
use crate::errors::{raise, IntoPy, Kind};
use crate::signals::SignalCheck;

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
) -> PyResult<Valid<CaptureConfig>> {
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
        return base.validated().py_err();
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
    let config: CaptureConfig = accd_sim::config::parse_named(&merged.to_string()).py_err()?;
    config.validated().py_err()
}

/// Flap deflections (right, left, top, bottom) from pitch, yaw and roll commands, in the unit of
/// the inputs (paper Fig. 5): pitch (nose up) moves both horizontal flaps, yaw (nose right) both
/// vertical flaps, roll (right side down) all four differentially.
///
/// Raises ``StateError`` for a non-finite command.
#[pyfunction]
pub fn mix_flaps(pitch: f64, yaw: f64, roll: f64) -> PyResult<[f64; 4]> {
    for (name, v) in [("pitch", pitch), ("yaw", yaw), ("roll", roll)] {
        if !v.is_finite() {
            return Err(raise(
                Kind::State,
                format!("`{name}` = {v} must be a finite number"),
            ));
        }
    }
    Ok(mix(pitch, yaw, roll))
}

/// A seed argument: a Python or numpy integer in the one seed range [0, 2^63)
/// ([`accd_sim::SEED_END`]); bools, floats and strings are refused (`ConfigError` naming the
/// argument and quoting the value as given).
pub fn seed_from_py(name: &str, value: &Bound<'_, PyAny>) -> PyResult<u64> {
    let bad = || {
        raise(
            Kind::Config,
            format!(
                "invalid config: `{name}` = {} is outside the allowed range: an integer in {}",
                value.repr().map(|r| r.to_string()).unwrap_or_default(),
                accd_sim::SEED_RANGE
            ),
        )
    };
    if value.is_instance_of::<PyBool>() || value.is_instance_of::<PyFloat>() {
        return Err(bad());
    }
    // Integers and numpy integers implement __index__; floats, strings and numpy floats do not.
    let index = value.call_method0("__index__").map_err(|_| bad())?;
    let seed = index.extract::<u64>().map_err(|_| bad())?;
    if seed >= accd_sim::SEED_END {
        return Err(bad());
    }
    Ok(seed)
}

/// A count argument (a number of envs, threads or steps): a Python or numpy integer in
/// `[low, high]`; bools, floats, strings and integers out of range are refused (`ConfigError`
/// naming the argument, the value and the range), never truncated, wrapped or parsed.
pub fn count_from_py(name: &str, value: &Bound<'_, PyAny>, low: u64, high: u64) -> PyResult<u64> {
    let range = if high == u64::MAX {
        format!("[{low}, 2^64 - 1]")
    } else {
        format!("[{low}, {high}]")
    };
    let bad = || {
        raise(
            Kind::Config,
            format!(
                "invalid config: `{name}` = {} is outside the allowed range: an integer in {range}",
                value.repr().map(|r| r.to_string()).unwrap_or_default()
            ),
        )
    };
    // numpy's bool scalar is no int subclass; its type is `numpy.bool` (`numpy.bool_` before 2.0).
    let type_name = value
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_default();
    if value.is_instance_of::<PyBool>()
        || value.is_instance_of::<PyFloat>()
        || type_name == "bool"
        || type_name == "bool_"
    {
        return Err(bad());
    }
    // Integers and numpy integers implement __index__; floats, strings and numpy floats do not.
    let index = value.call_method0("__index__").map_err(|_| bad())?;
    match index.extract::<u64>() {
        Ok(v) if (low..=high).contains(&v) => Ok(v),
        _ => Err(bad()),
    }
}

/// [`count_from_py`] for a count used as a `usize`, at most `usize::MAX`.
pub fn usize_from_py(
    name: &str,
    value: &Bound<'_, PyAny>,
    low: usize,
    high: usize,
) -> PyResult<usize> {
    // usize is at most 64 bits on every supported target: the conversions are lossless.
    count_from_py(name, value, low as u64, high as u64).map(|v| v as usize)
}

/// Flap commands: a sequence of 4 real numbers (Python or numpy floats and ints); bools,
/// complex numbers, strings and non-finite values are refused (`StateError`).
fn commands_from_py(name: &str, value: &Bound<'_, PyAny>) -> PyResult<[f64; 4]> {
    let items: Vec<Bound<'_, PyAny>> = value
        .try_iter()
        .map_err(|_| {
            raise(
                Kind::State,
                format!("`{name}` must be a sequence of 4 real numbers"),
            )
        })?
        .collect::<PyResult<_>>()?;
    if items.len() != 4 {
        return Err(raise(
            Kind::State,
            format!("`{name}` has {} values, expected 4", items.len()),
        ));
    }
    let mut out = [0.0; 4];
    for (i, item) in items.iter().enumerate() {
        let real = !item.is_instance_of::<PyBool>()
            && !item.is_instance_of::<pyo3::types::PyString>()
            && !item.is_instance_of::<pyo3::types::PyComplex>()
            && item
                .getattr("dtype")
                .and_then(|d| d.getattr("kind"))
                .map(|k| k.to_string() == "f" || k.to_string() == "i" || k.to_string() == "u")
                .unwrap_or(true);
        let v = if real {
            item.extract::<f64>().ok()
        } else {
            None
        };
        match v {
            Some(v) if v.is_finite() => out[i] = v,
            _ => {
                return Err(raise(
                    Kind::State,
                    format!(
                        "`{name}[{i}]` = {} must be a finite real number",
                        item.repr().map(|r| r.to_string()).unwrap_or_default()
                    ),
                ))
            }
        }
    }
    Ok(out)
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

impl PyCaptureSim {
    /// `steps` physics steps with `command` (rad), the GIL released, Python's signal handlers
    /// run every 50 ms (a raised `KeyboardInterrupt` stops after the current step).
    fn run(&mut self, py: Python<'_>, steps: usize, command: [f64; 4]) -> PyResult<()> {
        let inner = &mut self.inner;
        let mut check = SignalCheck::new();
        let result = py.detach(|| {
            for _ in 0..steps {
                inner.step(command)?;
                if check.interrupted() {
                    break;
                }
            }
            Ok::<(), SimError>(())
        });
        if let Some(e) = check.take() {
            return Err(e);
        }
        result.py_err()
    }
}

#[pymethods]
impl PyCaptureSim {
    #[new]
    #[pyo3(signature = (config = None, *, tether_preset = "table3", calm = false, seed = None, wake_seed = None))]
    fn new(
        py: Python<'_>,
        config: Option<&Bound<'_, PyDict>>,
        tether_preset: &str,
        calm: bool,
        seed: Option<&Bound<'_, PyAny>>,
        wake_seed: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let seed = seed
            .map(|s| seed_from_py("seed", s))
            .transpose()?
            .unwrap_or(0);
        let wake_seed = wake_seed
            .filter(|w| !w.is_none())
            .map(|w| seed_from_py("wake_seed", w))
            .transpose()?;
        let config = build(py, tether_preset, calm, config)?;
        let seeds = Seeds {
            initial: seed,
            wake: wake_seed.unwrap_or(seed),
            rlv: seed,
        };
        Ok(PyCaptureSim {
            inner: CaptureSim::new(&config, seeds).py_err()?,
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
    /// GIL, and returns :meth:`state`. ``steps``: a Python or numpy integer >= 0 (default, or
    /// None: 1).
    ///
    /// Raises:
    ///     ConfigError: ``steps`` is no integer (a bool, float or string) or is negative.
    ///     StateError: a non-finite or wrongly sized command.
    ///     SimulationError: the simulation diverged (the episode keeps its last good state).
    #[pyo3(signature = (flap_commands_deg = None, steps = None), text_signature = "($self, flap_commands_deg=None, steps=1)")]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        flap_commands_deg: Option<&Bound<'py, PyAny>>,
        steps: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let steps = match steps {
            Some(s) => usize_from_py("steps", s, 0, usize::MAX)?,
            None => 1,
        };
        let command = match flap_commands_deg {
            Some(v) if !v.is_none() => {
                commands_from_py("flap_commands_deg", v)?.map(f64::to_radians)
            }
            _ => [0.0; 4],
        };
        self.run(py, steps, command)?;
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
        self.run(py, steps, [0.0; 4])?;
        self.state(py)
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
        let s = self.inner.snapshot().py_err()?;
        snapshot_dict(py, &s)
    }

    /// Tether joint positions, shape (n + 1, 3), m (see :attr:`Tether.joint_positions`).
    #[getter]
    fn joint_positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
        let n = self.inner.config().tether.segments;
        let mut out = vec![Vector3::zeros(); n + 1];
        self.inner.joint_positions(&mut out).py_err()?;
        Ok(vectors_to_py(py, &out))
    }

    /// Tension along the chain, shape (n + 1,), N (see :meth:`Tether.tensions`).
    fn tensions<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
        let n = self.inner.config().tether.segments;
        let mut out = vec![0.0; n + 1];
        self.inner.tensions(&mut out).py_err()?;
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

/// A [`Snapshot`] as the dict of :meth:`CaptureSim.state` (its keys are documented there); shared
/// with ``BatchEnv.record_data``.
pub(crate) fn snapshot_dict<'py>(py: Python<'py>, s: &Snapshot) -> PyResult<Bound<'py, PyDict>> {
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
