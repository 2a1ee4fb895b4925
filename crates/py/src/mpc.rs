//! `accd_gym._core.Mpc`: the MPC baseline's per-step work ([`accd_sim::control::mpc`]) for
//! `accd_gym.control.mpc.MpcPolicy`.
//!
//! `Mpc` owns the LQR filter state of every env of a batch (the estimate the MPC plans from) and
//! steps them with the GIL released, on the calling thread, row after row: each row's
//! arithmetic depends on nothing but its own inputs, so the results are the same bits whatever
//! the batch size. The interface is `LqrFilter`'s, plus the solve counts.

use std::sync::Arc;

use accd_sim::control::filter::{FilterState, LqrFilter};
use accd_sim::control::lqr::MEASURED_DIM;
use accd_sim::control::mpc::{CaptureLimits, Mpc, MpcScratch, MpcStats, MpcTuning};
use accd_sim::{ACT_DIM, OBS_DIM};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::errors::IntoPy;
use crate::lqr::{
    add_sent, check_shape, from_py, restart_rows, states_from_arrays, states_to_arrays,
};

/// The MPC of one LQR design with the filter state of every env of a batch (see the module
/// docs of ``accd_sim::control::mpc``).
#[pyclass(name = "Mpc", module = "accd_gym._core")]
pub struct PyMpc {
    pub(crate) mpc: Arc<Mpc>,
    states: Vec<FilterState>,
    stats: MpcStats,
    /// The QP's workspace, made once: a solve allocates nothing.
    scratch: MpcScratch,
}

