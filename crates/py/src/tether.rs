//! `accd_gym.Tether`: the multibody tether alone, for design studies and validation.

use accd_tether::reference::{self, StandInBody};
use accd_tether::{Atmosphere, Tether, TetherConfig, TetherState, UniformFlow};
use nalgebra::Vector3;
use numpy::ndarray::Array2;
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArrayLike1, PyArrayLike2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyFloat};

use crate::arrays::{floats_from_py, vector_from_py, vector_to_py, vectors_from_py, vectors_to_py};
use crate::capture::usize_from_py;
use crate::errors::{raise, IntoPy, Kind, ToPy};
use crate::signals::SignalCheck;

/// A config from a preset name and a dict of overrides (unknown keys and bad values raise
/// `ConfigError`).
fn build_config(
    py: Python<'_>,
    preset: &str,
    overrides: Option<&Bound<'_, PyDict>>,
) -> PyResult<TetherConfig> {
    let base = TetherConfig::preset(preset).py_err()?;
    let Some(overrides) = overrides else {
        return Ok(base);
    };
    for (key, value) in overrides.iter() {
        if let Ok(f) = value.cast::<PyFloat>() {
            let v = f.value();
            if !v.is_finite() {
                return Err(raise(
                    Kind::Config,
                    format!("invalid tether config: `{key}` = {v} is not a finite number"),
                ));
            }
        }
    }
    let text: String = py
        .import("json")?
        .call_method1("dumps", (overrides,))
        .map_err(|e| raise(Kind::Config, format!("invalid tether config: {e}")))?
        .extract()?;
    let patch: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| raise(Kind::Config, format!("invalid tether config: {e}")))?;
    let mut merged = serde_json::to_value(&base).expect("a config serializes");
    if let (Some(target), Some(source)) = (merged.as_object_mut(), patch.as_object()) {
        for (k, v) in source {
            target.insert(k.clone(), v.clone());
        }
    }
    let config = TetherConfig::from_json(&merged.to_string()).map_err(|e| match e {
        // Positions in the merged document mean nothing to the caller: keep the message only.
        accd_tether::TetherError::ConfigParse { message } => {
            let message = message
                .split(" at line ")
                .next()
                .unwrap_or(&message)
                .to_string();
            match accd_sim::config::locate_parse_error::<TetherConfig>(&merged) {
                Some((field, value)) => raise(
                    Kind::Config,
                    format!(
                        "invalid tether config: `{field}` = {value} is outside the allowed range: {message}"
                    ),
                ),
                None => raise(Kind::Config, format!("invalid tether config: {message}")),
            }
        }
        other => other.to_py(),
    })?;
    // The configs of this module are for stepping: the same rule as `Tether::new`.
    config.validate_for_stepping().py_err()?;
    Ok(config)
}

fn config_to_dict<'py>(py: Python<'py>, config: &TetherConfig) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?
        .call_method1("loads", (config.to_json(),))
}

/// The validated tether configuration of `preset` with `overrides` applied, as a dict (SI units).
///
/// Presets: ``"table3"`` (the paper's selected tether, the default), ``"table1"`` (the 10 m
/// verification case), and ``"<material>-<length>m-<diameter>mm"`` for Table 2's materials
/// (``uhmwpe``, ``kevlar``, ``steel``) at any length and diameter, e.g. ``"steel-250m-24mm"``.
/// Raises ``ConfigError`` naming the field, the value and the allowed range.
#[pyfunction]
#[pyo3(signature = (preset = "table3", overrides = None))]
pub fn tether_config<'py>(
    py: Python<'py>,
    preset: &str,
    overrides: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let config = build_config(py, preset, overrides)?;
    config_to_dict(py, &config)
}

