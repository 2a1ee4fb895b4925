//! `accd_gym._core.lqr_design` and `LqrFilter`: the LQR baseline's design and its per-step
//! Kalman filter and control law ([`accd_sim::control`]), for `accd_gym.control.lqr.LqrPolicy`.
//!
//! The design runs with the GIL released. `LqrFilter` owns the filter state of every env of a
//! batch and steps them with the GIL released, on the calling thread, in blocks of rows that
//! share each read of the matrices (`LqrFilter::step_rows`): a row costs microseconds, less than
//! waking other threads costs on a busy machine. Each row's arithmetic depends on nothing but its
//! own inputs, so the results are the same bits whatever the batch size. A batch env runs the
//! same step per env in its own threads instead (`BatchEnv.set_controller`, which takes an
//! `LqrFilter` or an `Mpc` for its design).

use std::sync::Arc;

use accd_sim::control::filter::{FilterState, LqrFilter};
use accd_sim::control::lqr::{design, LqrDesign, LqrTuning, MEASURED_DIM};
use accd_sim::control::matrix::Matrix;
use accd_sim::{ACT_DIM, OBS_DIM};
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::errors::{raise, IntoPy, Kind};
use crate::linearize::PyLinearization;

pub(crate) fn to_py<'py>(py: Python<'py>, m: &Matrix) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((m.rows(), m.cols()), |(i, j)| m[(i, j)]).into_pyarray(py)
}

pub(crate) fn from_py(a: &PyReadonlyArray2<'_, f64>) -> Matrix {
    let v = a.as_array();
    Matrix::from_fn(v.nrows(), v.ncols(), |i, j| v[(i, j)])
}

/// One design of the LQR baseline (see ``accd_gym.control.lqr``): the observer's ``f``, ``g``,
/// ``h``, the Kalman gain ``l``, the LQR gain ``k``, the reference gain ``k_ff``, ``y_trim``, and
/// the two Riccati solutions with their relative residuals and doubling steps.
#[pyclass(name = "LqrDesign", module = "accd_gym._core", frozen)]
pub struct PyLqrDesign {
    inner: Arc<LqrDesign>,
}

#[pymethods]
impl PyLqrDesign {
    /// Plant states ``n``.
    #[getter]
    fn n(&self) -> usize {
        self.inner.n
    }
    /// ``F`` (nz x nz).
    #[getter]
    fn f<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.f)
    }
    /// ``G`` (nz x 4).
    #[getter]
    fn g<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.g)
    }
    /// ``H`` (24 x nz).
    #[getter]
    fn h<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.h)
    }
    /// The Kalman gain ``L`` (nz x 24).
    #[getter]
    fn l<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.l)
    }
    /// The LQR gain ``K`` (4 x n).
    #[getter]
    fn k<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.k)
    }
    /// The reference gain ``K_ff`` (4 x 4).
    #[getter]
    fn k_ff<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.k_ff)
    }
    /// The LQR's state weight ``Q`` (n x n).
    #[getter]
    fn q<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.q)
    }
    /// The reference's steady state per unit of ``w_y, w_z, r_y, r_z`` (n x 4).
    #[getter]
    fn x_ss<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.x_ss)
    }
    /// The reference's steady command per unit of ``w_y, w_z, r_y, r_z`` (4 x 4).
    #[getter]
    fn u_ss<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.u_ss)
    }
    /// The measured observation at the trim (24).
    #[getter]
    fn y_trim<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.y_trim)
    }
    /// The LQR's Riccati solution ``P`` (n x n).
    #[getter]
    fn lqr_solution<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.lqr.x)
    }
    /// The Kalman filter's Riccati solution (the prior covariance, nz x nz).
    #[getter]
    fn filter_solution<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        to_py(py, &self.inner.filter.x)
    }
    /// The relative residuals of the LQR's and the filter's Riccati equations.
    #[getter]
    fn residuals(&self) -> (f64, f64) {
        (
            self.inner.lqr.relative_residual,
            self.inner.filter.relative_residual,
        )
    }
    /// Doubling steps of the LQR's and the filter's Riccati solves.
    #[getter]
    fn doublings(&self) -> (usize, usize) {
        (self.inner.lqr.doublings, self.inner.filter.doublings)
    }
    /// The spectral radius of ``A - B K``.
    #[getter]
    fn closed_loop_radius(&self) -> f64 {
        self.inner.closed_loop_radius()
    }
    /// The spectral radius of ``(I - L H) F``.
    #[getter]
    fn observer_radius(&self) -> f64 {
        self.inner.observer_radius
    }
}

