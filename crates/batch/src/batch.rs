//! N episodes stepped by one call, in parallel over threads, with autoreset.
//!
//! Each env is an [`Episode`] with its own seeds ([`crate::seeds`]); envs never share state, so
//! an env's results depend only on the config, its base seed, its index and its actions: they are
//! bitwise identical whatever the batch size and thread count. Outputs go straight into the
//! caller's struct-of-arrays buffers ([`StepBuffers`]); nothing is allocated per step.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use accd_sim::control::controller::{Controller, ControllerState};
use accd_sim::control::mpc::MpcStats;
use accd_sim::state_format::{self, Expected, StateError, StateKind};
use accd_sim::task::episode::EpisodeState;
use accd_sim::{EnvConfig, Episode, Equilibrium, Outcome, SimError, Valid, ACT_DIM, OBS_DIM};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{BatchError, Result};
use crate::seeds::{episode_seeds, WakeSchedule};
use crate::shared::{run_shared, Queue, Rows};

/// Columns of the per-env info array ([`StepBuffers::info`]), all f64.
pub mod info {
    /// Episode time at the end of the step, s.
    pub const TIME: usize = 0;
    /// Distance from the capture point to the boom tip, m.
    pub const DISTANCE: usize = 1;
    /// Relative speed of the capture point with respect to the boom tip, m/s.
    pub const RELATIVE_SPEED: usize = 2;
    /// Highest attachment tension during the step, N.
    pub const PEAK_TENSION: usize = 3;
    /// 1 if captured.
    pub const CAPTURED: usize = 4;
    /// 1 if the tether was overloaded.
    pub const OVERLOAD: usize = 5;
    /// 1 if the ACCD left the flight envelope.
    pub const ENVELOPE_EXIT: usize = 6;
    /// 1 if the simulation diverged.
    pub const DIVERGED: usize = 7;
    /// Agent steps taken in the episode.
    pub const EPISODE_STEPS: usize = 8;
    /// Number of columns.
    pub const DIM: usize = 9;
    /// The event flags, the reasons an episode ends, in their order of precedence.
    pub const EVENTS: [usize; 4] = [CAPTURED, OVERLOAD, ENVELOPE_EXIT, DIVERGED];
    /// Column names, in order.
    pub const NAMES: [&str; DIM] = [
        "time",
        "distance",
        "relative_speed",
        "peak_tension",
        "captured",
        "overload",
        "envelope_exit",
        "diverged",
        "episode_steps",
    ];
}

/// When an ended episode is replaced by a new one (gymnasium's autoreset modes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Autoreset {
    /// In the step that ends it: the returned observation is the new episode's first, the
    /// ended episode's last goes to `final_obs` (stable-baselines3; gymnasium `SAME_STEP`).
    SameStep,
    /// In the next step, whose action is ignored for that env: it returns the new episode's
    /// first observation, reward 0, not done, `autoreset` set (gymnasium `NEXT_STEP`).
    NextStep,
    /// Never: an ended env must be reset (`reset` with a mask) before it is stepped again; a
    /// step of a batch with an ended env is refused (gymnasium `DISABLED`).
    Disabled,
}

/// Output buffers of one batch step, `N` envs (row-major, env by env).
pub struct StepBuffers<'a> {
    /// `N * OBS_DIM` observations.
    pub obs: &'a mut [f32],
    /// `N` rewards.
    pub reward: &'a mut [f64],
    /// `N` terminated flags.
    pub terminated: &'a mut [bool],
    /// `N` truncated flags.
    pub truncated: &'a mut [bool],
    /// `N * OBS_DIM`: an ended episode's last observation (same-step autoreset; rows of envs that
    /// did not end are left as they were).
    pub final_obs: &'a mut [f32],
    /// `N * info::DIM` info values of the step (of the ended episode where one ended).
    pub info: &'a mut [f64],
    /// `N` wake seeds of the episode each step belongs to.
    pub wake_seed: &'a mut [u64],
    /// `N` flags: this env was reset in this step (next-step autoreset).
    pub autoreset: &'a mut [bool],
}

/// Owned output buffers for `N` envs (for Rust callers; the Python bindings lend numpy arrays
/// instead). [`StepOutputs::buffers`] lends them to [`BatchEnv::step`].
#[derive(Debug, Clone, PartialEq)]
pub struct StepOutputs {
    /// `N * OBS_DIM` observations.
    pub obs: Vec<f32>,
    /// `N * OBS_DIM` last observations of ended episodes.
    pub final_obs: Vec<f32>,
    /// `N` rewards.
    pub reward: Vec<f64>,
    /// `N` terminated flags.
    pub terminated: Vec<bool>,
    /// `N` truncated flags.
    pub truncated: Vec<bool>,
    /// `N * info::DIM` info values.
    pub info: Vec<f64>,
    /// `N` wake seeds.
    pub wake_seed: Vec<u64>,
    /// `N` next-step autoreset flags.
    pub autoreset: Vec<bool>,
}

impl StepOutputs {
    /// Zeroed buffers for `n` envs.
    pub fn new(n: usize) -> StepOutputs {
        StepOutputs {
            obs: vec![0.0; n * OBS_DIM],
            final_obs: vec![0.0; n * OBS_DIM],
            reward: vec![0.0; n],
            terminated: vec![false; n],
            truncated: vec![false; n],
            info: vec![0.0; n * info::DIM],
            wake_seed: vec![0; n],
            autoreset: vec![false; n],
        }
    }

    /// The buffers, lent for one step.
    pub fn buffers(&mut self) -> StepBuffers<'_> {
        StepBuffers {
            obs: &mut self.obs,
            reward: &mut self.reward,
            terminated: &mut self.terminated,
            truncated: &mut self.truncated,
            final_obs: &mut self.final_obs,
            info: &mut self.info,
            wake_seed: &mut self.wake_seed,
            autoreset: &mut self.autoreset,
        }
    }
}

