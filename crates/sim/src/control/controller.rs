//! One env's controller: what a batch steps beside each env's episode, in the same thread, so
//! that a controller's command for the next step is ready when the step returns (the LQR
//! baseline and the MPC baseline, each the base of residual control).
//!
//! ```text
//! reset   the env's next observation starts an episode (the estimate starts afresh)
//! sent    the command actually sent since the last act (residual control adds a correction)
//! act     the command for a new observation (advances the estimate)
//! peek    the command for an observation without advancing anything (an ended episode's last)
//! ```
//!
//! A controller owns its env's state and its scratch space: `act` allocates nothing. Its
//! arithmetic is that of the design's per-row step ([`LqrFilter::step`], [`Mpc::step_rows`] on
//! one row), which depends on nothing but the row's own inputs: the same bits whatever the
//! batch, its size, its threads or the thread that steps the row.

use std::fmt::Debug;
use std::sync::Arc;

use crate::control::filter::{FilterState, LqrFilter};
use crate::control::mpc::{Mpc, MpcScratch, MpcStats};
use crate::error::Result;
use crate::state_format::StateError;
use crate::task::observation::{ACT_DIM, OBS_DIM};

/// One env's controller state: the filter's state and the last command `act` returned.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerState {
    /// The Kalman filter's state.
    pub filter: FilterState,
    /// The command of the last `act` (flap-limit units): what `sent` measures a correction
    /// from.
    pub command: [f32; ACT_DIM],
}

/// A per-env controller (see the module docs).
pub trait Controller: Send + Sync + Debug {
    /// The env's next observation starts an episode.
    fn reset(&mut self);

    /// The command actually sent after the last `act` was `sent` (clipped to [-1, 1]): the next
    /// prediction uses it. Adds `sent - command` (in f64) to the filter's command where that
    /// is not zero.
    fn sent(&mut self, sent: &[f32; ACT_DIM]);

    /// The command for the observation `obs`, written to `command`; advances the estimate.
    /// [`crate::SimError::Diverged`] when the command is not finite (never a NaN command).
    fn act(&mut self, obs: &[f32; OBS_DIM], command: &mut [f32; ACT_DIM]) -> Result<()>;

    /// The command `act` would write for `obs`, changing nothing.
    fn peek(&mut self, obs: &[f32; OBS_DIM], command: &mut [f32; ACT_DIM]) -> Result<()>;

    /// The command of the last `act`.
    fn command(&self) -> [f32; ACT_DIM];

    /// The env's state (a copy).
    fn state(&self) -> ControllerState;

    /// Restores a state of [`Controller::state`] (an error naming the field whose size does not
    /// fit this design).
    fn set_state(&mut self, state: &ControllerState) -> Result<()>;

    /// The counts of MPC solves since this controller was made (zero for the LQR).
    fn stats(&self) -> MpcStats {
        MpcStats::default()
    }

    /// A copy, state and all.
    fn boxed_clone(&self) -> Box<dyn Controller>;
}

impl Clone for Box<dyn Controller> {
    fn clone(&self) -> Self {
        self.boxed_clone()
    }
}

/// The f64 observation the filter reads (exact: every f32 is an f64).
fn widen(obs: &[f32; OBS_DIM]) -> [f64; OBS_DIM] {
    obs.map(f64::from)
}

fn add_sent(state: &mut FilterState, last: &[f32; ACT_DIM], sent: &[f32; ACT_DIM]) {
    for ((u, s), l) in state.u.iter_mut().zip(sent).zip(last) {
        let d = f64::from(s.clamp(-1.0, 1.0)) - f64::from(*l);
        if d != 0.0 {
            *u += d;
        }
    }
}

/// Copies the estimate, command and start flag (the scratch is overwritten by every step):
/// no allocation.
fn copy_filter(into: &mut FilterState, from: &FilterState) {
    into.z.copy_from_slice(&from.z);
    into.u = from.u;
    into.fresh = from.fresh;
}

fn restore(into: &mut ControllerState, from: &ControllerState) -> Result<()> {
    if from.filter.z.len() != into.filter.z.len() {
        return Err(StateError::invalid(
            "controller.z",
            format!("{} values", from.filter.z.len()),
            format!(
                "{} values (the design's observer states)",
                into.filter.z.len()
            ),
        )
        .into());
    }
    for (field, mut values) in [
        ("controller.z", from.filter.z.iter()),
        ("controller.u", from.filter.u.iter()),
    ] {
        if values.any(|v| !v.is_finite()) {
            return Err(StateError::invalid(field, "non-finite values", "finite values").into());
        }
    }
    if from.command.iter().any(|v| !(-1.0..=1.0).contains(v)) {
        return Err(StateError::invalid(
            "controller.command",
            "values outside [-1, 1] or non-finite",
            "flap commands in [-1, 1]",
        )
        .into());
    }
    into.filter.z.copy_from_slice(&from.filter.z);
    into.filter.u = from.filter.u;
    into.filter.fresh = from.filter.fresh;
    into.command = from.command;
    Ok(())
}