#[pymethods]
impl PyMpc {
    /// The MPC of an LQR design's matrices (``n`` plant states; ``f``, ``g``, ``h``, ``l``,
    /// ``k``, ``k_ff``, ``y_trim`` as ``LqrFilter``'s; ``q``, ``p`` the LQR's weight and Riccati
    /// solution, ``x_ss``, ``u_ss`` its reference), ``r_flap``, the agent step ``dt``, the
    /// settings ``(horizon, lead, margin, window, slack_weight, iterations)`` and the capture limits
    /// ``(max_closing_speed, capture_radius, approach_speed)``. ``ConfigError`` naming the field
    /// for a bad value (a zero horizon among them).
    #[new]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        n: usize,
        f: PyReadonlyArray2<'_, f64>,
        g: PyReadonlyArray2<'_, f64>,
        h: PyReadonlyArray2<'_, f64>,
        l: PyReadonlyArray2<'_, f64>,
        k: PyReadonlyArray2<'_, f64>,
        k_ff: PyReadonlyArray2<'_, f64>,
        y_trim: PyReadonlyArray1<'_, f64>,
        q: PyReadonlyArray2<'_, f64>,
        p: PyReadonlyArray2<'_, f64>,
        x_ss: PyReadonlyArray2<'_, f64>,
        u_ss: PyReadonlyArray2<'_, f64>,
        r_flap: f64,
        dt: f64,
        settings: (usize, usize, f64, f64, f64, usize),
        limits: (f64, f64, f64),
    ) -> PyResult<Self> {
        let (horizon, lead, margin, window, slack_weight, iterations) = settings;
        let tuning =
            MpcTuning::new(horizon, lead, margin, window, slack_weight, iterations).py_err()?;
        let y = y_trim.as_array();
        check_shape("y_trim", y.shape(), &[MEASURED_DIM])?;
        let mut yt = [0.0; MEASURED_DIM];
        for (o, v) in yt.iter_mut().zip(y.iter()) {
            *o = *v;
        }
        let (f, g, h) = (from_py(&f), from_py(&g), from_py(&h));
        let filter = LqrFilter::from_parts(
            n,
            &f,
            &g,
            &h,
            &from_py(&l),
            &from_py(&k),
            &from_py(&k_ff),
            yt,
        )
        .py_err()?;
        let (q, p, x_ss, u_ss) = (from_py(&q), from_py(&p), from_py(&x_ss), from_py(&u_ss));
        let limits = CaptureLimits {
            max_closing_speed: limits.0,
            capture_radius: limits.1,
            approach_speed: limits.2,
        };
        let mpc = py
            .detach(|| {
                Mpc::new(
                    filter, &f, &g, &h, &q, r_flap, &p, &x_ss, &u_ss, dt, tuning, limits,
                )
            })
            .py_err()?;
        let scratch = mpc.plan().new_scratch();
        Ok(Self {
            mpc: Arc::new(mpc),
            states: Vec::new(),
            stats: MpcStats::default(),
            scratch,
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
        self.mpc.filter().nz()
    }

    /// The horizon in agent steps.
    #[getter]
    fn horizon(&self) -> usize {
        self.mpc.plan().horizon()
    }

    /// ``(steps, constrained, inexact, fallbacks)`` since construction: rows stepped, rows
    /// solved exactly with active constraints, rows whose solve reached the active-set step
    /// limit and rows whose solve failed (both of which got the LQR's command).
    #[getter]
    fn stats(&self) -> (u64, u64, u64, u64) {
        (
            self.stats.steps,
            self.stats.constrained,
            self.stats.inexact,
            self.stats.fallbacks,
        )
    }

    /// Flap commands (N, 4) float32 in [-1, 1] for observations (N, 25) float64, as
    /// ``LqrFilter.step`` (``rows``: the envs computed; ``advance=False``: a look-ahead that
    /// keeps every state and count).
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
            self.states = (0..n).map(|_| self.mpc.filter().new_state()).collect();
        }
        let mut flat = vec![[0.0_f64; OBS_DIM]; n];
        for (o, r) in flat.iter_mut().zip(view.rows()) {
            for (a, b) in o.iter_mut().zip(r.iter()) {
                *a = *b;
            }
        }
        let mut out = vec![[0.0_f32; ACT_DIM]; n];
        let mpc = &*self.mpc;
        let mut look_ahead;
        let mut stats = self.stats;
        let states = if advance {
            &mut self.states
        } else {
            look_ahead = self.states.clone();
            &mut look_ahead
        };
        let scratch = &mut self.scratch;
        let solved =
            py.detach(|| mpc.step_rows(states, &flat, &mask, &mut out, scratch, &mut stats));
        if advance {
            // The rows stepped before an error keep their new states: their counts too.
            self.stats = stats;
        }
        solved.py_err()?;
        let arr = Array2::from_shape_fn((n, ACT_DIM), |(i, j)| out[i][j]);
        Ok(arr.into_pyarray(py))
    }

    /// Restarts the estimates of the envs in ``mask`` (all when None).
    #[pyo3(signature = (mask = None))]
    fn restart(&mut self, mask: Option<PyReadonlyArray1<'_, bool>>) -> PyResult<()> {
        restart_rows(&mut self.states, mask)
    }

    /// Adds ``offset`` (N, 4; flap-limit units) to the command each env's next prediction uses.
    fn sent(&mut self, offset: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        add_sent(&mut self.states, offset)
    }

    /// The state of every env: ``z`` (N, nz), ``u`` (N, 4), ``fresh`` (N,) (copies). The MPC
    /// keeps nothing else between steps (each solve starts from the unconstrained optimum).
    #[allow(clippy::type_complexity)]
    fn get_state<'py>(
        &self,
        py: Python<'py>,
    ) -> (
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<bool>>,
    ) {
        states_to_arrays(py, &self.states, self.mpc.filter().nz())
    }

    /// Restores a state of ``get_state`` (``StateError`` for shapes that do not fit).
    fn set_state(
        &mut self,
        z: PyReadonlyArray2<'_, f64>,
        u: PyReadonlyArray2<'_, f64>,
        fresh: PyReadonlyArray1<'_, bool>,
    ) -> PyResult<()> {
        self.states = states_from_arrays(self.mpc.filter(), z, u, fresh)?;
        Ok(())
    }

    /// Forgets every env's state (the next ``step`` starts afresh).
    fn clear(&mut self) {
        self.states.clear();
    }
}