/// Output buffers of a reset.
pub struct ResetBuffers<'a> {
    /// `N * OBS_DIM` observations: the new episodes' first, and for envs a partial reset left
    /// alone their current one.
    pub obs: &'a mut [f32],
    /// `N` wake seeds of the envs' (new or current) episodes.
    pub wake_seed: &'a mut [u64],
}

/// Most envs in one batch.
pub const MAX_ENVS: usize = 65_536;
/// Most threads of a batch's pool.
pub const MAX_THREADS: usize = 1024;

/// How `reset` seeds the envs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SeedSpec {
    /// Keep each env's base seed and start its next episode.
    Next,
    /// Env `i` gets base seed `s + i`, as gymnasium's `SyncVectorEnv` and SB3's `DummyVecEnv`
    /// seed their sub-envs; episode counters restart at 0. `s + N - 1` must lie in the seed
    /// range [0, 2^63) ([`check_base_seed`]): a seed never wraps.
    Base(u64),
    /// Env `i` gets base seed `s_i` in [0, 2^63) (so it replays a single env seeded `s_i`);
    /// episode counters restart at 0.
    PerEnv(Vec<u64>),
}

#[derive(Clone)]
struct Slot {
    episode: Episode,
    base: u64,
    /// Index of the current episode under `base`.
    index: u64,
    /// The episode ended in the last step: next-step autoreset resets it at the next step,
    /// disabled autoreset waits for `reset`.
    pending_reset: bool,
    /// Why the episode that ended in the last step diverged, kept past a same-step autoreset
    /// (which starts the next episode at once); not part of the saved state.
    final_divergence: Option<String>,
    /// The true observation of the episode that ended in the last step (same-step autoreset,
    /// with true observations kept: [`BatchEnv::set_true_observation`]); not saved.
    final_true_obs: [f32; OBS_DIM],
    /// A step of the batch was interrupted while this env's episode may have been part-way
    /// through it: the env refuses steps and saves until it is reset or restored.
    interrupted: bool,
    /// The env's controller, where the batch has one ([`BatchEnv::set_controllers`]).
    control: Option<Control>,
}

/// One env's controller and what it returned beyond its command.
#[derive(Clone, Debug)]
struct Control {
    controller: Box<dyn Controller>,
    /// The command for the last observation of the episode that ended in the last step
    /// (same-step autoreset; [`Controller::peek`]).
    final_command: [f32; ACT_DIM],
    /// Why the controller failed in the last step or reset (its command was not finite).
    error: Option<SimError>,
}

impl Control {
    /// The controller's command for `obs` (an episode's first observation where `start`).
    fn act(&mut self, obs: &[f32], start: bool) {
        let obs: &[f32; OBS_DIM] = obs.try_into().expect("an observation row");
        if start {
            self.controller.reset();
        }
        let mut command = [0.0; ACT_DIM];
        if let Err(e) = self.controller.act(obs, &mut command) {
            self.error = Some(e);
        }
    }

    /// The command for an ended episode's last observation `obs`, advancing nothing.
    fn peek(&mut self, obs: &[f32]) {
        let obs: &[f32; OBS_DIM] = obs.try_into().expect("an observation row");
        if let Err(e) = self.controller.peek(obs, &mut self.final_command) {
            self.error = Some(e);
        }
    }
}

/// Checks that base seed `seed` gives each of `num_envs` envs a seed `seed + i` inside the one
/// seed range [0, 2^63) ([`accd_sim::SEED_END`]): nothing wraps, in the core or in the
/// infos' int64 columns (a wrapped seed would silently repeat another env's episodes).
pub fn check_base_seed(seed: u64, num_envs: usize) -> Result<()> {
    let last = (num_envs.max(1) - 1) as u64;
    if seed >= accd_sim::SEED_END - last {
        return Err(SimError::invalid_config(
            "seed",
            seed,
            &format!(
                "[0, 2^63 - num_envs] = [0, {}] for num_envs = {num_envs} (env i is seeded seed + i, \
                 every seed in {})",
                accd_sim::SEED_END - 1 - last,
                accd_sim::SEED_RANGE
            ),
        )
        .into());
    }
    Ok(())
}

/// Checks one env's base seed `seed` (an entry of a per-env seed list): in [0, 2^63)
/// ([`accd_sim::SEED_END`]).
pub fn check_env_seed(seed: u64) -> Result<()> {
    if seed >= accd_sim::SEED_END {
        return Err(SimError::invalid_config("seed", seed, accd_sim::SEED_RANGE).into());
    }
    Ok(())
}

/// N episodes of one config.
pub struct BatchEnv {
    config: Arc<Valid<EnvConfig>>,
    equilibrium: Arc<Equilibrium>,
    slots: Vec<Slot>,
    schedule: WakeSchedule,
    autoreset: Autoreset,
    pool: rayon::ThreadPool,
    threads: usize,
    /// The time one env's step took in the last completed watched step (wall time x threads /
    /// envs; `None` before the first). The calling thread takes envs itself only while this is
    /// under [`SHARE_BELOW`], so that it still asks its interruption check that often.
    env_step_time: Option<Duration>,
    /// Set when a step or reset panicked (a bug): the envs may be half-stepped, so every later
    /// call fails with [`BatchError::Internal`].
    poisoned: Option<String>,
}

impl BatchEnv {
    /// `num_envs` envs of `config`, env `i` seeded with base `seed + i`, stepped on
    /// `threads` threads of its own pool (0: one per core).
    pub fn new(
        config: Valid<EnvConfig>,
        num_envs: usize,
        seed: u64,
        autoreset: Autoreset,
        threads: usize,
    ) -> Result<BatchEnv> {
        BatchEnv::new_interruptible(config, num_envs, seed, autoreset, threads, &mut || false)
    }

