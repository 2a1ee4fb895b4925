//! `accd_gym._core.BatchEnv`: the native batch of RL episodes behind the gymnasium and
//! stable-baselines3 envs. Rust writes every step's outputs straight into numpy arrays that this
//! object owns (two sets, used alternately), with the GIL released while the envs step.

use accd_batch::BatchState;
use accd_batch::{
    check_base_seed, info, Autoreset, BatchEnv, BatchError, ResetBuffers, SeedSpec, StepBuffers,
    WakeSchedule, HELD_OUT_WAKE_SEEDS, MAX_ENVS, MAX_THREADS, TRAINING_WAKE_SEEDS,
    VALIDATION_WAKE_SEEDS,
};
use std::sync::Arc;

use accd_sim::control::controller::{Controller, ControllerState, LqrController, MpcController};
use accd_sim::control::filter::FilterState;
use accd_sim::state_format::{self, StateKind};
use accd_sim::{EnvConfig, SimError, Valid, ACT_DIM, OBSERVATION, OBS_BOUND, OBS_DIM};
use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyString, PyTuple};
use serde::{Deserialize, Serialize};

use crate::arrays::{vector_to_py, vectors_to_py};
use crate::capture::{seed_from_py, snapshot_dict, usize_from_py};
use crate::config::PyEnvConfig;
use crate::errors::{raise, IntoPy, Kind};
use crate::lqr::{check_shape, states_to_arrays, PyLqrFilter};
use crate::mpc::PyMpc;
use crate::signals::SignalCheck;

/// One set of output arrays.
struct Buffers {
    obs: Py<PyArray2<f32>>,
    final_obs: Py<PyArray2<f32>>,
    reward: Py<PyArray1<f64>>,
    terminated: Py<PyArray1<bool>>,
    truncated: Py<PyArray1<bool>>,
    info: Py<PyArray2<f64>>,
    wake_seed: Py<PyArray1<u64>>,
    autoreset: Py<PyArray1<bool>>,
}

impl Buffers {
    fn new(py: Python<'_>, n: usize) -> Buffers {
        Buffers {
            obs: PyArray2::zeros(py, [n, OBS_DIM], false).unbind(),
            final_obs: PyArray2::zeros(py, [n, OBS_DIM], false).unbind(),
            reward: PyArray1::zeros(py, n, false).unbind(),
            terminated: PyArray1::from_vec(py, vec![false; n]).unbind(),
            truncated: PyArray1::from_vec(py, vec![false; n]).unbind(),
            info: PyArray2::zeros(py, [n, info::DIM], false).unbind(),
            wake_seed: PyArray1::zeros(py, n, false).unbind(),
            autoreset: PyArray1::from_vec(py, vec![false; n]).unbind(),
        }
    }

    /// Whether Rust may write every array now: a caller may have made one read-only
    /// (``flags.writeable = False``) or hold a borrow of it.
    fn writable(&self, py: Python<'_>) -> bool {
        self.obs.bind(py).try_readwrite().is_ok()
            && self.final_obs.bind(py).try_readwrite().is_ok()
            && self.reward.bind(py).try_readwrite().is_ok()
            && self.terminated.bind(py).try_readwrite().is_ok()
            && self.truncated.bind(py).try_readwrite().is_ok()
            && self.info.bind(py).try_readwrite().is_ok()
            && self.wake_seed.bind(py).try_readwrite().is_ok()
            && self.autoreset.bind(py).try_readwrite().is_ok()
    }
}

/// A write borrow of `array`; an error (never a panic) if it cannot be had, which
/// [`PyBatchEnv::next_buffers`] rules out by replacing arrays that are not writable.
fn writable<'py, T: numpy::Element, D: numpy::ndarray::Dimension>(
    array: &Bound<'py, numpy::PyArray<T, D>>,
) -> PyResult<numpy::PyReadwriteArray<'py, T, D>> {
    array.try_readwrite().map_err(|e| {
        pyo3::exceptions::PyRuntimeError::new_err(format!(
            "internal error (a bug, please report it): an output array is not writable ({e})"
        ))
    })
}

/// N In-Air Capturing episodes stepped by one call (internal; use ``accd_gym.AccdVecEnv`` or
/// ``gymnasium.make_vec("accd_gym/InAirCapture-v0")``).
///
/// ``step`` and ``reset`` return numpy arrays owned by this object, written in place by Rust.
/// Two sets are used alternately: an array returned by one call stays valid through the next
/// call and is overwritten by the call after it. Copy what you keep longer. An array the caller
/// made read-only (or holds a borrow of) is left alone: that set is replaced by new arrays.
#[pyclass(name = "BatchEnv", module = "accd_gym._core")]
pub struct PyBatchEnv {
    inner: BatchEnv,
    buffers: [Buffers; 2],
    next: usize,
}