/// The LQR baseline of one env: its design's filter and control law ([`LqrFilter`]).
#[derive(Debug, Clone)]
pub struct LqrController {
    filter: Arc<LqrFilter>,
    state: ControllerState,
    /// A copy of the filter's state for `peek` (allocated once).
    spare: FilterState,
}

impl LqrController {
    /// A controller of `filter` whose next observation starts an episode.
    pub fn new(filter: Arc<LqrFilter>) -> Self {
        let state = ControllerState {
            filter: filter.new_state(),
            command: [0.0; ACT_DIM],
        };
        let spare = filter.new_state();
        Self {
            filter,
            state,
            spare,
        }
    }
}

impl Controller for LqrController {
    fn reset(&mut self) {
        self.state.filter.fresh = true;
    }

    fn sent(&mut self, sent: &[f32; ACT_DIM]) {
        add_sent(&mut self.state.filter, &self.state.command, sent);
    }

    fn act(&mut self, obs: &[f32; OBS_DIM], command: &mut [f32; ACT_DIM]) -> Result<()> {
        self.filter
            .step(&mut self.state.filter, &widen(obs), command)?;
        self.state.command = *command;
        Ok(())
    }

    fn peek(&mut self, obs: &[f32; OBS_DIM], command: &mut [f32; ACT_DIM]) -> Result<()> {
        copy_filter(&mut self.spare, &self.state.filter);
        self.filter.step(&mut self.spare, &widen(obs), command)
    }

    fn command(&self) -> [f32; ACT_DIM] {
        self.state.command
    }

    fn state(&self) -> ControllerState {
        self.state.clone()
    }

    fn set_state(&mut self, state: &ControllerState) -> Result<()> {
        restore(&mut self.state, state)
    }

    fn boxed_clone(&self) -> Box<dyn Controller> {
        Box::new(self.clone())
    }
}

/// The MPC baseline of one env ([`Mpc`]): the LQR's filter for the estimate, a QP for the
/// command.
#[derive(Debug, Clone)]
pub struct MpcController {
    mpc: Arc<Mpc>,
    state: ControllerState,
    spare: FilterState,
    scratch: MpcScratch,
    stats: MpcStats,
}

impl MpcController {
    /// A controller of `mpc` whose next observation starts an episode.
    pub fn new(mpc: Arc<Mpc>) -> Self {
        let state = ControllerState {
            filter: mpc.filter().new_state(),
            command: [0.0; ACT_DIM],
        };
        let spare = mpc.filter().new_state();
        let scratch = mpc.plan().new_scratch();
        Self {
            mpc,
            state,
            spare,
            scratch,
            stats: MpcStats::default(),
        }
    }

    fn solve(
        mpc: &Mpc,
        state: &mut FilterState,
        obs: &[f32; OBS_DIM],
        command: &mut [f32; ACT_DIM],
        scratch: &mut MpcScratch,
        stats: &mut MpcStats,
    ) -> Result<()> {
        let mut out = [[0.0_f32; ACT_DIM]];
        mpc.step_rows(
            std::slice::from_mut(state),
            &[widen(obs)],
            &[true],
            &mut out,
            scratch,
            stats,
        )?;
        *command = out[0];
        Ok(())
    }
}

impl Controller for MpcController {
    fn reset(&mut self) {
        self.state.filter.fresh = true;
    }

    fn sent(&mut self, sent: &[f32; ACT_DIM]) {
        add_sent(&mut self.state.filter, &self.state.command, sent);
    }

    fn act(&mut self, obs: &[f32; OBS_DIM], command: &mut [f32; ACT_DIM]) -> Result<()> {
        Self::solve(
            &self.mpc,
            &mut self.state.filter,
            obs,
            command,
            &mut self.scratch,
            &mut self.stats,
        )?;
        self.state.command = *command;
        Ok(())
    }

    fn peek(&mut self, obs: &[f32; OBS_DIM], command: &mut [f32; ACT_DIM]) -> Result<()> {
        copy_filter(&mut self.spare, &self.state.filter);
        let mut stats = self.stats;
        Self::solve(
            &self.mpc,
            &mut self.spare,
            obs,
            command,
            &mut self.scratch,
            &mut stats,
        )
    }

    fn command(&self) -> [f32; ACT_DIM] {
        self.state.command
    }

    fn state(&self) -> ControllerState {
        self.state.clone()
    }

    fn set_state(&mut self, state: &ControllerState) -> Result<()> {
        restore(&mut self.state, state)
    }

    fn stats(&self) -> MpcStats {
        self.stats
    }

    fn boxed_clone(&self) -> Box<dyn Controller> {
        Box::new(self.clone())
    }
}