    /// [`BatchEnv::new`], asking `interrupted()` after every physics step of the settling and
    /// after every env built, and stopping with [`SimError::Interrupted`] when it returns true.
    /// The envs' estimated memory ([`EnvConfig::bytes_per_env`]) must fit the budget of
    /// [`crate::memory::budget_bytes`].
    pub fn new_interruptible(
        config: Valid<EnvConfig>,
        num_envs: usize,
        seed: u64,
        autoreset: Autoreset,
        threads: usize,
        interrupted: &mut dyn FnMut() -> bool,
    ) -> Result<BatchEnv> {
        if !(1..=MAX_ENVS).contains(&num_envs) {
            return Err(SimError::invalid_config(
                "num_envs",
                num_envs,
                &format!("[1, {MAX_ENVS}]"),
            )
            .into());
        }
        if threads > MAX_THREADS {
            return Err(SimError::invalid_config(
                "num_threads",
                threads,
                &format!("[0, {MAX_THREADS}]"),
            )
            .into());
        }
        check_base_seed(seed, num_envs)?;
        crate::memory::check_budget(&config, num_envs)?;
        let config = Arc::new(config);
        let equilibrium = Arc::new(Equilibrium::settle_interruptible(&config, interrupted)?);
        let schedule = WakeSchedule::from_config(&config);
        let n = num_envs as u64;
        let first = Episode::new(
            Arc::clone(&config),
            Arc::clone(&equilibrium),
            episode_seeds(seed, 0, 0, n, &schedule),
        )?;
        let mut slots = Vec::with_capacity(num_envs);
        for i in 0..n {
            let mut episode = first.clone();
            let base = seed + i;
            episode.reset(episode_seeds(base, 0, i, n, &schedule))?;
            if interrupted() {
                return Err(SimError::Interrupted {
                    time: 0.0,
                    what: format!("building env {i} of {num_envs}"),
                }
                .into());
            }
            slots.push(Slot {
                episode,
                base,
                index: 0,
                pending_reset: false,
                final_divergence: None,
                final_true_obs: [0.0; OBS_DIM],
                interrupted: false,
                control: None,
            });
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| BatchError::Threads(e.to_string()))?;
        let threads = pool.current_num_threads();
        Ok(BatchEnv {
            config,
            equilibrium,
            slots,
            schedule,
            autoreset,
            pool,
            threads,
            env_step_time: None,
            poisoned: None,
        })
    }

    /// Number of envs.
    pub fn num_envs(&self) -> usize {
        self.slots.len()
    }

    /// Threads stepping the envs.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// The configuration.
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// The open-loop equilibrium the episodes start around.
    pub fn equilibrium(&self) -> &Equilibrium {
        &self.equilibrium
    }

    /// The autoreset mode.
    pub fn autoreset(&self) -> Autoreset {
        self.autoreset
    }

    /// The wake-seed schedule of new episodes.
    pub fn wake_schedule(&self) -> &WakeSchedule {
        &self.schedule
    }

    /// Sets the wake-seed schedule of the episodes started from now on (resets and autoresets).
    pub fn set_wake_schedule(&mut self, schedule: WakeSchedule) -> Result<()> {
        let range = accd_sim::SEED_RANGE;
        match &schedule {
            WakeSchedule::List(list) if list.is_empty() => {
                return Err(
                    SimError::invalid_config("wake_seeds", "[]", "a non-empty list").into(),
                );
            }
            WakeSchedule::List(list) => {
                if let Some(s) = list.iter().find(|s| **s >= accd_sim::SEED_END) {
                    return Err(SimError::invalid_config("wake_seeds", s, range).into());
                }
            }
            WakeSchedule::Fixed(s) if *s >= accd_sim::SEED_END => {
                return Err(SimError::invalid_config("wake_seed", s, range).into());
            }
            _ => {}
        }
        self.schedule = schedule;
        Ok(())
    }

    /// Env `i`'s episode.
    pub fn episode(&self, i: usize) -> Result<&Episode> {
        self.check_index(i)?;
        Ok(&self.slots[i].episode)
    }

    /// Env `i`'s episode, mutably (for snapshots of its physics).
    pub fn episode_mut(&mut self, i: usize) -> Result<&mut Episode> {
        self.check_index(i)?;
        Ok(&mut self.slots[i].episode)
    }

    /// Keeps (`on`) or drops every env's true observation ([`Episode::set_true_observation`]):
    /// noise-free and delay-free, scaled like the observation. Off, nothing of it is computed.
    pub fn set_true_observation(&mut self, on: bool) {
        for slot in &mut self.slots {
            slot.episode.set_true_observation(on);
        }
    }

    /// Writes every env's true observation of its latest state into `out` (`N * OBS_DIM`).
    pub fn true_observations(&self, out: &mut [f32]) -> Result<()> {
        self.write_true(out, |slot| slot.episode.true_observation().copied())
    }

    /// Writes every env's true observation of the episode that ended in the last step into
    /// `out` (`N * OBS_DIM`; same-step autoreset, rows of envs whose episode ended in the last
    /// step, the others' rows hold stale values).
    pub fn final_true_observations(&self, out: &mut [f32]) -> Result<()> {
        self.write_true(out, |slot| {
            slot.episode.true_observation().map(|_| slot.final_true_obs)
        })
    }

    fn write_true(
        &self,
        out: &mut [f32],
        row: impl Fn(&Slot) -> Option<[f32; OBS_DIM]>,
    ) -> Result<()> {
        check_len("true_obs", out.len(), self.slots.len() * OBS_DIM)?;
        for (slot, chunk) in self.slots.iter().zip(out.chunks_exact_mut(OBS_DIM)) {
            let values = row(slot).ok_or(BatchError::TrueObservationOff)?;
            chunk.copy_from_slice(&values);
        }
        Ok(())
    }

