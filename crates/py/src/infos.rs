//! The per-env info dicts of the SB3 VecEnv and the single gymnasium env, built from a step's
//! info array in one native call: 5.2 us per step of 16 envs, against 23 us for the Python loop
//! over the columns it replaced (about 1 % of PPO's wall time).

use accd_batch::info;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

use crate::errors::{raise, Kind};

/// One dict per row of ``info`` ((n, len(INFO_NAMES)) float64, the step's info array) with
/// ``wake_seed`` ((n,) uint64): the columns by their ``INFO_NAMES`` (the ``EVENT_NAMES`` as bool,
/// ``episode_steps`` as int, the rest as float), then ``wake_seed`` (int). The dicts are new
/// objects; nothing refers to the arrays.
#[pyfunction]
pub fn info_dicts<'py>(
    py: Python<'py>,
    info: PyReadonlyArray2<'py, f64>,
    wake_seed: PyReadonlyArray1<'py, u64>,
) -> PyResult<Bound<'py, PyList>> {
    let rows = info.as_array();
    let seeds = wake_seed.as_array();
    let (n, columns) = rows.dim();
    if columns != info::DIM || seeds.len() != n {
        return Err(raise(
            Kind::State,
            format!(
                "info has shape ({n}, {columns}) and wake_seed ({}), expected ({n}, {}) and ({n},)",
                seeds.len(),
                info::DIM
            ),
        ));
    }
    let keys: Vec<Bound<'py, PyString>> = info::NAMES
        .iter()
        .map(|name| PyString::intern(py, name))
        .collect();
    let wake_key = pyo3::intern!(py, "wake_seed");
    let list = PyList::empty(py);
    for (row, seed) in rows.rows().into_iter().zip(seeds.iter()) {
        let d = PyDict::new(py);
        for (k, (key, &value)) in keys.iter().zip(row.iter()).enumerate() {
            if info::EVENTS.contains(&k) {
                d.set_item(key, value != 0.0)?;
            } else if k == info::EPISODE_STEPS {
                d.set_item(key, value as i64)?;
            } else {
                d.set_item(key, value)?;
            }
        }
        d.set_item(wake_key, *seed)?;
        list.append(d)?;
    }
    Ok(list)
}