impl PyBatchEnv {
    /// The next buffer set, replaced by new arrays if the caller made one of its arrays
    /// read-only; flips the alternation.
    fn next_buffers(&mut self, py: Python<'_>) -> &Buffers {
        let i = self.next;
        self.next = 1 - self.next;
        if !self.buffers[i].writable(py) {
            self.buffers[i] = Buffers::new(py, self.inner.num_envs());
        }
        &self.buffers[i]
    }
}

/// The payload of a Python env's state ([`accd_sim::state_format`]; a change here is a change
/// of the format): the batch and the two flags the Python class keeps.
#[derive(Serialize, Deserialize)]
struct EnvState {
    /// The env must be reset before it is stepped (it never was).
    needs_reset: bool,
    /// The env was seeded (a reset without a seed then continues the seeded streams).
    seeded: bool,
    /// The batch.
    batch: BatchState,
}

/// The state kind of a Python env class: ``"single"``, ``"vector"`` or ``"sb3"``.
fn parse_kind(kind: &str) -> PyResult<StateKind> {
    match kind {
        "single" => Ok(StateKind::SingleEnv),
        "vector" => Ok(StateKind::VectorEnv),
        "sb3" => Ok(StateKind::Sb3VecEnv),
        other => Err(raise(
            Kind::State,
            format!(
                "invalid state kind `kind` = {other:?}, expected \"single\", \"vector\" or \"sb3\""
            ),
        )),
    }
}

fn parse_autoreset(mode: &str) -> PyResult<Autoreset> {
    match mode {
        "same_step" => Ok(Autoreset::SameStep),
        "next_step" => Ok(Autoreset::NextStep),
        "disabled" => Ok(Autoreset::Disabled),
        other => Err(raise(
            Kind::Config,
            format!("invalid config: `autoreset_mode` = {other:?} is outside the allowed range \"same_step\", \"next_step\" or \"disabled\""),
        )),
    }
}

/// The flap commands of a step, `(num_envs, 4)` float32 and C-contiguous, as one slice.
fn action_rows<'a>(actions: &'a PyReadonlyArray2<'_, f32>, n: usize) -> PyResult<&'a [f32]> {
    let shape = actions.shape();
    if shape != [n, ACT_DIM] {
        return Err(raise(
            Kind::State,
            format!("actions have shape {shape:?}, expected ({n}, {ACT_DIM})"),
        ));
    }
    actions
        .as_slice()
        .map_err(|_| raise(Kind::State, "actions must be a C-contiguous float32 array"))
}

#[pymethods]
impl PyBatchEnv {
    /// ``num_envs`` episodes of ``config`` (a validated ``EnvConfig``, used as it is, or an
    /// ``EnvConfig`` as JSON, validated here), env ``i`` seeded with base ``seed + i`` (``seed``
    /// in [0, 2^63 - num_envs]: no seed wraps); autoreset ``"same_step"``, ``"next_step"`` or
    /// ``"disabled"``; ``num_threads`` threads of its own (0 or None: one per core). The counts
    /// are Python or numpy integers in [1, MAX_ENVS] and [0, MAX_THREADS] (ConfigError naming
    /// the argument otherwise).
    #[new]
    #[pyo3(signature = (config, num_envs, seed, autoreset_mode = "same_step", num_threads = None))]
    fn new(
        py: Python<'_>,
        config: &Bound<'_, PyAny>,
        num_envs: &Bound<'_, PyAny>,
        seed: &Bound<'_, PyAny>,
        autoreset_mode: &str,
        num_threads: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let num_envs = usize_from_py("num_envs", num_envs, 1, MAX_ENVS)?;
        let num_threads = match num_threads {
            Some(t) => usize_from_py("num_threads", t, 0, MAX_THREADS)?,
            None => 0,
        };
        let seed = seed_from_py("seed", seed)?;
        check_base_seed(seed, num_envs).py_err()?;
        let mode = parse_autoreset(autoreset_mode)?;
        let config = match config.cast::<PyEnvConfig>() {
            Ok(valid) => Valid::clone(&valid.get().inner),
            Err(_) => {
                let text: &str = config.extract().map_err(|_| {
                    raise(
                        Kind::Config,
                        "invalid config: a BatchEnv takes an EnvConfig or its JSON text",
                    )
                })?;
                EnvConfig::from_json(text).py_err()?
            }
        };
        let mut check = SignalCheck::new();
        let built = py.detach(|| {
            BatchEnv::new_interruptible(config, num_envs, seed, mode, num_threads, &mut || {
                check.interrupted()
            })
        });
        if let Some(e) = check.take() {
            return Err(e);
        }
        let inner = built.py_err()?;
        if let Some(why) = &inner.equilibrium().outside_limits {
            let message = std::ffi::CString::new(why.as_str())
                .map_err(|e| raise(Kind::Config, e.to_string()))?;
            PyErr::warn(
                py,
                &py.get_type::<pyo3::exceptions::PyUserWarning>(),
                &message,
                2,
            )?;
        }
        let n = inner.num_envs();
        Ok(PyBatchEnv {
            inner,
            buffers: [Buffers::new(py, n), Buffers::new(py, n)],
            next: 0,
        })
    }