    /// Gives every env a controller made by `make` (or none, for `None`), stepped from now on in
    /// the thread that steps its env ([`accd_sim::control::controller`]): after each env's step
    /// and reset it computes its command for the new observation (restarted with each new
    /// episode, automatic resets included), and before each step it is told the action sent.
    /// The controllers start afresh (command zero until the env's next reset or step).
    pub fn set_controllers(&mut self, make: Option<&dyn Fn() -> Box<dyn Controller>>) {
        for slot in &mut self.slots {
            slot.control = make.map(|m| Control {
                controller: m(),
                final_command: [0.0; ACT_DIM],
                error: None,
            });
        }
    }

    /// Whether the envs have controllers ([`BatchEnv::set_controllers`]).
    pub fn has_controllers(&self) -> bool {
        self.slots.iter().all(|s| s.control.is_some()) && !self.slots.is_empty()
    }

    fn controls(&self) -> Result<impl Iterator<Item = &Control>> {
        if !self.has_controllers() {
            return Err(BatchError::NoController);
        }
        Ok(self.slots.iter().filter_map(|s| s.control.as_ref()))
    }

    /// Writes every env's controller command for its latest observation into `out`
    /// (`N * ACT_DIM`).
    pub fn controller_commands(&self, out: &mut [f32]) -> Result<()> {
        check_len("commands", out.len(), self.slots.len() * ACT_DIM)?;
        for (c, chunk) in self.controls()?.zip(out.chunks_exact_mut(ACT_DIM)) {
            chunk.copy_from_slice(&c.controller.command());
        }
        Ok(())
    }

    /// Writes every env's controller command for the last observation of the episode that
    /// ended in the last step into `out` (`N * ACT_DIM`; same-step autoreset, rows of envs
    /// whose episode ended in the last step, the others' rows hold stale values).
    pub fn final_controller_commands(&self, out: &mut [f32]) -> Result<()> {
        check_len("commands", out.len(), self.slots.len() * ACT_DIM)?;
        for (c, chunk) in self.controls()?.zip(out.chunks_exact_mut(ACT_DIM)) {
            chunk.copy_from_slice(&c.final_command);
        }
        Ok(())
    }

    /// Every env's controller state.
    pub fn controller_states(&self) -> Result<Vec<ControllerState>> {
        Ok(self.controls()?.map(|c| c.controller.state()).collect())
    }

    /// Restores every env's controller state (one per env); on an error (a state that does
    /// not fit, named by its env) nothing changes.
    pub fn set_controller_states(&mut self, states: &[ControllerState]) -> Result<()> {
        check_len("controller states", states.len(), self.slots.len())?;
        let mut controllers: Vec<Box<dyn Controller>> =
            self.controls()?.map(|c| c.controller.clone()).collect();
        for (env, (c, s)) in controllers.iter_mut().zip(states).enumerate() {
            c.set_state(s).map_err(|e| BatchError::Env {
                env,
                source: Box::new(e.into()),
            })?;
        }
        for (slot, c) in self.slots.iter_mut().zip(controllers) {
            let control = slot.control.as_mut().expect("checked by controls()");
            control.controller = c;
            control.error = None;
        }
        Ok(())
    }

    /// The MPC solve counts of every env's controller, summed (zero for the LQR).
    pub fn controller_stats(&self) -> Result<MpcStats> {
        let mut total = MpcStats::default();
        for c in self.controls()? {
            let s = c.controller.stats();
            total.steps += s.steps;
            total.constrained += s.constrained;
            total.inexact += s.inexact;
            total.fallbacks += s.fallbacks;
        }
        Ok(total)
    }

    /// Why env `i`'s episode that ended in the last step (same-step autoreset) diverged, or
    /// `None` if it did not; for the other modes see [`Episode::divergence`].
    pub fn final_divergence(&self, i: usize) -> Result<Option<&str>> {
        self.check_index(i)?;
        Ok(self.slots[i].final_divergence.as_deref())
    }

    fn check_index(&self, i: usize) -> Result<()> {
        if i >= self.slots.len() {
            return Err(SimError::invalid_config(
                "env index",
                i,
                &format!("[0, {})", self.slots.len()),
            )
            .into());
        }
        Ok(())
    }