/// The build of the physics' arithmetic this process runs: ``"native"`` (compiled for AVX2 and
/// FMA, on an x86-64 processor that has them) or ``"portable"`` (every other processor, or the
/// environment variable ``ACCD_GYM_ARITHMETIC=portable``). Both compute the same bits.
///
/// Raises ``ConfigError`` if ``ACCD_GYM_ARITHMETIC`` holds a value other than ``native`` or
/// ``portable`` (or nothing).
#[pyfunction]
pub fn arithmetic() -> PyResult<&'static str> {
    accd_tether::portable_requested().map_err(|value| {
        crate::errors::raise(
            crate::errors::Kind::Config,
            format!(
                "`{}` is {value:?}; allowed: {} (or unset)",
                accd_tether::ARITHMETIC_VARIABLE,
                accd_tether::ARITHMETIC_VALUES.join(", ")
            ),
        )
    })?;
    Ok(accd_tether::arithmetic())
}

/// International Standard Atmosphere at a geometric altitude (m, -500 to 20000).
///
/// Returns a dict with ``altitude`` (m), ``temperature`` (K), ``pressure`` (Pa), ``density``
/// (kg/m^3) and ``speed_of_sound`` (m/s).
#[pyfunction]
pub fn isa<'py>(py: Python<'py>, altitude: f64) -> PyResult<Bound<'py, PyDict>> {
    let a = Atmosphere::isa(altitude).py_err()?;
    let d = PyDict::new(py);
    d.set_item("altitude", a.altitude)?;
    d.set_item("temperature", a.temperature)?;
    d.set_item("pressure", a.pressure)?;
    d.set_item("density", a.density)?;
    d.set_item("speed_of_sound", a.speed_of_sound)?;
    Ok(d)
}

/// Mass (kg) and drag area C_D A (m^2) of the stand-in capturing device used until the 6-DoF
/// model exists: a 50 kg, 0.3 m diameter finned body with C_D = 0.6 on its frontal area.
#[pyfunction]
pub fn stand_in_body<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
    let body = StandInBody::accd();
    let d = PyDict::new(py);
    d.set_item("mass", body.mass)?;
    d.set_item("drag_area", body.drag_area)?;
    Ok(d)
}