/// Designs the LQR baseline for a linearization with the tuning's ten values (in the order of
/// ``accd_gym.control.lqr.LqrTuning``'s fields); ``ConfigError`` when no stabilizing design
/// exists.
#[pyfunction]
pub fn lqr_design(
    py: Python<'_>,
    lin: &PyLinearization,
    tuning: [f64; 10],
) -> PyResult<PyLqrDesign> {
    let tuning = LqrTuning::new(tuning).py_err()?;
    let model = &lin.inner.model;
    let designed = py.detach(|| design(model, &tuning)).py_err()?;
    Ok(PyLqrDesign {
        inner: Arc::new(designed),
    })
}

/// The Kalman filter and control law of one design, with the filter state of every env of a
/// batch (see the module docs of ``accd_sim::control::filter``).
#[pyclass(name = "LqrFilter", module = "accd_gym._core")]
pub struct PyLqrFilter {
    pub(crate) filter: Arc<LqrFilter>,
    states: Vec<FilterState>,
}

pub(crate) fn check_shape(name: &str, got: &[usize], want: &[usize]) -> PyResult<()> {
    if got != want {
        return Err(raise(
            Kind::State,
            format!("`{name}` has shape {got:?}, expected {want:?}"),
        ));
    }
    Ok(())
}

#[pymethods]
impl PyLqrFilter {
    /// The filter of a design's matrices (``n`` plant states; shapes as ``LqrDesign``'s).
    #[new]
    #[allow(clippy::too_many_arguments)]
    fn new(
        n: usize,
        f: PyReadonlyArray2<'_, f64>,
        g: PyReadonlyArray2<'_, f64>,
        h: PyReadonlyArray2<'_, f64>,
        l: PyReadonlyArray2<'_, f64>,
        k: PyReadonlyArray2<'_, f64>,
        k_ff: PyReadonlyArray2<'_, f64>,
        y_trim: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Self> {
        let y = y_trim.as_array();
        check_shape("y_trim", y.shape(), &[MEASURED_DIM])?;
        let mut yt = [0.0; MEASURED_DIM];
        for (o, v) in yt.iter_mut().zip(y.iter()) {
            *o = *v;
        }
        let filter = LqrFilter::from_parts(
            n,
            &from_py(&f),
            &from_py(&g),
            &from_py(&h),
            &from_py(&l),
            &from_py(&k),
            &from_py(&k_ff),
            yt,
        )
        .py_err()?;
        Ok(Self {
            filter: Arc::new(filter),
            states: Vec::new(),
        })
    }

    /// Number of envs whose state it holds (0 before the first ``step``).
    #[getter]
    fn num_envs(&self) -> usize {
        self.states.len()
    }

    /// Observer states ``nz``.
    #[getter]
    fn nz(&self) -> usize {
        self.filter.nz()
    }

    /// Flap commands (N, 4) float32 in [-1, 1] for observations (N, 25) float64. ``rows`` (a
    /// bool mask, default all) selects the envs computed; the others keep their state and get
    /// zero commands. ``advance`` (default true) keeps the new estimates; false leaves every
    /// state as it was (a look-ahead). A batch of another size than the state's starts every
    /// estimate afresh. A row's command does not depend on the other rows.
    #[pyo3(signature = (obs, rows = None, advance = true))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        obs: PyReadonlyArray2<'_, f64>,
        rows: Option<PyReadonlyArray1<'_, bool>>,
        advance: bool,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let view = obs.as_array();
        let n = view.nrows();
        check_shape("obs", view.shape(), &[n, OBS_DIM])?;
        let mask: Vec<bool> = match rows {
            None => vec![true; n],
            Some(m) => {
                let m = m.as_array();
                check_shape("rows", m.shape(), &[n])?;
                m.to_vec()
            }
        };
        if self.states.len() != n {
            self.states = (0..n).map(|_| self.filter.new_state()).collect();
        }
        let mut flat = vec![[0.0_f64; OBS_DIM]; n];
        for (o, r) in flat.iter_mut().zip(view.rows()) {
            for (a, b) in o.iter_mut().zip(r.iter()) {
                *a = *b;
            }
        }
        let mut out = vec![[0.0_f32; ACT_DIM]; n];
        let filter = &*self.filter;
        let mut look_ahead;
        let states = if advance {
            &mut self.states
        } else {
            look_ahead = self.states.clone();
            &mut look_ahead
        };
        py.detach(|| filter.step_rows(states, &flat, &mask, &mut out))
            .py_err()?;
        let arr = Array2::from_shape_fn((n, ACT_DIM), |(i, j)| out[i][j]);
        Ok(arr.into_pyarray(py))
    }