    /// Starts new episodes in the envs `mask` selects (every env for `None`; gymnasium's
    /// `reset_mask`), seeded as `seeds` says (entries of unselected envs are ignored), and writes
    /// every env's observation and wake seed: the new episodes' and, for the envs left alone,
    /// their current ones. A selected env's pending autoreset is cancelled.
    pub fn reset(
        &mut self,
        seeds: SeedSpec,
        mask: Option<&[bool]>,
        out: ResetBuffers<'_>,
    ) -> Result<()> {
        self.check_poisoned()?;
        let n = self.slots.len();
        check_len("obs", out.obs.len(), n * OBS_DIM)?;
        check_len("wake_seed", out.wake_seed.len(), n)?;
        match &seeds {
            SeedSpec::PerEnv(list) => {
                check_len("seed", list.len(), n)?;
                list.iter().try_for_each(|s| check_env_seed(*s))?;
            }
            SeedSpec::Base(s) => check_base_seed(*s, n)?,
            SeedSpec::Next => {}
        }
        if let Some(m) = mask {
            check_len("reset_mask", m.len(), n)?;
        }
        let selected = |i: usize| mask.is_none_or(|m| m[i]);
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if !selected(i) {
                continue;
            }
            match &seeds {
                SeedSpec::Next => slot.index += 1,
                SeedSpec::Base(s) => {
                    slot.base = s + i as u64;
                    slot.index = 0;
                }
                SeedSpec::PerEnv(list) => {
                    slot.base = list[i];
                    slot.index = 0;
                }
            }
            slot.pending_reset = false;
            slot.interrupted = false;
        }
        let schedule = &self.schedule;
        let results: Vec<Result<()>> = {
            let mut results = vec![Ok(()); n];
            let job = |(i, (slot, r)): (usize, (&mut Slot, &mut Result<()>))| {
                if selected(i) {
                    let s = episode_seeds(slot.base, slot.index, i as u64, n as u64, schedule);
                    *r = slot.episode.reset(s).map_err(BatchError::from);
                    if let (Ok(()), Some(c)) = (&*r, slot.control.as_mut()) {
                        c.act(slot.episode.observation(), true);
                        if let Some(e) = c.error.take() {
                            *r = Err(e.into());
                        }
                    }
                }
            };
            let slots = &mut self.slots;
            let pool = &self.pool;
            run(&mut self.poisoned, || {
                pool.install(|| {
                    slots
                        .par_iter_mut()
                        .zip(results.par_iter_mut())
                        .enumerate()
                        .for_each(job)
                })
            })?;
            results
        };
        for (i, r) in results.into_iter().enumerate() {
            r.map_err(|e| BatchError::Env {
                env: i,
                source: Box::new(e),
            })?;
        }
        for (i, slot) in self.slots.iter().enumerate() {
            out.obs[i * OBS_DIM..(i + 1) * OBS_DIM].copy_from_slice(slot.episode.observation());
            out.wake_seed[i] = slot.episode.seeds().wake;
        }
        Ok(())
    }

    /// One agent step of every env with `actions` (`N * ACT_DIM` flap commands in [-1, 1],
    /// clipped). A non-finite action is an error naming the env; no env is stepped then.
    pub fn step(&mut self, actions: &[f32], out: StepBuffers<'_>) -> Result<()> {
        self.step_watched(actions, out, None)
    }

    /// [`BatchEnv::step`] that stays interruptible however long the step takes, asking
    /// `interrupted()` from the calling thread (so Python can run its signal handlers there) at
    /// most about [`WATCH_INTERVAL`] apart. While one env's step takes under [`SHARE_BELOW`]
    /// (every usual config) the calling thread steps envs itself beside the pool's threads and asks between
    /// its envs (`crate::shared`: no thread wakes up for nothing, the step's latency drops);
    /// otherwise (and on the first step) it only waits and asks. Once `interrupted()` returns
    /// true the envs stop before their next physics step and the call fails with
    /// [`SimError::Interrupted`]; the envs may then be part-way through the step, so each
    /// refuses to step or be saved ([`BatchError::Interrupted`]) until a reset or `set_state`.
    /// Results are bitwise those of [`BatchEnv::step`] whichever thread steps which env. Unlike
    /// it, this allocates (a small job box per helper thread a call).
    pub fn step_interruptible(
        &mut self,
        actions: &[f32],
        out: StepBuffers<'_>,
        interrupted: &mut dyn FnMut() -> bool,
    ) -> Result<()> {
        self.step_watched(actions, out, Some(interrupted))
    }

    /// Fails with [`BatchError::Interrupted`] naming the first env left part-way through an
    /// interrupted step.
    pub fn check_consistent(&self) -> Result<()> {
        match self.slots.iter().position(|s| s.interrupted) {
            Some(env) => Err(BatchError::Interrupted { env }),
            None => Ok(()),
        }
    }

    /// [`BatchEnv::step`] (`watch` None) or [`BatchEnv::step_interruptible`].
    fn step_watched(
        &mut self,
        actions: &[f32],
        out: StepBuffers<'_>,
        watch: Option<&mut dyn FnMut() -> bool>,
    ) -> Result<()> {
        self.check_step(actions, &out)?;
        let n = self.slots.len();
        let stop = AtomicBool::new(false);
        let stepper = RowStepper {
            mode: self.autoreset,
            schedule: &self.schedule,
            n: n as u64,
            stop: &stop,
        };
        let queue = Queue::new(StepRows::new(&mut self.slots, actions, out));
        let take_one = || match queue.pop() {
            Some(row) => {
                stepper.step(row);
                true
            }
            None => false,
        };
        match watch {
            None => {
                // Rayon's parallel iterator over the rows (no allocation).
                let pool = &self.pool;
                run(&mut self.poisoned, || {
                    pool.install(|| (0..n).into_par_iter().for_each(|_| _ = take_one()))
                })?;
            }
            Some(interrupted) => {
                let threads = self.threads;
                let share = self.env_step_time.is_some_and(|t| t < SHARE_BELOW);
                let start = Instant::now();
                run(&mut self.poisoned, || {
                    share_rows(&self.pool, threads, n, share, &take_one, &stop, interrupted)
                })?;
                if !stop.load(Ordering::Relaxed) {
                    self.env_step_time = Some(start.elapsed() * threads as u32 / n as u32);
                }
            }
        }
        if stop.load(Ordering::Relaxed) {
            return Err(self.interrupted_step());
        }
        self.controller_error()
    }

    /// The first env whose controller failed in the last step or reset, as an error naming it.
    fn controller_error(&mut self) -> Result<()> {
        for (env, slot) in self.slots.iter_mut().enumerate() {
            if let Some(e) = slot.control.as_mut().and_then(|c| c.error.take()) {
                return Err(BatchError::Env {
                    env,
                    source: Box::new(e.into()),
                });
            }
        }
        Ok(())
    }

    /// What a step refuses before any env steps: a poisoned or interrupted batch, buffers of the
    /// wrong sizes, a non-finite action, an ended env under disabled autoreset.
    fn check_step(&self, actions: &[f32], out: &StepBuffers<'_>) -> Result<()> {
        self.check_poisoned()?;
        self.check_consistent()?;
        let n = self.slots.len();
        check_len("actions", actions.len(), n * ACT_DIM)?;
        check_len("obs", out.obs.len(), n * OBS_DIM)?;
        check_len("final_obs", out.final_obs.len(), n * OBS_DIM)?;
        check_len("reward", out.reward.len(), n)?;
        check_len("terminated", out.terminated.len(), n)?;
        check_len("truncated", out.truncated.len(), n)?;
        check_len("info", out.info.len(), n * info::DIM)?;
        check_len("wake_seed", out.wake_seed.len(), n)?;
        check_len("autoreset", out.autoreset.len(), n)?;
        if let Some(k) = actions.iter().position(|v| !v.is_finite()) {
            return Err(BatchError::Action {
                env: k / ACT_DIM,
                component: k % ACT_DIM,
                value: actions[k],
            });
        }
        if self.autoreset == Autoreset::Disabled {
            if let Some(env) = self.slots.iter().position(|s| s.pending_reset) {
                return Err(BatchError::ResetNeeded { env });
            }
        }
        Ok(())
    }

    /// After an interrupted step: every env may be part-way through it, so each is marked to
    /// refuse steps and saves until a reset or restore; the error of the step.
    fn interrupted_step(&mut self) -> BatchError {
        for slot in &mut self.slots {
            slot.interrupted = true;
        }
        let time = self.slots.first().map_or(0.0, |s| s.episode.sim().time());
        SimError::Interrupted {
            time,
            what: format!("a step of {} envs", self.slots.len()),
        }
        .into()
    }

    /// Fails with [`BatchError::Internal`] once a step or reset has panicked.
    fn check_poisoned(&self) -> Result<()> {
        match &self.poisoned {
            Some(message) => Err(BatchError::Internal(message.clone())),
            None => Ok(()),
        }
    }

    /// Every env's dynamic state (episodes, seeds, counters, random streams) and the wake
    /// schedule; the config is not included.
    pub fn state(&self) -> BatchState {
        BatchState {
            schedule: self.schedule.clone(),
            envs: self
                .slots
                .iter()
                .map(|slot| SlotState {
                    base: slot.base,
                    index: slot.index,
                    pending_reset: slot.pending_reset,
                    episode: slot.episode.state(),
                })
                .collect(),
        }
    }

    /// Restores a state from [`BatchEnv::state`] of a batch with the same config and size:
    /// every env then continues exactly as the saved one would. Restored into copies first:
    /// on an error (another number of envs, a malformed episode) the batch is as it was.
    pub fn set_state(&mut self, state: BatchState) -> Result<()> {
        if state.envs.len() != self.slots.len() {
            return Err(SimError::from(StateError::NumEnvs {
                expected: self.slots.len() as u64,
                found: state.envs.len() as u64,
            })
            .into());
        }
        if let WakeSchedule::List(list) = &state.schedule {
            if list.is_empty() {
                return Err(SimError::from(StateError::invalid(
                    "schedule",
                    "an empty wake seed list",
                    "a list of at least one wake seed",
                ))
                .into());
            }
        }
        let mut slots = self.slots.clone();
        for (env, (slot, saved)) in slots.iter_mut().zip(state.envs).enumerate() {
            slot.base = saved.base;
            slot.index = saved.index;
            slot.pending_reset = saved.pending_reset;
            slot.final_divergence = None;
            slot.interrupted = false;
            slot.episode
                .set_state(saved.episode)
                .map_err(|e| in_env(env, e))?;
        }
        self.slots = slots;
        self.schedule = state.schedule;
        Ok(())
    }

    /// The hash of the config that pins a state to it ([`state_format::config_hash`]).
    pub fn config_hash(&self) -> Result<[u8; 32]> {
        Ok(state_format::config_hash(&*self.config).map_err(SimError::from)?)
    }

    /// What a state of this batch saved as `kind` must be.
    pub fn expected_state(&self, kind: StateKind) -> Result<Expected> {
        Ok(Expected {
            kind,
            config_hash: self.config_hash()?,
            num_envs: self.slots.len() as u64,
        })
    }

    /// [`BatchEnv::state`] behind a header ([`state_format`], kind [`StateKind::Batch`]).
    pub fn save(&self) -> Result<Vec<u8>> {
        self.check_consistent()?;
        let hash = self.config_hash()?;
        let n = self.slots.len() as u64;
        Ok(
            state_format::encode(StateKind::Batch, &hash, n, &self.state())
                .map_err(SimError::from)?,
        )
    }

    /// Restores a state from [`BatchEnv::save`]: a corrupted, truncated or foreign blob
    /// (another kind, config or number of envs) is an error naming what is wrong
    /// ([`SimError::State`]) and changes nothing.
    pub fn load(&mut self, bytes: &[u8]) -> Result<()> {
        let expected = self.expected_state(StateKind::Batch)?;
        let state = state_format::decode(bytes, &expected).map_err(SimError::from)?;
        self.set_state(state)
    }
}

