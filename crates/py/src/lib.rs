//! `accd_gym._core`: the Python bindings of accd-gym. Glue only; the physics lives in the
//! pure-Rust crates.
//!
//! # Threading model
//! Every object is `Send + Sync` and guarded by PyO3's borrow checking: a method that steps
//! (`Tether.step`, `Tether.advance`) takes the object mutably and releases the GIL while the Rust
//! code runs, so other Python threads proceed, but a second call on the *same* object from another
//! thread during that time raises `RuntimeError: Already borrowed`. Different objects step in
//! parallel freely. `BatchEnv` steps its envs on a thread pool of its own (rayon) and, in its
//! step, on the calling thread too (`accd_batch`'s `shared` module).
//!
//! # Signals
//! Loops that may run long with the GIL released (`Tether.step`/`advance`,
//! `CaptureSim.step`/`settle`, building a `BatchEnv`) check Python's signal handlers every
//! 50 ms ([`signals`]) and raise what they raise (`KeyboardInterrupt` on Ctrl+C) after the
//! current whole step, the object keeping that step's state.
//!
//! # Panics
//! A panic is a bug. None is caught and re-labelled: `BatchEnv` reports one from its worker
//! threads as `RuntimeError` ("internal error") and refuses further use.

mod arrays;
mod batch;
mod capture;
mod config;
mod errors;
mod infos;
mod linearize;
mod lqr;
mod mpc;
mod signals;
mod tether;

use pyo3::prelude::*;

/// Native core of accd-gym (Rust). Use the `accd_gym` package rather than this module directly.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<tether::PyTether>()?;
    m.add_class::<capture::PyCaptureSim>()?;
    m.add_class::<config::PyEnvConfig>()?;
    m.add_function(wrap_pyfunction!(config::validation_passes, m)?)?;
    m.add_function(wrap_pyfunction!(config::config_fields, m)?)?;
    batch::register(m)?;
    m.add_function(wrap_pyfunction!(infos::info_dicts, m)?)?;
    m.add_class::<linearize::PyLinearization>()?;
    m.add_function(wrap_pyfunction!(linearize::linearize, m)?)?;
    m.add_class::<lqr::PyLqrDesign>()?;
    m.add_class::<lqr::PyLqrFilter>()?;
    m.add_function(wrap_pyfunction!(lqr::lqr_design, m)?)?;
    m.add_class::<mpc::PyMpc>()?;
    m.add_function(wrap_pyfunction!(capture::mix_flaps, m)?)?;
    m.add_function(wrap_pyfunction!(capture::default_aero_table_json, m)?)?;
    m.add_function(wrap_pyfunction!(tether::tether_config, m)?)?;
    m.add_function(wrap_pyfunction!(tether::isa, m)?)?;
    m.add_function(wrap_pyfunction!(tether::arithmetic, m)?)?;
    m.add_function(wrap_pyfunction!(tether::stand_in_body, m)?)?;
    m.add_function(wrap_pyfunction!(tether::towed_tether, m)?)?;
    Ok(())
}
