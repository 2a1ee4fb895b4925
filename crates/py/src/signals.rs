//! Keeping long native loops interruptible. They run with the GIL released, so Python cannot
//! act on Ctrl+C (SIGINT) or SIGTERM until they return; a [`SignalCheck`] passed to the loop as
//! its interruption check re-acquires the GIL briefly, at most every [`INTERVAL`], to run
//! `PyErr_CheckSignals` (which only acts on the main thread). When a handler raises
//! (`KeyboardInterrupt`, or whatever a handler installed for SIGTERM raises), the loop stops
//! after its current step and the exception is raised from the call.
//!
//! # Platforms
//! The check only asks CPython to run the handlers that its own low-level handler has flagged,
//! so it behaves the same wherever CPython delivers the signal. Linux and macOS deliver SIGINT
//! and SIGTERM as POSIX signals (tested here: `tests/test_reliability.py`). On Windows, Ctrl+C
//! and Ctrl+Break reach the C runtime's console handler on a thread of its own, which flags
//! SIGINT (or SIGBREAK) for the main thread in the same way, so the check raises
//! `KeyboardInterrupt` there too; Windows has no SIGTERM from other processes (ending a process
//! runs no handler). The Windows behaviour is assumed from CPython's documentation of its
//! `signal` module, not tested here.

use std::time::{Duration, Instant};

use pyo3::prelude::*;

/// Longest time between two signal checks (the bound is 0.2 s).
pub const INTERVAL: Duration = Duration::from_millis(50);

/// A loop's interruption check: false until a signal handler raised, true from then on.
pub struct SignalCheck {
    last: Instant,
    raised: Option<PyErr>,
}

impl SignalCheck {
    /// A check whose first poll is one [`INTERVAL`] from now.
    pub fn new() -> SignalCheck {
        SignalCheck {
            last: Instant::now(),
            raised: None,
        }
    }

    /// Whether to stop: runs the Python signal handlers when [`INTERVAL`] has passed since the
    /// last check (with the GIL), and reports whether one raised.
    pub fn interrupted(&mut self) -> bool {
        if self.raised.is_some() {
            return true;
        }
        if self.last.elapsed() < INTERVAL {
            return false;
        }
        if let Err(e) = Python::attach(|py| py.check_signals()) {
            self.raised = Some(e);
            return true;
        }
        self.last = Instant::now();
        false
    }

    /// The exception a signal handler raised, if any.
    pub fn take(&mut self) -> Option<PyErr> {
        self.raised.take()
    }
}