/// An error restoring env `env`'s episode, as a state error naming the env.
fn in_env(env: usize, error: SimError) -> BatchError {
    let error = match error {
        SimError::State(StateError::Invalid {
            field,
            value,
            allowed,
        }) => StateError::Invalid {
            field: format!("envs[{env}].{field}"),
            value,
            allowed,
        },
        other => StateError::invalid(
            &format!("envs[{env}]"),
            other,
            "a state the env can continue from",
        ),
    };
    SimError::State(error).into()
}

/// The saved state of a [`BatchEnv`] ([`BatchEnv::state`]): part of the state format
/// ([`state_format`]; a change here is a change of [`state_format::FORMAT_VERSION`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchState {
    /// Where the wake seeds come from.
    pub schedule: WakeSchedule,
    /// Every env, in order.
    pub envs: Vec<SlotState>,
}

/// One env of a [`BatchState`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlotState {
    /// The env's base seed.
    pub base: u64,
    /// Index of its current episode under `base`.
    pub index: u64,
    /// Its episode ended in the last step and awaits a reset.
    pub pending_reset: bool,
    /// The episode.
    pub episode: EpisodeState,
}

/// One env's share of a step: its slot, action and output rows.
struct Row<'a> {
    /// The env's index in the batch.
    env: usize,
    slot: &'a mut Slot,
    action: &'a [f32],
    obs: &'a mut [f32],
    final_obs: &'a mut [f32],
    info: &'a mut [f64],
    reward: &'a mut f64,
    terminated: &'a mut bool,
    truncated: &'a mut bool,
    wake_seed: &'a mut u64,
    autoreset: &'a mut bool,
}