    /// Number of envs.
    #[getter]
    fn num_envs(&self) -> usize {
        self.inner.num_envs()
    }

    /// Threads stepping the envs.
    #[getter]
    fn num_threads(&self) -> usize {
        self.inner.threads()
    }

    /// The full configuration (defaults filled in) as JSON.
    fn config_json(&self) -> PyResult<String> {
        serde_json::to_string(self.inner.config()).map_err(|e| raise(Kind::Config, e.to_string()))
    }

    /// Starts new episodes in every env, or in those ``mask`` selects ((num_envs,) bool), and
    /// returns ``(obs, wake_seed)``: every env's observation (num_envs, OBS_DIM) float32 and its
    /// episode's wake seed (num_envs,) uint64 (new episodes', and the current ones of envs the
    /// mask leaves alone). ``seed``: None (each env's next episode), an int in
    /// [0, 2^63 - num_envs] (env ``i``: base ``seed + i``, never wrapped) or a sequence of
    /// num_envs ints in [0, 2^63) (env ``i``: base ``seed[i]``); a single env seeded with env
    /// ``i``'s base replays it. Python and numpy integers only (ConfigError otherwise).
    #[pyo3(signature = (seed = None, mask = None))]
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seed: Option<&Bound<'py, PyAny>>,
        mask: Option<Vec<bool>>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let spec = match seed {
            None => SeedSpec::Next,
            Some(s) if s.is_none() => SeedSpec::Next,
            // A sequence (list, tuple, array): one seed per env; a string is no sequence of seeds.
            Some(s) if !s.is_instance_of::<PyString>() && s.try_iter().is_ok() => SeedSpec::PerEnv(
                s.try_iter()?
                    .map(|v| seed_from_py("seed", &v?))
                    .collect::<PyResult<Vec<u64>>>()?,
            ),
            Some(s) => {
                let base = seed_from_py("seed", s)?;
                check_base_seed(base, self.inner.num_envs()).py_err()?;
                SeedSpec::Base(base)
            }
        };
        let b = self.next_buffers(py);
        let obs = b.obs.bind(py).clone();
        let wake = b.wake_seed.bind(py).clone();
        {
            let mut o = writable(&obs)?;
            let mut w = writable(&wake)?;
            let (o, w) = (o.as_slice_mut()?, w.as_slice_mut()?);
            let inner = &mut self.inner;
            py.detach(|| {
                inner.reset(
                    spec,
                    mask.as_deref(),
                    ResetBuffers {
                        obs: o,
                        wake_seed: w,
                    },
                )
            })
            .py_err()?;
        }
        PyTuple::new(py, [obs.into_any(), wake.into_any()])
    }

    /// One agent step of every env with ``actions`` ((num_envs, 4) float32, C-contiguous; values
    /// outside [-1, 1] are clipped, non-finite values raise StateError naming the env). Returns
    /// ``(obs, reward, terminated, truncated, final_obs, info, wake_seed, autoreset)``; see the
    /// Python envs for their meaning.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        actions: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let a = action_rows(&actions, self.inner.num_envs())?;
        let b = self.next_buffers(py);
        let arrays = (
            b.obs.bind(py).clone(),
            b.reward.bind(py).clone(),
            b.terminated.bind(py).clone(),
            b.truncated.bind(py).clone(),
            b.final_obs.bind(py).clone(),
            b.info.bind(py).clone(),
            b.wake_seed.bind(py).clone(),
            b.autoreset.bind(py).clone(),
        );
        {
            let mut obs = writable(&arrays.0)?;
            let mut reward = writable(&arrays.1)?;
            let mut terminated = writable(&arrays.2)?;
            let mut truncated = writable(&arrays.3)?;
            let mut final_obs = writable(&arrays.4)?;
            let mut info = writable(&arrays.5)?;
            let mut wake = writable(&arrays.6)?;
            let mut reset = writable(&arrays.7)?;
            let buffers = StepBuffers {
                obs: obs.as_slice_mut()?,
                reward: reward.as_slice_mut()?,
                terminated: terminated.as_slice_mut()?,
                truncated: truncated.as_slice_mut()?,
                final_obs: final_obs.as_slice_mut()?,
                info: info.as_slice_mut()?,
                wake_seed: wake.as_slice_mut()?,
                autoreset: reset.as_slice_mut()?,
            };
            let inner = &mut self.inner;
            let mut check = SignalCheck::new();
            let result =
                py.detach(|| inner.step_interruptible(a, buffers, &mut || check.interrupted()));
            if let Some(e) = check.take() {
                return Err(e);
            }
            result.py_err()?;
        }
        PyTuple::new(
            py,
            [
                arrays.0.into_any(),
                arrays.1.into_any(),
                arrays.2.into_any(),
                arrays.3.into_any(),
                arrays.4.into_any(),
                arrays.5.into_any(),
                arrays.6.into_any(),
                arrays.7.into_any(),
            ],
        )
    }

    /// Benchmark support: ``steps`` agent steps of every env with the same ``actions``
    /// (``(num_envs, 4)`` float32), stepped by the Rust batch alone (its ``step``, as the
    /// criterion benchmark ``batch_step`` runs it: no Python and no numpy between the steps, the
    /// outputs into buffers of its own), with the GIL released. Returns the wall time in seconds.
    /// The envs advance as :meth:`step` advances them; Ctrl+C stops the loop between two steps
    /// (``KeyboardInterrupt``).
    fn time_rust_steps(
        &mut self,
        py: Python<'_>,
        actions: PyReadonlyArray2<'_, f32>,
        steps: &Bound<'_, PyAny>,
    ) -> PyResult<f64> {
        let steps = usize_from_py("steps", steps, 0, usize::MAX)?;
        let n = self.inner.num_envs();
        let a = action_rows(&actions, n)?.to_vec();
        let mut out = accd_batch::StepOutputs::new(n);
        let inner = &mut self.inner;
        let mut check = SignalCheck::new();
        let result = py.detach(|| {
            let start = std::time::Instant::now();
            for _ in 0..steps {
                if check.interrupted() {
                    break;
                }
                inner.step(&a, out.buffers())?;
            }
            Ok::<f64, BatchError>(start.elapsed().as_secs_f64())
        });
        if let Some(e) = check.take() {
            return Err(e);
        }
        result.py_err()
    }

    /// Sets where the wake seeds of the episodes started from now on come from:
    /// ``"training"`` (drawn from the training range), ``"fixed"`` (``seeds[0]`` for every
    /// episode) or ``"list"`` (env ``i``'s episode ``e`` uses ``seeds[(i + e * num_envs) % len]``).
    #[pyo3(signature = (kind, seeds = Vec::new()))]
    fn set_wake_schedule(&mut self, kind: &str, seeds: Vec<u64>) -> PyResult<()> {
        let schedule = match (kind, seeds.as_slice()) {
            ("training", []) => WakeSchedule::Training,
            ("fixed", [s]) => WakeSchedule::Fixed(*s),
            ("list", list) if !list.is_empty() => WakeSchedule::List(list.to_vec()),
            _ => {
                return Err(raise(
                    Kind::Config,
                    format!("invalid config: wake schedule `{kind}` with {} seeds is outside the allowed range: \"training\" with none, \"fixed\" with one, \"list\" with at least one", seeds.len()),
                ))
            }
        };
        self.inner.set_wake_schedule(schedule).py_err()
    }

    /// The current wake schedule as ``(kind, seeds)``.
    fn wake_schedule(&self) -> (String, Vec<u64>) {
        match self.inner.wake_schedule() {
            WakeSchedule::Training => ("training".into(), vec![]),
            WakeSchedule::Fixed(s) => ("fixed".into(), vec![*s]),
            WakeSchedule::List(l) => ("list".into(), l.clone()),
        }
    }

    /// Every env's exact state (episodes, seeds, counters, random streams) and the Python
    /// env's flags ``needs_reset`` and ``seeded``, as bytes: a header (magic, format version,
    /// ``kind`` (``"single"``, ``"vector"`` or ``"sb3"``), number of envs, the config's SHA-256,
    /// a CRC-32) and the postcard-encoded state (``accd_sim::state_format``).
    fn get_state<'py>(
        &self,
        py: Python<'py>,
        kind: &str,
        needs_reset: bool,
        seeded: bool,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let kind = parse_kind(kind)?;
        self.inner.check_consistent().py_err()?;
        let hash = self.inner.config_hash().py_err()?;
        let state = EnvState {
            needs_reset,
            seeded,
            batch: self.inner.state(),
        };
        let n = self.inner.num_envs() as u64;
        let bytes = state_format::encode(kind, &hash, n, &state).py_err()?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// Restores a state from ``get_state`` of an env of the same ``kind``, config and number of
    /// envs and returns its ``(needs_reset, seeded)``. Anything else (corrupted, truncated,
    /// another kind, config or size, the old format) raises ``StateError`` naming what is wrong
    /// and changes nothing.
    fn set_state(&mut self, py: Python<'_>, state: &[u8], kind: &str) -> PyResult<(bool, bool)> {
        let kind = parse_kind(kind)?;
        let inner = &mut self.inner;
        py.detach(|| {
            let expected = inner.expected_state(kind)?;
            let saved: EnvState = state_format::decode(state, &expected).map_err(SimError::from)?;
            inner.set_state(saved.batch)?;
            Ok::<_, BatchError>((saved.needs_reset, saved.seeded))
        })
        .py_err()
    }

    /// The true boom tip minus capture point of every env at its current state, (N, 3) m, TA
    /// frame (a new array): what the observation's ``boom_rel_*`` shows without sensors.
    fn boom_relative<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = self.inner.num_envs();
        let mut rows = Vec::with_capacity(n);
        for i in 0..n {
            let r = self.inner.episode(i).py_err()?.sim().boom_relative();
            rows.push(vec![r.x, r.y, r.z]);
        }
        Ok(PyArray2::from_vec2(py, &rows)?)
    }

    /// The current observation of env ``i`` (a new array).
    fn observation<'py>(&self, py: Python<'py>, i: usize) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let e = self.inner.episode(i).py_err()?;
        Ok(PyArray1::from_slice(py, e.observation()))
    }

    /// Seeds of env ``i``'s current episode: ``{"initial", "wake", "rlv"}``.
    fn episode_seeds<'py>(&self, py: Python<'py>, i: usize) -> PyResult<Bound<'py, PyDict>> {
        let s = self.inner.episode(i).py_err()?.seeds();
        let d = PyDict::new(py);
        d.set_item("initial", s.initial)?;
        d.set_item("wake", s.wake)?;
        d.set_item("rlv", s.rlv)?;
        Ok(d)
    }

    /// Physical parameters of env ``i``'s current episode with randomized physics (the keys of
    /// ``accd_gym.PARAMETER_NAMES``: tether length m, diameter m, ACCD mass kg, force and moment
    /// coefficient factors, wake angle deg, wake strength, airspeed m/s, ambient RMS m/s), or
    /// None without randomization.
    fn episode_parameters<'py>(
        &self,
        py: Python<'py>,
        i: usize,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(p) = self.inner.episode(i).py_err()?.parameters() else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        for (name, value) in accd_sim::Parameters::NAMES.iter().zip(p.values()) {
            d.set_item(*name, value)?;
        }
        Ok(Some(d))
    }

    /// Where env ``i``'s episode starts from (TA frame, m): ``equilibrium`` (the ACCD's open-loop
    /// equilibrium), ``capture_point`` (the capture point's) and ``boom_nominal`` (the boom tip's
    /// nominal formation position, ``boom.placement``).
    fn episode_setup<'py>(&self, py: Python<'py>, i: usize) -> PyResult<Bound<'py, PyDict>> {
        let eq = self.inner.episode(i).py_err()?.equilibrium();
        let d = PyDict::new(py);
        d.set_item("equilibrium", vector_to_py(py, &eq.position))?;
        d.set_item("capture_point", vector_to_py(py, &eq.capture_point))?;
        d.set_item("boom_nominal", vector_to_py(py, &eq.boom_nominal))?;
        Ok(d)
    }

    /// Keeps (``on``) or drops every env's true observation: what perfect sensors would
    /// observe (noise-free, delay-free), scaled like the observation; off by default, and
    /// nothing of it is computed while off.
    fn set_true_observation(&mut self, on: bool) {
        self.inner.set_true_observation(on);
    }

    /// Every env's true observation of its latest state, (num_envs, 25) float32 (StateError
    /// while true observations are off).
    fn true_observations<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let mut out = vec![0.0f32; self.inner.num_envs() * OBS_DIM];
        self.inner.true_observations(&mut out).py_err()?;
        rows_to_py(py, out)
    }

    /// Every env's true observation of the episode that ended in the last step, (num_envs, 25)
    /// float32 (``"same_step"`` autoreset; the rows of envs whose episode did not end are
    /// stale).
    fn final_true_observations<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let mut out = vec![0.0f32; self.inner.num_envs() * OBS_DIM];
        self.inner.final_true_observations(&mut out).py_err()?;
        rows_to_py(py, out)
    }

    /// Gives every env a controller of ``stepper`` (an ``LqrFilter`` or an ``Mpc``: its design,
    /// not its env states), or removes them (None). From then on each env's controller runs
    /// in the thread that steps the env, with the GIL released: after every reset and step it
    /// computes the command for the env's new observation (restarted with each new episode,
    /// automatic resets included), and before every step it is told the action sent (the
    /// filter predicts with it). Every env's controller starts afresh.
    fn set_controller(&mut self, stepper: Option<&Bound<'_, PyAny>>) -> PyResult<()> {
        let Some(stepper) = stepper.filter(|s| !s.is_none()) else {
            self.inner.set_controllers(None);
            return Ok(());
        };
        if let Ok(f) = stepper.cast::<PyLqrFilter>() {
            let filter = Arc::clone(&f.borrow().filter);
            let make = move || -> Box<dyn Controller> {
                Box::new(LqrController::new(Arc::clone(&filter)))
            };
            self.inner.set_controllers(Some(&make));
        } else if let Ok(m) = stepper.cast::<PyMpc>() {
            let mpc = Arc::clone(&m.borrow().mpc);
            let make =
                move || -> Box<dyn Controller> { Box::new(MpcController::new(Arc::clone(&mpc))) };
            self.inner.set_controllers(Some(&make));
        } else {
            return Err(raise(
                Kind::Config,
                format!(
                    "invalid config: a controller is an LqrFilter, an Mpc or None, got {}",
                    stepper.get_type().name()?
                ),
            ));
        }
        Ok(())
    }

    /// Whether the envs have controllers (``set_controller``).
    #[getter]
    fn has_controller(&self) -> bool {
        self.inner.has_controllers()
    }

    /// Every env's controller command for its latest observation, (num_envs, 4) float32 in
    /// [-1, 1] (StateError without controllers).
    fn controller_commands<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let mut out = vec![0.0f32; self.inner.num_envs() * ACT_DIM];
        self.inner.controller_commands(&mut out).py_err()?;
        PyArray1::from_vec(py, out).reshape([self.inner.num_envs(), ACT_DIM])
    }

    /// Every env's controller command for the last observation of the episode that ended in the
    /// last step, (num_envs, 4) float32 (``"same_step"`` autoreset; other rows are stale),
    /// computed without advancing the controller.
    fn final_controller_commands<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let mut out = vec![0.0f32; self.inner.num_envs() * ACT_DIM];
        self.inner.final_controller_commands(&mut out).py_err()?;
        PyArray1::from_vec(py, out).reshape([self.inner.num_envs(), ACT_DIM])
    }

    /// Every env's controller state: ``z`` (N, nz), ``u`` (N, 4), ``fresh`` (N,) as
    /// ``LqrFilter.get_state``, and ``command`` (N, 4) float32, the last command (copies).
    #[allow(clippy::type_complexity)]
    fn controller_state<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyArray2<f32>>,
    )> {
        let states = self.inner.controller_states().py_err()?;
        let filters: Vec<FilterState> = states.iter().map(|s| s.filter.clone()).collect();
        let nz = filters.first().map_or(0, |f| f.z.len());
        let (z, u, fresh) = states_to_arrays(py, &filters, nz);
        let commands: Vec<f32> = states.iter().flat_map(|s| s.command).collect();
        let commands = PyArray1::from_vec(py, commands).reshape([states.len(), ACT_DIM])?;
        Ok((z, u, fresh, commands))
    }

    /// Restores a state of ``controller_state`` (StateError for shapes that do not fit; then
    /// nothing changes).
    fn set_controller_state(
        &mut self,
        z: PyReadonlyArray2<'_, f64>,
        u: PyReadonlyArray2<'_, f64>,
        fresh: PyReadonlyArray1<'_, bool>,
        command: PyReadonlyArray2<'_, f32>,
    ) -> PyResult<()> {
        let n = self.inner.num_envs();
        let (zv, uv, fv, cv) = (
            z.as_array(),
            u.as_array(),
            fresh.as_array(),
            command.as_array(),
        );
        check_shape("command", cv.shape(), &[n, ACT_DIM])?;
        check_shape("u", uv.shape(), &[n, ACT_DIM])?;
        check_shape("fresh", fv.shape(), &[n])?;
        if zv.nrows() != n {
            check_shape("z", zv.shape(), &[n, zv.ncols()])?;
        }
        let states: Vec<ControllerState> = (0..n)
            .map(|i| {
                let mut filter = FilterState::new(zv.ncols());
                filter
                    .z
                    .iter_mut()
                    .zip(zv.row(i))
                    .for_each(|(a, b)| *a = *b);
                filter
                    .u
                    .iter_mut()
                    .zip(uv.row(i))
                    .for_each(|(a, b)| *a = *b);
                filter.fresh = fv[i];
                let mut command = [0.0f32; ACT_DIM];
                command.iter_mut().zip(cv.row(i)).for_each(|(a, b)| *a = *b);
                ControllerState { filter, command }
            })
            .collect();
        self.inner.set_controller_states(&states).py_err()
    }

    /// ``(steps, constrained, inexact, fallbacks)`` of the envs' MPC controllers since they were
    /// set, summed (zeros for the LQR; StateError without controllers).
    fn controller_stats(&self) -> PyResult<(u64, u64, u64, u64)> {
        let s = self.inner.controller_stats().py_err()?;
        Ok((s.steps, s.constrained, s.inexact, s.fallbacks))
    }

    /// Why env ``i``'s episode diverged, or None.
    fn divergence(&self, i: usize) -> PyResult<Option<String>> {
        Ok(self
            .inner
            .episode(i)
            .py_err()?
            .divergence()
            .map(str::to_owned))
    }

    /// Why env ``i``'s episode that ended in the last step diverged (``"same_step"`` autoreset,
    /// whose next episode has already started), or None.
    fn final_divergence(&self, i: usize) -> PyResult<Option<String>> {
        Ok(self.inner.final_divergence(i).py_err()?.map(str::to_owned))
    }

    /// What a picture of env ``i`` needs (TA frame, m): ``joints`` (n+1, 3), ``accd_position``,
    /// ``capture_point``, ``boom_tip``, ``equilibrium`` (3,), ``attitude`` (w, x, y, z),
    /// ``deflection_deg`` (4,), ``time`` s, ``distance`` m, ``tension`` N.
    fn render_data<'py>(&mut self, py: Python<'py>, i: usize) -> PyResult<Bound<'py, PyDict>> {
        let e = self.inner.episode_mut(i).py_err()?;
        let equilibrium = e.equilibrium().position;
        let sim = e.sim_mut();
        let s = sim.snapshot().py_err()?;
        let mut joints = vec![nalgebra::Vector3::zeros(); sim.tether_state().segments() + 1];
        sim.joint_positions(&mut joints).py_err()?;
        let d = PyDict::new(py);
        d.set_item("joints", vectors_to_py(py, &joints))?;
        d.set_item("accd_position", vector_to_py(py, &s.position))?;
        d.set_item("capture_point", vector_to_py(py, &s.capture_point))?;
        d.set_item("boom_tip", vector_to_py(py, &s.boom_tip))?;
        d.set_item("equilibrium", vector_to_py(py, &equilibrium))?;
        let q = s.attitude.quaternion();
        d.set_item("attitude", PyArray1::from_slice(py, &[q.w, q.i, q.j, q.k]))?;
        d.set_item("deflection_deg", s.deflection.map(f64::to_degrees).to_vec())?;
        d.set_item("time", s.time)?;
        d.set_item("distance", s.capture.distance)?;
        d.set_item("tension", s.attachment_tension)?;
        Ok(d)
    }

    /// Everything a recording stores of env ``i``'s current state (TA frame, SI units): the keys
    /// of ``CaptureSim.state`` (``time``, ``position``, ``velocity``, ``attitude``, ``euler``,
    /// ``omega``, ``flap_deflection_deg``, ``flap_command_deg``, ``alpha``, ``beta``,
    /// ``airspeed``, ``force``, ``moment``, ``capture_point``, ``capture_point_velocity``,
    /// ``boom_tip``, ``boom_velocity``, ``distance``, ``relative_speed``, ``captured``,
    /// ``attachment_tension``, ``aircraft_velocity``), plus ``joints`` (n+1, 3) m (the inboard end
    /// of each segment, then the tip), ``tensions`` (n+1,) N at those joints (entry 0 at the
    /// attachment, entry n the tip body's pull) and ``equilibrium`` (3,) m. Reading it leaves the
    /// episode unchanged (``tests/test_recording.py``).
    fn record_data<'py>(&mut self, py: Python<'py>, i: usize) -> PyResult<Bound<'py, PyDict>> {
        let e = self.inner.episode_mut(i).py_err()?;
        let equilibrium = e.equilibrium().position;
        let sim = e.sim_mut();
        let s = sim.snapshot().py_err()?;
        let n = sim.tether_state().segments();
        let mut joints = vec![nalgebra::Vector3::zeros(); n + 1];
        sim.joint_positions(&mut joints).py_err()?;
        let mut tensions = vec![0.0; n + 1];
        sim.tensions(&mut tensions).py_err()?;
        let d = snapshot_dict(py, &s)?;
        d.set_item("joints", vectors_to_py(py, &joints))?;
        d.set_item("tensions", PyArray1::from_vec(py, tensions))?;
        d.set_item("equilibrium", vector_to_py(py, &equilibrium))?;
        Ok(d)
    }
}