/// A tether of ``preset`` (with ``config`` overrides) carrying the stand-in capturing device
/// (see :func:`stand_in_body`), towed at the paper's 185 m/s through ISA air at 6000 m: the
/// reference case of the settling demo and of the tests. It starts trailing straight back.
#[pyfunction]
#[pyo3(signature = (preset = "table3", config = None))]
pub fn towed_tether(
    py: Python<'_>,
    preset: &str,
    config: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyTether> {
    let base = build_config(py, preset, config)?;
    let (config, flow) = reference::towed(&base, StandInBody::accd()).py_err()?;
    Ok(PyTether {
        inner: Tether::new(&config).py_err()?,
        flow,
    })
}

/// The paper's 3D multibody tether: ``n`` rigid segments hung from the towing aircraft (TA)
/// through one axial visco-elastic element, with nonlinear bending springs, joint damping,
/// per-segment aerodynamics, the TA's acceleration as a rheonomous constraint and a tip mass.
///
/// All quantities are SI and in the TA frame: origin at the attachment point, x forward, y to
/// starboard, z down. A new tether trails straight back at rest, unstretched, at t = 0, in still
/// air (no flow, zero density): call :meth:`set_surroundings` or :meth:`tow` for air.
///
/// Args:
///     config: overrides of the preset's fields (see :func:`accd_gym.tether_config`).
///     preset: ``"table3"`` (default), ``"table1"`` or ``"<material>-<L>m-<d>mm"``.
///
/// Raises:
///     ConfigError: an unknown key or a value outside its range (the message names both).
#[pyclass(name = "Tether", module = "accd_gym._core")]
pub struct PyTether {
    inner: Tether,
    flow: UniformFlow,
}

impl PyTether {
    fn n(&self) -> usize {
        self.inner.config().segments
    }

    /// Stretch of each segment's element, m (see `stretches`).
    fn stretch_values(&self) -> Vec<f64> {
        let (n, q) = (self.n(), &self.inner.state().q);
        let mut out = vec![0.0; n];
        out[0] = q[0];
        if self.inner.config().is_distributed() {
            out[1..].copy_from_slice(&q[2 * n + 1..3 * n]);
        }
        out
    }

    fn install(
        &mut self,
        state: Result<TetherState, accd_tether::TetherError>,
        time: f64,
    ) -> PyResult<()> {
        let mut state = state.py_err()?;
        // States built from directions or angles are in the attachment layout (2n + 1); a
        // distributed tether takes the same geometry with the elongation on segment 1's element.
        if self.inner.config().is_distributed() && state.q.len() == 2 * self.n() + 1 {
            state = state.to_distributed().py_err()?;
        }
        if !time.is_finite() {
            return Err(raise(
                Kind::State,
                format!("`time` = {time} must be finite"),
            ));
        }
        state.time = time;
        self.inner.set_state(state).py_err()
    }

    /// `steps` fixed steps with the GIL released (see `step`).
    fn step_n(&mut self, py: Python<'_>, steps: usize) -> PyResult<()> {
        let flow = self.flow;
        let inner = &mut self.inner;
        let mut check = SignalCheck::new();
        let result =
            py.detach(|| inner.step_many_interruptible(steps, &flow, &mut || check.interrupted()));
        if let Some(e) = check.take() {
            return Err(e);
        }
        result.py_err()
    }
}

#[pymethods]
impl PyTether {
    #[new]
    #[pyo3(signature = (config = None, *, preset = "table3"))]
    fn new(py: Python<'_>, config: Option<&Bound<'_, PyDict>>, preset: &str) -> PyResult<Self> {
        let config = build_config(py, preset, config)?;
        Ok(PyTether {
            inner: Tether::new(&config).py_err()?,
            flow: UniformFlow::still(),
        })
    }

    /// The configuration in force, as a dict (SI units).
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        config_to_dict(py, self.inner.config())
    }

    /// Number of segments n.
    #[getter]
    fn segments(&self) -> usize {
        self.n()
    }

    /// Where the axial elasticity sits: ``"attachment"`` (one element at the attachment, the
    /// paper's simplified model, the default) or ``"distributed"`` (an element ``n k``, ``n c_s``
    /// in every segment, the paper's full model of section 2.3.6).
    #[getter]
    fn elasticity(&self) -> &'static str {
        self.inner.config().elasticity.name()
    }

    /// How a step integrates: ``"explicit"`` (classical RK4, substepped for the fastest mode,
    /// the default) or ``"implicit_axial"`` (the Rosenbrock-W method ROS34PW2 with the axial
    /// spring-dampers implicit, so that stiff axial elements step at the default 0.01 s).
    #[getter]
    fn scheme(&self) -> &'static str {
        self.inner.config().scheme.name()
    }

    /// Number of generalized coordinates: 2n + 1 (attachment elasticity) or 3n (distributed).
    #[getter]
    fn dofs(&self) -> usize {
        self.inner.config().dofs()
    }

    /// Simulation time, s.
    #[getter]
    fn time(&self) -> f64 {
        self.inner.state().time
    }

    /// Fixed RK4 step, s.
    #[getter]
    fn time_step(&self) -> f64 {
        self.inner.time_step()
    }

    /// Generalized coordinates ``[s, phi_1, psi_1, ..., phi_n, psi_n]`` (m, rad), a copy; with
    /// the distributed elasticity followed by the stretches ``s_2, ..., s_n`` of the elements of
    /// segments 2 to n (m), and ``s`` is segment 1's element.
    ///
    /// ``phi`` is the in-plane angle below the trailing direction (0 trailing back, pi/2 hanging
    /// down), ``psi`` the lateral angle towards starboard; the chart is singular only for a
    /// segment pointing straight sideways.
    #[getter]
    fn q<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.state().q)
    }

    /// Rates of :attr:`q` (m/s, rad/s), a copy.
    #[getter]
    fn qd<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.state().qd)
    }

    /// Elongation s of the axial element at the attachment, m (segment 1's element when the
    /// elasticity is distributed; the whole tether's is :attr:`total_elongation`).
    #[getter]
    fn elongation(&self) -> f64 {
        self.inner.state().elongation()
    }

    /// Stretch of the axial element at the inboard end of each segment, shape (n,), m: the
    /// attachment element's ``s`` first; the other entries are zero unless the elasticity is
    /// distributed.
    #[getter]
    fn stretches<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.stretch_values())
    }

    /// Total elongation of the tether, the sum of :attr:`stretches`, m.
    #[getter]
    fn total_elongation(&self) -> f64 {
        self.stretch_values().iter().sum()
    }

    /// Unit direction of each segment, shape (n, 3), pointing away from the aircraft.
    #[getter]
    fn segment_directions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let st = self.inner.state();
        let dirs: Vec<Vector3<f64>> = (0..self.n()).map(|k| st.direction(k)).collect();
        vectors_to_py(py, &dirs)
    }

    /// Joint positions, shape (n + 1, 3), m: the inboard end of each segment (the first is the
    /// outboard end of the axial element, at distance s from the attachment) and then the tip.
    #[getter]
    fn joint_positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let mut out = vec![Vector3::zeros(); self.n() + 1];
        self.inner.joint_positions(&mut out).py_err()?;
        Ok(vectors_to_py(py, &out))
    }

    /// Tip position, shape (3,), m.
    #[getter]
    fn tip_position<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vector_to_py(py, &self.inner.tip_state().0)
    }

    /// Tip velocity relative to the TA frame, shape (3,), m/s.
    #[getter]
    fn tip_velocity<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vector_to_py(py, &self.inner.tip_state().1)
    }

    /// Tension of the axial element at the attachment, k s + c s', N.
    #[getter]
    fn attachment_tension(&self) -> f64 {
        self.inner.attachment_tension()
    }

    /// Tension along the chain, shape (n + 1,), N: entry k < n at the inboard end of segment
    /// k + 1 (entry 0 at the attachment), entry n where the tip body pulls on the last segment.
    /// Computed from Newton's law with the current surroundings.
    fn tensions<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let mut out = vec![0.0; self.n() + 1];
        self.inner.tensions(&self.flow, &mut out).py_err()?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// Energy of the current state, J: a dict with ``kinetic``, ``gravity`` (zero at the
    /// attachment's height), ``axial`` and ``bending`` strain energy, and their ``total``.
    fn energy<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let e = self.inner.energy();
        let d = PyDict::new(py);
        d.set_item("kinetic", e.kinetic)?;
        d.set_item("gravity", e.gravity)?;
        d.set_item("axial", e.axial)?;
        d.set_item("bending", e.bending)?;
        d.set_item("total", e.total())?;
        Ok(d)
    }

    /// Mass matrix M(q) at the current state, shape (dofs, dofs) (see :attr:`dofs`).
    fn mass_matrix<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let q = self.inner.state().q.clone();
        let m = self.inner.model_mut().mass_matrix(&q).py_err()?;
        Ok(Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)]).into_pyarray(py))
    }

    /// Generalized accelerations q'' at the current state and surroundings, shape (dofs,).
    fn accelerations<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let flow = self.flow;
        let a = self.inner.accelerations(&flow).py_err()?;
        Ok(PyArray1::from_slice(py, a))
    }

    /// Sets the state from segment directions.
    ///
    /// Args:
    ///     directions: shape (n, 3), each segment's direction away from the aircraft (normalised
    ///         here; must not point straight sideways).
    ///     direction_rates: shape (n, 3), rate of each unit direction, 1/s (the part along the
    ///         direction is dropped). Default: at rest.
    ///     elongation: s, m (with the distributed elasticity on segment 1's element, the others
    ///         unstretched). elongation_rate: s', m/s. time: s.
    #[pyo3(signature = (directions, direction_rates = None, elongation = 0.0, elongation_rate = 0.0, time = 0.0))]
    fn set_state(
        &mut self,
        directions: PyArrayLike2<'_, f64, AllowTypeChange>,
        direction_rates: Option<PyArrayLike2<'_, f64, AllowTypeChange>>,
        elongation: f64,
        elongation_rate: f64,
        time: f64,
    ) -> PyResult<()> {
        let n = self.n();
        let dirs = vectors_from_py("directions", &directions, Some(n))?;
        let rates = match direction_rates {
            Some(r) => vectors_from_py("direction_rates", &r, Some(n))?,
            None => vec![Vector3::zeros(); n],
        };
        self.install(
            TetherState::from_directions(&dirs, &rates, elongation, elongation_rate),
            time,
        )
    }

    /// Sets the state from the angles (rad) and their rates (rad/s), each of shape (n,),
    /// with the elongation s (m), its rate (m/s) and the time (s); with the distributed
    /// elasticity s is segment 1's element's and the others are unstretched.
    #[pyo3(signature = (phi, psi, phi_rate = None, psi_rate = None, elongation = 0.0, elongation_rate = 0.0, time = 0.0))]
    #[allow(clippy::too_many_arguments)]
    fn set_angles(
        &mut self,
        phi: PyArrayLike1<'_, f64, AllowTypeChange>,
        psi: PyArrayLike1<'_, f64, AllowTypeChange>,
        phi_rate: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
        psi_rate: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
        elongation: f64,
        elongation_rate: f64,
        time: f64,
    ) -> PyResult<()> {
        let n = self.n();
        let phi = floats_from_py("phi", &phi, n)?;
        let psi = floats_from_py("psi", &psi, n)?;
        let phi_rate = phi_rate
            .map(|a| floats_from_py("phi_rate", &a, n))
            .transpose()?
            .unwrap_or(vec![0.0; n]);
        let psi_rate = psi_rate
            .map(|a| floats_from_py("psi_rate", &a, n))
            .transpose()?
            .unwrap_or(vec![0.0; n]);
        self.install(
            TetherState::from_angles(
                &phi,
                &psi,
                &phi_rate,
                &psi_rate,
                elongation,
                elongation_rate,
            ),
            time,
        )
    }

    /// Sets the generalized coordinates and rates directly, each of shape (dofs,) (see :attr:`q`).
    #[pyo3(signature = (q, qd, time = 0.0))]
    fn set_coordinates(
        &mut self,
        q: PyArrayLike1<'_, f64, AllowTypeChange>,
        qd: PyArrayLike1<'_, f64, AllowTypeChange>,
        time: f64,
    ) -> PyResult<()> {
        let dofs = self.inner.config().dofs();
        let q = floats_from_py("q", &q, dofs)?;
        let qd = floats_from_py("qd", &qd, dofs)?;
        self.install(Ok(TetherState { time: 0.0, q, qd }), time)
    }

    /// Sets what the surroundings supply; arguments left out keep their values.
    ///
    /// Args:
    ///     air_velocity: (3,), velocity of the air in the TA frame, m/s; flying at V through
    ///         still air it is (-V, 0, 0). Uniform over the tether.
    ///     air_density: kg/m^3.
    ///     frame_acceleration: (3,), acceleration of the towing aircraft in its own frame, m/s^2
    ///         (every mass feels -m a).
    ///     tip_force: (3,), constant external force on the tip body, N.
    ///     tip_drag_area: C_D A of the tip body, m^2: adds 0.5 rho C_D A |v| v on its velocity v
    ///         relative to the air.
    #[pyo3(signature = (*, air_velocity = None, air_density = None, frame_acceleration = None, tip_force = None, tip_drag_area = None))]
    fn set_surroundings(
        &mut self,
        air_velocity: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
        air_density: Option<f64>,
        frame_acceleration: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
        tip_force: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
        tip_drag_area: Option<f64>,
    ) -> PyResult<()> {
        let mut flow = self.flow;
        if let Some(v) = air_velocity {
            flow.velocity = vector_from_py("air_velocity", &v)?;
        }
        if let Some(v) = frame_acceleration {
            flow.frame_acceleration = vector_from_py("frame_acceleration", &v)?;
        }
        if let Some(v) = tip_force {
            flow.tip_force = vector_from_py("tip_force", &v)?;
        }
        if let Some(rho) = air_density {
            if !(rho.is_finite() && (0.0..=10.0).contains(&rho)) {
                return Err(raise(
                    Kind::Config,
                    format!("`air_density` = {rho} is outside the allowed range [0, 10] kg/m^3"),
                ));
            }
            flow.density = rho;
        }
        if let Some(area) = tip_drag_area {
            if !(area.is_finite() && (0.0..=100.0).contains(&area)) {
                return Err(raise(
                    Kind::Config,
                    format!("`tip_drag_area` = {area} is outside the allowed range [0, 100] m^2"),
                ));
            }
            flow.tip_drag_area = area;
        }
        self.flow = flow;
        Ok(())
    }

    /// Flies the towing aircraft straight and level at ``airspeed`` (m/s) through ISA air at
    /// ``altitude`` (m): air velocity (-airspeed, 0, 0), ISA density. Defaults: the paper's
    /// 185 m/s at 6000 m. Other surroundings keep their values.
    #[pyo3(signature = (airspeed = 185.0, altitude = 6000.0))]
    fn tow(&mut self, airspeed: f64, altitude: f64) -> PyResult<()> {
        if !(airspeed.is_finite() && (0.0..=400.0).contains(&airspeed)) {
            return Err(raise(
                Kind::Config,
                format!("`airspeed` = {airspeed} is outside the allowed range [0, 400] m/s"),
            ));
        }
        let air = Atmosphere::isa(altitude).py_err()?;
        self.flow.velocity = Vector3::new(-airspeed, 0.0, 0.0);
        self.flow.density = air.density;
        Ok(())
    }

    /// The surroundings in force, as a dict (see :meth:`set_surroundings`).
    fn surroundings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("air_velocity", vector_to_py(py, &self.flow.velocity))?;
        d.set_item("air_density", self.flow.density)?;
        d.set_item(
            "frame_acceleration",
            vector_to_py(py, &self.flow.frame_acceleration),
        )?;
        d.set_item("tip_force", vector_to_py(py, &self.flow.tip_force))?;
        d.set_item("tip_drag_area", self.flow.tip_drag_area)?;
        Ok(d)
    }

    /// Advances ``steps`` fixed steps (the GIL is released meanwhile). Each step takes as many
    /// RK4 substeps as the chain's fastest mode needs at the current tension (one for Table 3).
    /// ``steps``: a Python or numpy integer >= 0 (default, or None: 1).
    ///
    /// Raises:
    ///     ConfigError: ``steps`` is no integer (a bool, float or string) or is negative.
    ///     KeyboardInterrupt: Ctrl+C (signal handlers run every 50 ms); the tether keeps the
    ///         state of the last whole step.
    ///     SimulationError: the state diverged (non-finite, a joint folded completely, or a segment
    ///         reached the chart's lateral singularity); the tether keeps the last good state.
    #[pyo3(signature = (steps = None), text_signature = "($self, steps=1)")]
    fn step(&mut self, py: Python<'_>, steps: Option<&Bound<'_, PyAny>>) -> PyResult<()> {
        let steps = match steps {
            Some(s) => usize_from_py("steps", s, 0, usize::MAX)?,
            None => 1,
        };
        self.step_n(py, steps)
    }

    /// Advances by ``duration`` seconds, rounded to whole steps; returns the number of steps.
    fn advance(&mut self, py: Python<'_>, duration: f64) -> PyResult<usize> {
        if !(duration.is_finite() && duration >= 0.0) {
            return Err(raise(
                Kind::State,
                format!("`duration` = {duration} must be finite and >= 0"),
            ));
        }
        let steps = (duration / self.inner.time_step()).round() as usize;
        self.step_n(py, steps)?;
        Ok(steps)
    }

    fn __repr__(&self) -> String {
        let c = self.inner.config();
        format!(
            "Tether(segments={}, length={} m, mass_per_length={} kg/m, tip_mass={} kg, time={:.3} s)",
            c.segments,
            c.length,
            c.mass_per_length,
            c.tip_mass,
            self.inner.state().time
        )
    }
}
