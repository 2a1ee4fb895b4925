//! `accd_gym._core.linearize`: the discrete-time linear model of a configuration's capture
//! dynamics about its trim ([`accd_sim::task::linearize`]), and the nonlinear step it was taken from.

use accd_sim::{Linearized, SimError, ACT_DIM};
use nalgebra::DMatrix;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1};
use pyo3::prelude::*;

use crate::arrays::vector_to_py;
use crate::config::PyEnvConfig;
use crate::errors::{raise, IntoPy, Kind};
use crate::signals::SignalCheck;

/// The linear model ``x+ - x* = A (x - x*) + B u + E w``, ``y - y* = C (x - x*)`` of one agent
/// step about the trim (see ``accd_gym.linearize``), with the nonlinear step it was taken from.
#[pyclass(name = "Linearization", module = "accd_gym._core", frozen)]
pub struct PyLinearization {
    pub(crate) inner: Linearized,
}

fn matrix<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)]).into_pyarray(py)
}

fn fixed<const N: usize>(
    name: &str,
    values: Option<PyReadonlyArray1<'_, f64>>,
) -> PyResult<[f64; N]> {
    let mut out = [0.0; N];
    if let Some(v) = values {
        let v = v.as_array();
        if v.len() != N {
            return Err(raise(
                Kind::Config,
                format!(
                    "invalid config: `{name}` has {} values, expected {N}",
                    v.len()
                ),
            ));
        }
        for (o, x) in out.iter_mut().zip(v.iter()) {
            *o = *x;
        }
    }
    Ok(out)
}

#[pymethods]
impl PyLinearization {
    /// ``A`` (state x state).
    #[getter]
    fn a<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        matrix(py, &self.inner.model.a)
    }
    /// ``B`` (state x 4), per unit of flap command (the env's action).
    #[getter]
    fn b<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        matrix(py, &self.inner.model.b)
    }
    /// ``E`` (state x 2), per m/s of wind bias at the ACCD (y, z).
    #[getter]
    fn e<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        matrix(py, &self.inner.model.e)
    }
    /// ``C`` (25 x state): the observation (scaled, before clipping) with the boom held fixed.
    #[getter]
    fn c<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        matrix(py, &self.inner.model.c)
    }
    /// The trim state ``x*``.
    #[getter]
    fn trim<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.model.trim)
    }
    /// The observation at the trim ``y*`` (boom tip at the trim capture point, at rest).
    #[getter]
    fn trim_observation<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.model.trim_observation)
    }
    /// The trim attitude quaternion (w, x, y, z; body to TA frame).
    #[getter]
    fn trim_attitude(&self) -> [f64; 4] {
        let q = self.inner.model.trim_attitude;
        [q.w, q.i, q.j, q.k]
    }
    /// Finite-difference step of each state component (its unit).
    #[getter]
    fn steps<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.model.steps)
    }
    /// Names of the state components.
    #[getter]
    fn state_names(&self) -> Vec<String> {
        self.inner.model.state_names.clone()
    }
    /// The capture point at the trim, m (TA frame).
    #[getter]
    fn capture_point<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vector_to_py(py, &self.inner.model.capture_point)
    }
    /// The ACCD's centre of gravity at the trim, m (TA frame).
    #[getter]
    fn position<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vector_to_py(py, &self.inner.model.position)
    }
    /// The settled equilibrium's position (what ``accd_d*`` refer to), m.
    #[getter]
    fn equilibrium_position<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vector_to_py(py, &self.inner.model.equilibrium_position)
    }
    /// ``max |f(x) - x|`` at the settled equilibrium.
    #[getter]
    fn settle_residual(&self) -> f64 {
        self.inner.model.settle_residual
    }
    /// ``max |f(x*) - x*|`` at the trim.
    #[getter]
    fn trim_residual(&self) -> f64 {
        self.inner.model.trim_residual
    }
    /// Newton iterations done on the trim.
    #[getter]
    fn newton_iterations(&self) -> usize {
        self.inner.model.newton_iterations
    }
    /// The model's step (the agent step), s.
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.model.dt
    }

    /// The nonlinear agent step from ``x* + dx`` with flap commands ``u`` (4, flap-limit units;
    /// default 0) and wind bias ``wind`` (2, m/s at the ACCD, y and z; default 0): the next
    /// state minus ``x*``.
    #[pyo3(signature = (dx, u = None, wind = None))]
    fn step<'py>(
        &self,
        py: Python<'py>,
        dx: PyReadonlyArray1<'_, f64>,
        u: Option<PyReadonlyArray1<'_, f64>>,
        wind: Option<PyReadonlyArray1<'_, f64>>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let dx = dx.as_array().to_vec();
        let u: [f64; ACT_DIM] = fixed("u", u)?;
        let wind: [f64; 2] = fixed("wind", wind)?;
        let inner = &self.inner;
        let next = py.detach(|| inner.step(&dx, &u, &wind)).py_err()?;
        Ok(PyArray1::from_vec(py, next))
    }

    /// The observation (25, scaled, not clipped) at ``x* + dx``, the boom tip at the trim
    /// capture point and at rest.
    fn observe<'py>(
        &self,
        py: Python<'py>,
        dx: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let dx = dx.as_array().to_vec();
        let inner = &self.inner;
        let y = py.detach(|| inner.observe(&dx)).py_err()?;
        Ok(PyArray1::from_slice(py, &y))
    }
}

/// Linearizes the configuration's capture dynamics over one agent step about its trim
/// (``accd_sim::task::linearize``); interruptible (Ctrl+C) between evaluations.
#[pyfunction]
pub fn linearize(py: Python<'_>, config: &PyEnvConfig) -> PyResult<PyLinearization> {
    let config = &config.inner;
    let mut check = SignalCheck::new();
    let result = py.detach(|| Linearized::new(config, &mut || check.interrupted()));
    if let Some(e) = check.take() {
        return Err(e);
    }
    let inner: Result<Linearized, SimError> = result;
    Ok(PyLinearization {
        inner: inner.py_err()?,
    })
}