/// The default environment configuration as JSON.
#[pyfunction]
pub fn default_env_config_json() -> PyResult<String> {
    serde_json::to_string(&EnvConfig::default()).map_err(|e| raise(Kind::Config, e.to_string()))
}

/// Validates an environment configuration (JSON) and returns it with defaults filled in, as JSON;
/// raises ConfigError naming the field, value and allowed range.
#[pyfunction]
pub fn env_config_json(config_json: &str) -> PyResult<String> {
    let config = EnvConfig::from_json(config_json).py_err()?;
    serde_json::to_string(&config).map_err(|e| raise(Kind::Config, e.to_string()))
}

/// Lowest and highest reward of one agent step under a configuration (JSON).
#[pyfunction]
pub fn reward_bounds(config_json: &str) -> PyResult<(f64, f64)> {
    let config = EnvConfig::from_json(config_json).py_err()?;
    Ok(config.reward.bounds(config.episode_steps()))
}

/// Agent steps of one episode under a configuration (JSON): ``capture_window / agent_step``,
/// rounded.
#[pyfunction]
pub fn episode_steps(config_json: &str) -> PyResult<u64> {
    let config = EnvConfig::from_json(config_json).py_err()?;
    Ok(config.episode_steps())
}

/// The observation table: a list of ``(name, unit, scale, description)``, in index order.
#[pyfunction]
pub fn observation_table() -> Vec<(&'static str, &'static str, f64, &'static str)> {
    OBSERVATION
        .iter()
        .map(|f| (f.name, f.unit, f.scale, f.description))
        .collect()
}