/// A step's slots, actions and output buffers, lent out env by env ([`Row`]) to the threads of
/// the step through a [`Queue`]. Holds the exclusive borrows it was made from for its lifetime.
struct StepRows<'a> {
    len: usize,
    slots: *mut Slot,
    actions: &'a [f32],
    obs: *mut f32,
    final_obs: *mut f32,
    info: *mut f64,
    reward: *mut f64,
    terminated: *mut bool,
    truncated: *mut bool,
    wake_seed: *mut u64,
    autoreset: *mut bool,
    _borrow: std::marker::PhantomData<(&'a mut [Slot], StepBuffers<'a>)>,
}

impl<'a> StepRows<'a> {
    /// The rows of `slots`; the caller has checked every buffer's length against it.
    fn new(slots: &'a mut [Slot], actions: &'a [f32], out: StepBuffers<'a>) -> Self {
        let len = slots.len();
        assert!(actions.len() == len * ACT_DIM && out.obs.len() == len * OBS_DIM);
        assert!(out.final_obs.len() == len * OBS_DIM && out.info.len() == len * info::DIM);
        assert!([out.reward.len(), out.terminated.len(), out.truncated.len()] == [len; 3]);
        assert!(out.wake_seed.len() == len && out.autoreset.len() == len);
        StepRows {
            len,
            slots: slots.as_mut_ptr(),
            actions,
            obs: out.obs.as_mut_ptr(),
            final_obs: out.final_obs.as_mut_ptr(),
            info: out.info.as_mut_ptr(),
            reward: out.reward.as_mut_ptr(),
            terminated: out.terminated.as_mut_ptr(),
            truncated: out.truncated.as_mut_ptr(),
            wake_seed: out.wake_seed.as_mut_ptr(),
            autoreset: out.autoreset.as_mut_ptr(),
            _borrow: std::marker::PhantomData,
        }
    }
}

// SAFETY: the rows only hand out disjoint parts of exclusively borrowed slots and buffers (see
// `row`), and a `Slot` is `Send`, so rows may be used on other threads.
unsafe impl Sync for StepRows<'_> {}

// SAFETY: row i touches slot i, the i-th chunk of every output buffer and (shared) the i-th
// action, nothing else: rows of distinct indices are disjoint. The lengths were asserted in
// `new`.
unsafe impl Rows for StepRows<'_> {
    type Row<'r>
        = Row<'r>
    where
        Self: 'r;

    fn len(&self) -> usize {
        self.len
    }

    unsafe fn row(&self, i: usize) -> Row<'_> {
        use std::slice::from_raw_parts_mut as chunk;
        Row {
            env: i,
            slot: &mut *self.slots.add(i),
            action: &self.actions[i * ACT_DIM..(i + 1) * ACT_DIM],
            obs: chunk(self.obs.add(i * OBS_DIM), OBS_DIM),
            final_obs: chunk(self.final_obs.add(i * OBS_DIM), OBS_DIM),
            info: chunk(self.info.add(i * info::DIM), info::DIM),
            reward: &mut *self.reward.add(i),
            terminated: &mut *self.terminated.add(i),
            truncated: &mut *self.truncated.add(i),
            wake_seed: &mut *self.wake_seed.add(i),
            autoreset: &mut *self.autoreset.add(i),
        }
    }
}

/// Starts the slot's episode `slot.index` (the slot is env `env` of `n`); on failure the
/// episode is marked diverged and its outcome returned.
fn restart(slot: &mut Slot, env: u64, n: u64, schedule: &WakeSchedule) -> Option<Outcome> {
    let seeds = episode_seeds(slot.base, slot.index, env, n, schedule);
    match slot.episode.reset(seeds) {
        Ok(()) => None,
        Err(e) => {
            slot.episode.fail_reset(seeds, e);
            Some(Outcome {
                terminated: true,
                diverged: true,
                ..Outcome::default()
            })
        }
    }
}

/// What every row of a step shares: the autoreset mode, the wake-seed schedule of new episodes,
/// the number of envs and the flag that stops the step.
struct RowStepper<'s> {
    mode: Autoreset,
    schedule: &'s WakeSchedule,
    n: u64,
    stop: &'s AtomicBool,
}