    /// Restarts the estimates of the envs in ``mask`` (all when None): their next observation
    /// initialises them.
    #[pyo3(signature = (mask = None))]
    fn restart(&mut self, mask: Option<PyReadonlyArray1<'_, bool>>) -> PyResult<()> {
        restart_rows(&mut self.states, mask)
    }

    /// Adds ``offset`` (N, 4; flap-limit units) to the command each env's next prediction uses.
    fn sent(&mut self, offset: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        add_sent(&mut self.states, offset)
    }

    /// The state of every env: ``z`` (N, nz), ``u`` (N, 4), ``fresh`` (N,) (copies).
    #[allow(clippy::type_complexity)]
    fn get_state<'py>(
        &self,
        py: Python<'py>,
    ) -> (
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<bool>>,
    ) {
        states_to_arrays(py, &self.states, self.filter.nz())
    }

    /// Restores a state of ``get_state`` (``StateError`` for shapes that do not fit).
    fn set_state(
        &mut self,
        z: PyReadonlyArray2<'_, f64>,
        u: PyReadonlyArray2<'_, f64>,
        fresh: PyReadonlyArray1<'_, bool>,
    ) -> PyResult<()> {
        self.states = states_from_arrays(&self.filter, z, u, fresh)?;
        Ok(())
    }

    /// Forgets every env's state (the next ``step`` starts afresh).
    fn clear(&mut self) {
        self.states.clear();
    }
}

/// Marks the envs in ``mask`` (all when None) to restart: their next observation initialises them.
pub(crate) fn restart_rows(
    states: &mut [FilterState],
    mask: Option<PyReadonlyArray1<'_, bool>>,
) -> PyResult<()> {
    match mask {
        None => states.iter_mut().for_each(|s| s.fresh = true),
        Some(m) => {
            let m = m.as_array();
            check_shape("mask", m.shape(), &[states.len()])?;
            for (s, r) in states.iter_mut().zip(m.iter()) {
                if *r {
                    s.fresh = true;
                }
            }
        }
    }
    Ok(())
}

/// Adds ``offset`` (N, 4; flap-limit units) to the command each env's next prediction uses.
pub(crate) fn add_sent(
    states: &mut [FilterState],
    offset: PyReadonlyArray2<'_, f64>,
) -> PyResult<()> {
    let v = offset.as_array();
    check_shape("offset", v.shape(), &[states.len(), ACT_DIM])?;
    if v.iter().any(|d| !d.is_finite()) {
        return Err(crate::errors::raise(
            crate::errors::Kind::State,
            "invalid state: `offset` has non-finite values, outside the allowed range: finite flap-limit units",
        ));
    }
    for (s, r) in states.iter_mut().zip(v.rows()) {
        for (u, d) in s.u.iter_mut().zip(r.iter()) {
            *u += *d;
        }
    }
    Ok(())
}

/// The rows' filter states as ``z`` (N, nz), ``u`` (N, 4), ``fresh`` (N,) (copies).
#[allow(clippy::type_complexity)]
pub(crate) fn states_to_arrays<'py>(
    py: Python<'py>,
    states: &[FilterState],
    nz: usize,
) -> (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<bool>>,
) {
    let rows = states.len();
    let z = Array2::from_shape_fn((rows, nz), |(i, j)| states[i].z[j]);
    let u = Array2::from_shape_fn((rows, ACT_DIM), |(i, j)| states[i].u[j]);
    let fresh = Array1::from_shape_fn(rows, |i| states[i].fresh);
    (
        z.into_pyarray(py),
        u.into_pyarray(py),
        fresh.into_pyarray(py),
    )
}

/// The filter states of [`states_to_arrays`]'s arrays (``StateError`` for shapes that do not
/// fit ``filter``).
pub(crate) fn states_from_arrays(
    filter: &LqrFilter,
    z: PyReadonlyArray2<'_, f64>,
    u: PyReadonlyArray2<'_, f64>,
    fresh: PyReadonlyArray1<'_, bool>,
) -> PyResult<Vec<FilterState>> {
    let (z, u, fresh) = (z.as_array(), u.as_array(), fresh.as_array());
    let rows = z.nrows();
    check_shape("z", z.shape(), &[rows, filter.nz()])?;
    check_shape("u", u.shape(), &[rows, ACT_DIM])?;
    check_shape("fresh", fresh.shape(), &[rows])?;
    let mut states = Vec::with_capacity(rows);
    for i in 0..rows {
        let mut s = filter.new_state();
        for (a, b) in s.z.iter_mut().zip(z.row(i).iter()) {
            *a = *b;
        }
        for (a, b) in s.u.iter_mut().zip(u.row(i).iter()) {
            *a = *b;
        }
        s.fresh = fresh[i];
        states.push(s);
    }
    Ok(states)
}