/// Registers the batch env and its constants.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyBatchEnv>()?;
    m.add_function(wrap_pyfunction!(default_env_config_json, m)?)?;
    m.add_function(wrap_pyfunction!(env_config_json, m)?)?;
    m.add_function(wrap_pyfunction!(reward_bounds, m)?)?;
    m.add_function(wrap_pyfunction!(episode_steps, m)?)?;
    m.add_function(wrap_pyfunction!(observation_table, m)?)?;
    m.add("OBS_DIM", OBS_DIM)?;
    m.add("ACT_DIM", ACT_DIM)?;
    m.add("OBS_BOUND", OBS_BOUND)?;
    m.add("MAX_ENVS", MAX_ENVS)?;
    m.add("SEED_END", accd_sim::SEED_END)?;
    m.add("MAX_THREADS", MAX_THREADS)?;
    m.add("INFO_NAMES", info::NAMES.to_vec())?;
    m.add("EVENT_NAMES", info::EVENTS.map(|k| info::NAMES[k]).to_vec())?;
    m.add("PARAMETER_NAMES", accd_sim::Parameters::NAMES.to_vec())?;
    m.add(
        "TRAINING_WAKE_SEEDS",
        (TRAINING_WAKE_SEEDS.start, TRAINING_WAKE_SEEDS.end),
    )?;
    m.add(
        "HELD_OUT_WAKE_SEEDS",
        (HELD_OUT_WAKE_SEEDS.start, HELD_OUT_WAKE_SEEDS.end),
    )?;
    m.add(
        "VALIDATION_WAKE_SEEDS",
        (VALIDATION_WAKE_SEEDS.start, VALIDATION_WAKE_SEEDS.end),
    )?;
    Ok(())
}

/// `values` (`N * OBS_DIM`) as an (N, OBS_DIM) array.
fn rows_to_py(py: Python<'_>, values: Vec<f32>) -> PyResult<Bound<'_, PyArray2<f32>>> {
    let n = values.len() / OBS_DIM;
    PyArray1::from_vec(py, values).reshape([n, OBS_DIM])
}