impl RowStepper<'_> {
    /// Steps a row: its [`RowStepper::begin`], its episode's step if it steps, and its
    /// [`RowStepper::finish`].
    fn step(&self, mut row: Row<'_>) {
        if self.begin(&mut row) {
            if let Some(c) = row.slot.control.as_mut() {
                let sent: &[f32; ACT_DIM] = row.action.try_into().expect("an action row");
                c.controller.sent(sent);
            }
            let result = row.slot.episode.step_interruptible(row.action, self.stop);
            self.finish(&mut row, result);
        }
    }

    /// Before the row's step: a pending reset starts the next episode (the row is then done).
    /// Returns whether the row's episode steps.
    fn begin(&self, row: &mut Row<'_>) -> bool {
        let slot = &mut *row.slot;
        *row.autoreset = false;
        slot.final_divergence = None;
        if let Some(c) = slot.control.as_mut() {
            c.error = None;
        }
        if slot.pending_reset {
            slot.pending_reset = false;
            slot.index += 1;
            let outcome = restart(slot, row.env as u64, self.n, self.schedule);
            row.obs.copy_from_slice(slot.episode.observation());
            *row.reward = 0.0;
            *row.terminated = outcome.is_some();
            *row.truncated = false;
            *row.autoreset = true;
            *row.wake_seed = slot.episode.seeds().wake;
            write_info(row.info, &outcome.unwrap_or_default(), 0);
            if let Some(c) = slot.control.as_mut() {
                c.act(row.obs, true);
            }
            return false;
        }
        *row.wake_seed = slot.episode.seeds().wake;
        // Interrupted: this env is left as it was.
        !self.stop.load(Ordering::Relaxed)
    }

    /// After the row's step: its outputs, and the automatic reset of an ended episode.
    fn finish(&self, row: &mut Row<'_>, result: std::result::Result<Outcome, SimError>) {
        let o = match result {
            Ok(o) => o,
            Err(SimError::Interrupted { .. }) => return,
            // Actions were checked; a remaining error is a divergence (a panic is a bug: it
            // poisons the batch, see `run`).
            Err(_) => Outcome {
                terminated: true,
                diverged: true,
                ..Outcome::default()
            },
        };
        let slot = &mut *row.slot;
        *row.reward = o.reward;
        *row.terminated = o.terminated;
        *row.truncated = o.truncated;
        write_info(row.info, &o, slot.episode.steps());
        row.obs.copy_from_slice(slot.episode.observation());
        let mut start = false;
        if o.terminated || o.truncated {
            match self.mode {
                Autoreset::NextStep | Autoreset::Disabled => slot.pending_reset = true,
                Autoreset::SameStep => {
                    row.final_obs.copy_from_slice(row.obs);
                    if let Some(c) = slot.control.as_mut() {
                        c.peek(row.final_obs);
                    }
                    start = true;
                    if let Some(true_obs) = slot.episode.true_observation() {
                        slot.final_true_obs = *true_obs;
                    }
                    if o.diverged {
                        slot.final_divergence = slot.episode.divergence().map(str::to_owned);
                    }
                    slot.index += 1;
                    restart(slot, row.env as u64, self.n, self.schedule);
                    row.obs.copy_from_slice(slot.episode.observation());
                }
            }
        }
        // The controller's command for the step's observation, in this thread.
        if let Some(c) = slot.control.as_mut() {
            c.act(row.obs, start);
        }
    }
}

/// Runs `take_one` (which steps the next row and says whether there was one) until no
/// row is left, on the pool's threads and, where `share`, on the calling thread too, which asks
/// `interrupted()` between its rows and while it waits ([`run_shared`]). Long env steps
/// (unusual configs) run on the pool alone, the caller watching.
fn share_rows(
    pool: &rayon::ThreadPool,
    threads: usize,
    n: usize,
    share: bool,
    take_one: &(dyn Fn() -> bool + Sync),
    stop: &AtomicBool,
    interrupted: &mut dyn FnMut() -> bool,
) {
    // With n envs the caller takes one: more than n - 1 helpers would only be waited for.
    let helpers = if share {
        (threads - 1).min(n - 1)
    } else {
        threads
    };
    run_shared(
        pool,
        helpers,
        share,
        take_one,
        stop,
        WATCH_INTERVAL,
        interrupted,
    )
}

/// Longest time the calling thread of [`BatchEnv::step_interruptible`] waits between two
/// calls of its interruption check.
pub const WATCH_INTERVAL: Duration = Duration::from_millis(10);

/// The calling thread of [`BatchEnv::step_interruptible`] steps envs itself (besides the pool)
/// while one env's step has lately taken less than this; it asks the interruption check between
/// its envs, so at most about this long apart.
pub const SHARE_BELOW: Duration = Duration::from_millis(5);

/// Runs a parallel job; a panic in it (a bug, never a divergence) poisons the batch and becomes
/// [`BatchError::Internal`] with the panic's message.
fn run(poisoned: &mut Option<String>, job: impl FnOnce()) -> Result<()> {
    if let Err(payload) = catch_unwind(AssertUnwindSafe(job)) {
        let what = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into());
        let message = format!(
            "internal error (a bug, please report it): {what}; this batch can no longer be used"
        );
        *poisoned = Some(message.clone());
        return Err(BatchError::Internal(message));
    }
    Ok(())
}

fn write_info(info: &mut [f64], o: &Outcome, steps: u64) {
    let flag = |b: bool| if b { 1.0 } else { 0.0 };
    info[info::TIME] = o.time;
    info[info::DISTANCE] = o.distance;
    info[info::RELATIVE_SPEED] = o.relative_speed;
    info[info::PEAK_TENSION] = o.peak_tension;
    info[info::CAPTURED] = flag(o.captured);
    info[info::OVERLOAD] = flag(o.overload);
    info[info::ENVELOPE_EXIT] = flag(o.envelope_exit);
    info[info::DIVERGED] = flag(o.diverged);
    info[info::EPISODE_STEPS] = steps as f64;
}

fn check_len(what: &'static str, found: usize, expected: usize) -> Result<()> {
    if found != expected {
        return Err(BatchError::Shape {
            what,
            expected,
            found,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_in_a_job_is_an_internal_error_that_poisons_the_batch() {
        let mut poisoned = None;
        let err = run(&mut poisoned, || panic!("index out of bounds")).unwrap_err();
        assert!(
            matches!(&err, BatchError::Internal(m) if m.contains("a bug") && m.contains("index out of bounds")),
            "{err}"
        );
        assert!(poisoned.is_some());
        let mut clean = None;
        run(&mut clean, || {}).unwrap();
        assert!(clean.is_none());
    }
}
