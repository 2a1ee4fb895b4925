//! One episode of the RL task ([`crate::task`]): reset from seeds around the open-loop
//! equilibrium, agent steps of several physics steps, observation, reward and episode end.
//! Nothing here allocates per step; divergence is an outcome, not a panic or a NaN.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use accd_tether::TetherState;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Result, SimError};
use crate::physics::accd::AccdState;
use crate::physics::aero::AeroModel;
use crate::physics::capture::{CaptureSim, CaptureState, Snapshot};
use crate::physics::turbulence::AmbientTurbulence;
use crate::physics::wake::{AirSampling, Wake};
use crate::rng::{Seeds, Stream};
use crate::rotation;
use crate::state_format::{check_len, StateError};
use crate::task::config::EnvConfig;
use crate::task::observation::{
    observe, observe_sensed, tilt, ObservationInputs, ACT_DIM, OBS_DIM, SENSED_LAYOUT,
};
use crate::task::randomization::Parameters;
use crate::task::sensors::{SensorState, Sensors};
use crate::task::static_equilibrium;
use crate::valid::Valid;

type V3 = Vector3<f64>;

/// ChaCha stream label of the initial conditions ("INITIAL " in ASCII).
pub const INITIAL_STREAM: u64 = u64::from_be_bytes(*b"INITIAL ");

/// The open-loop equilibrium episodes start around: neutral flaps, mean wake, no turbulence,
/// settled for `initial.settle_time` from the straight trailing start.
#[derive(Debug, Clone, PartialEq)]
pub struct Equilibrium {
    /// The tether's state (time 0).
    pub tether: TetherState,
    /// The ACCD's attitude and rates.
    pub accd: AccdState,
    /// The ACCD's position, m (TA frame).
    pub position: V3,
    /// The capture point's position, m (TA frame).
    pub capture_point: V3,
    /// Where the boom tip's formation sits, m (TA frame; [`crate::BoomConfig::nominal`]).
    pub boom_nominal: V3,
    /// Why episodes starting around this equilibrium would end at their first step (it breaks
    /// an episode limit), if they would.
    pub outside_limits: Option<String>,
    /// Physics steps spent finding it: settled in time, or solved directly
    /// ([`Equilibrium::solve_near`]).
    pub cost_steps: usize,
}

/// The settled state alone (no boom placed): what [`Equilibrium::settle`] and the reference
/// equilibrium of [`reference_capture_point`] share.
struct Settled {
    tether: TetherState,
    accd: AccdState,
    snapshot: Snapshot,
    /// Physics steps spent.
    steps: usize,
}

fn settle_open_loop(
    config: &Valid<EnvConfig>,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<Settled> {
    let mut capture = config.capture().into_inner();
    capture.turbulence.wake_turbulence = false;
    capture.turbulence.ambient = AmbientTurbulence::None;
    // Switching the turbulence off keeps every rule (no rule asks for turbulence).
    let capture = Valid::trusted(capture);
    let mut sim = CaptureSim::new(&capture, Seeds::default())?;
    let steps = (config.initial.settle_time / sim.time_step()).round() as usize;
    for _ in 0..steps {
        sim.step([0.0; 4])?;
        if interrupted() {
            return Err(SimError::Interrupted {
                time: sim.time(),
                what: "settling the open-loop equilibrium".into(),
            });
        }
    }
    let snapshot = sim.snapshot()?;
    let mut tether = sim.tether_state().clone();
    tether.time = 0.0;
    Ok(Settled {
        tether,
        accd: *sim.accd_state(),
        snapshot,
        steps,
    })
}

/// The capture point's open-loop equilibrium in the default configuration, computed with the
/// air-sampling scheme `sampling` (the schemes' equilibria differ in the last digits): the
/// reference [`crate::BoomConfig::nominal`] measures `boom.offset` from. Settled once per
/// process and scheme (about 4000 physics steps), then cached.
pub fn reference_capture_point(
    sampling: AirSampling,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<V3> {
    static CACHE: Mutex<[Option<V3>; 2]> = Mutex::new([None, None]);
    let slot = match sampling {
        AirSampling::PerStep => 0,
        AirSampling::PerStage => 1,
    };
    if let Some(p) = CACHE.lock().unwrap_or_else(|e| e.into_inner())[slot] {
        return Ok(p);
    }
    let mut config = EnvConfig::default();
    config.physics.wake.sampling = sampling;
    let settled = settle_open_loop(&config.validated()?, interrupted)?;
    let p = settled.snapshot.capture_point;
    CACHE.lock().unwrap_or_else(|e| e.into_inner())[slot] = Some(p);
    Ok(p)
}

impl Equilibrium {
    /// Settles the config's system open loop (turbulence off) and places the boom's formation
    /// ([`crate::BoomConfig::nominal`]).
    pub fn settle(config: &Valid<EnvConfig>) -> Result<Equilibrium> {
        Equilibrium::settle_interruptible(config, &mut || false)
    }

    /// [`Equilibrium::settle`], asking `interrupted()` after every physics step and stopping
    /// with [`SimError::Interrupted`] when it returns true.
    pub fn settle_interruptible(
        config: &Valid<EnvConfig>,
        interrupted: &mut dyn FnMut() -> bool,
    ) -> Result<Equilibrium> {
        let settled = settle_open_loop(config, interrupted).map_err(|e| unsettled(config, e))?;
        Equilibrium::place(config, settled, interrupted)
    }

    /// The open-loop equilibrium of `config` solved directly from `near`, the equilibrium of
    /// `near_config` (another configuration of the same system: the base of randomized physics),
    /// with at most [`static_equilibrium::MAX_STEPS`] physics steps
    /// ([`crate::task::static_equilibrium`]): the state the time settle converges to, at rest.
    /// When that solve does not converge, settled in time as [`Equilibrium::settle`].
    pub fn solve_near(
        config: &Valid<EnvConfig>,
        near: &Equilibrium,
        near_config: &EnvConfig,
    ) -> Result<Equilibrium> {
        Equilibrium::solve_near_with(config, near, near_config, None)
    }

    /// [`Equilibrium::solve_near`] with `config`'s aerodynamic model and mean wake built.
    fn solve_near_with(
        config: &Valid<EnvConfig>,
        near: &Equilibrium,
        near_config: &EnvConfig,
        model: Option<(Arc<AeroModel>, Wake)>,
    ) -> Result<Equilibrium> {
        let solved =
            static_equilibrium::solve(config, near_config, &near.tether, &near.accd, model)?;
        let settled = match solved {
            Some(s) => Settled {
                tether: s.tether,
                accd: s.accd,
                snapshot: s.snapshot,
                steps: s.steps,
            },
            None => settle_open_loop(config, &mut || false).map_err(|e| unsettled(config, e))?,
        };
        Equilibrium::place(config, settled, &mut || false)
    }

    /// The equilibrium at `settled`, with the boom's formation placed relative to it.
    fn place(
        config: &Valid<EnvConfig>,
        settled: Settled,
        interrupted: &mut dyn FnMut() -> bool,
    ) -> Result<Equilibrium> {
        let capture_point = settled.snapshot.capture_point;
        let boom_nominal = config.physics.boom.nominal(&capture_point, || {
            reference_capture_point(config.physics.wake.sampling, interrupted)
        })?;
        let outside_limits = outside_limits(config, &settled.snapshot, &boom_nominal);
        Ok(Equilibrium {
            tether: settled.tether,
            accd: settled.accd,
            position: settled.snapshot.position,
            capture_point,
            boom_nominal,
            outside_limits,
            cost_steps: settled.steps,
        })
    }
}

/// A divergence while settling `config`'s equilibrium as [`SimError::Unsettled`], naming the
/// fields set away from their defaults (every value is inside its range, so one of them or
/// their combination is what fails); any other error as it is.
fn unsettled(config: &EnvConfig, e: SimError) -> SimError {
    let diverged = matches!(
        e,
        SimError::Diverged { .. } | SimError::Tether(accd_tether::TetherError::Diverged { .. })
    );
    if !diverged {
        return e;
    }
    let fields = config.changed_fields();
    SimError::Unsettled {
        fields: if fields.is_empty() {
            "none (the defaults)".into()
        } else {
            fields.join(", ")
        },
        reason: e.to_string(),
    }
}

/// Why episodes of `config` starting around its open-loop equilibrium `s` would mostly end at
/// once, if they would: the capture point farther than `limits.max_distance` from the boom tip's
/// nominal place `nominal` (along track the approach closes on the capture point), the ACCD
/// tilted beyond `limits.max_tilt_deg`, or the attachment tension beyond the overload tension.
/// The message names the limit and the equilibrium's value. (A warning, not an error: an
/// unsettled start, a short `initial.settle_time`, is a legitimate choice in tests.)
fn outside_limits(config: &EnvConfig, s: &Snapshot, nominal: &V3) -> Option<String> {
    let boom = &config.physics.boom;
    let limits = &config.limits;
    let along = if boom.approach_speed > 0.0 {
        s.capture_point.x
    } else {
        nominal.x
    };
    let nominal = Vector3::new(along, nominal.y, nominal.z);
    let distance = (s.capture_point - nominal).norm();
    let tilt_deg = tilt(&s.attitude).to_degrees();
    let overload = limits.overload_fraction * config.physics.tether.breaking_tension;
    let what = if distance > limits.max_distance {
        format!(
            "puts the capture point {distance:.2} m from the boom tip's nominal position \
             (boom.offset, boom.placement), beyond limits.max_distance = {} m",
            limits.max_distance
        )
    } else if tilt_deg > limits.max_tilt_deg {
        format!(
            "tilts the ACCD {tilt_deg:.2} deg, beyond limits.max_tilt_deg = {} deg",
            limits.max_tilt_deg
        )
    } else if s.attachment_tension > overload {
        format!(
            "pulls {:.4e} N at the attachment, beyond the overload tension {overload:.4e} N \
             (limits.overload_fraction = {} of tether.breaking_tension)",
            s.attachment_tension, limits.overload_fraction
        )
    } else {
        return None;
    };
    Some(format!(
        "the open-loop equilibrium of this configuration (neutral flaps, after \
         initial.settle_time = {} s) {what}: episodes start around it, so most end at their \
         first step; relax that limit or change the configuration",
        config.initial.settle_time
    ))
}

/// What one agent step did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Outcome {
    /// Reward of the step.
    pub reward: f64,
    /// The episode ended (capture, overload, envelope exit or divergence).
    pub terminated: bool,
    /// The capture window elapsed.
    pub truncated: bool,
    /// Captured.
    pub captured: bool,
    /// The attachment tension exceeded the overload limit.
    pub overload: bool,
    /// The ACCD left the flight envelope.
    pub envelope_exit: bool,
    /// The simulation diverged (the observation is the last good one).
    pub diverged: bool,
    /// Distance from the capture point to the boom tip at the end of the step, m.
    pub distance: f64,
    /// Relative speed of the capture point with respect to the boom tip, m/s.
    pub relative_speed: f64,
    /// Highest attachment tension during the step, N.
    pub peak_tension: f64,
    /// Episode time at the end of the step, s.
    pub time: f64,
}

/// One episode: the physics, the task's bookkeeping, the latest observation.
#[derive(Clone)]
pub struct Episode {
    /// The env's configuration (what randomized physics draws around).
    base: Arc<Valid<EnvConfig>>,
    /// This episode's configuration: `base`, or with randomization the episode's drawn physics.
    config: Arc<Valid<EnvConfig>>,
    equilibrium: Arc<Equilibrium>,
    /// The equilibrium of `base`: what randomized physics solves its own equilibria from.
    base_equilibrium: Arc<Equilibrium>,
    /// The drawn physical parameters, with randomization.
    parameters: Option<Parameters>,
    sim: CaptureSim,
    /// Scratch for the perturbed initial state.
    start: TetherState,
    substeps: usize,
    total_steps: u64,
    flap_limit: f64,
    overload_tension: f64,
    steps: u64,
    seeds: Seeds,
    previous_action: [f64; ACT_DIM],
    obs: [f32; OBS_DIM],
    distance: f64,
    done: bool,
    divergence: Option<String>,
    /// The sensor model of the observation (`sensors.enabled`), or none: the true state.
    sensors: Option<Sensors>,
    /// The true observation (perfect sensors: noise-free, delay-free) of the latest state,
    /// kept only when asked for ([`Episode::set_true_observation`]); the observation's own
    /// path is unchanged without it.
    true_obs: Option<[f32; OBS_DIM]>,
}

impl Episode {
    /// An episode of `config` starting around `equilibrium` (see [`Equilibrium::settle`]),
    /// reset with `seeds`.
    pub fn new(
        config: Arc<Valid<EnvConfig>>,
        equilibrium: Arc<Equilibrium>,
        seeds: Seeds,
    ) -> Result<Episode> {
        if config.randomization.enabled {
            check_drawable(&config)?;
        }
        let mut sim = CaptureSim::new(&config.capture(), seeds)?;
        sim.set_boom_nominal(equilibrium.boom_nominal)?;
        let sensors = config.sensors.enabled.then(|| {
            Sensors::new(
                &config.sensors,
                config.physics.tether.time_step,
                SENSED_LAYOUT,
            )
        });
        let mut episode = Episode {
            base: Arc::clone(&config),
            parameters: None,
            start: equilibrium.tether.clone(),
            substeps: config.substeps(),
            total_steps: config.episode_steps(),
            flap_limit: config.physics.accd.flap_limit_deg.to_radians(),
            overload_tension: config.limits.overload_fraction
                * config.physics.tether.breaking_tension,
            config,
            base_equilibrium: Arc::clone(&equilibrium),
            equilibrium,
            sim,
            steps: 0,
            seeds,
            previous_action: [0.0; ACT_DIM],
            obs: [0.0; OBS_DIM],
            distance: 0.0,
            done: false,
            divergence: None,
            sensors,
            true_obs: None,
        };
        episode.reset(seeds)?;
        Ok(episode)
    }

    /// The physics of the episode with wake seed `wake_seed` when the base config randomizes
    /// it and the draw differs from the current one: its config, equilibrium and sim, built
    /// whole (nothing of `self` changes); None when the current physics already fits.
    fn drawn_physics(&self, seeds: Seeds) -> Result<Option<Physics>> {
        if !self.base.randomization.enabled {
            return Ok(None);
        }
        let parameters = Parameters::draw(&self.base.randomization, seeds.wake);
        if self.parameters == Some(parameters) {
            return Ok(None);
        }
        let config = Arc::new(drawn_config(&self.base, &parameters)?);
        // The aerodynamic model and the wake tables, built once for the solve and the episode.
        let capture = config.capture();
        let aero = Arc::new(capture.accd.aero_model()?);
        let wake = Wake::from_config(&capture.wake, capture.aircraft.airspeed)?;
        let equilibrium = Arc::new(Equilibrium::solve_near_with(
            &config,
            &self.base_equilibrium,
            &self.base,
            Some((Arc::clone(&aero), wake.clone())),
        )?);
        // Installed, then reset at once (`Episode::reset`): its turbulence is generated there.
        let mut sim = CaptureSim::with_model_for_reset(&capture, seeds, aero, wake)?;
        sim.set_boom_nominal(equilibrium.boom_nominal)?;
        Ok(Some(Physics {
            parameters,
            config,
            equilibrium,
            sim,
        }))
    }

    /// Makes `physics` the episode's.
    fn install(&mut self, physics: Physics) {
        self.flap_limit = physics.config.physics.accd.flap_limit_deg.to_radians();
        self.overload_tension = physics.config.limits.overload_fraction
            * physics.config.physics.tether.breaking_tension;
        self.start = physics.equilibrium.tether.clone();
        self.parameters = Some(physics.parameters);
        self.config = physics.config;
        self.equilibrium = physics.equilibrium;
        self.sim = physics.sim;
    }

    /// Starts a new episode: the ACCD displaced from the equilibrium and tilted at random (from
    /// the `initial` stream of `seeds.initial`), boom and turbulence from their seeds, t = 0.
    /// With randomized physics the episode's parameters are drawn from `seeds.wake` first, and
    /// its equilibrium solved from the base's ([`Equilibrium::solve_near`]; unless the
    /// parameters are the current ones).
    pub fn reset(&mut self, seeds: Seeds) -> Result<()> {
        if let Some(physics) = self.drawn_physics(seeds)? {
            self.install(physics);
        }
        let init = &self.config.initial;
        let mut stream = Stream::new(seeds.initial, INITIAL_STREAM);
        let length = self.config.physics.tether.length;
        let d_psi = stream.range(-1.0, 1.0) * init.offset[0] / length;
        let d_phi = stream.range(-1.0, 1.0) * init.offset[1] / length;
        let max_angle = init.attitude_deg.to_radians();
        let roll = stream.range(-1.0, 1.0) * max_angle;
        let pitch = stream.range(-1.0, 1.0) * max_angle;
        let yaw = stream.range(-1.0, 1.0) * max_angle;

        let eq = &self.equilibrium;
        self.start.q.copy_from_slice(&eq.tether.q);
        self.start.qd.copy_from_slice(&eq.tether.qd);
        for k in 0..self.config.physics.tether.segments {
            self.start.q[1 + 2 * k] += d_phi;
            self.start.q[2 + 2 * k] += d_psi;
        }
        let accd = AccdState {
            attitude: eq.accd.attitude * rotation::from_euler_angles(roll, pitch, yaw),
            omega: eq.accd.omega,
        };
        self.sim.reset(seeds, &self.start, accd)?;
        self.seeds = seeds;
        self.steps = 0;
        self.previous_action = [0.0; ACT_DIM];
        self.done = false;
        self.divergence = None;
        if let Some(sensors) = &mut self.sensors {
            sensors.reset(seeds.initial, &self.sim.boom_relative());
        }
        let snapshot = self.sim.snapshot()?;
        if !self.observe(&snapshot) {
            return Err(SimError::Diverged {
                time: 0.0,
                reason: "non-finite initial observation".into(),
            });
        }
        self.distance = snapshot.capture.distance;
        Ok(())
    }

    /// Writes the observation of `s` into `self.obs` if it is finite; false otherwise.
    fn observe(&mut self, s: &Snapshot) -> bool {
        let inputs = ObservationInputs {
            snapshot: s,
            equilibrium: &self.equilibrium.position,
            flap_limit: self.flap_limit,
            capture_window: self.config.capture_window,
        };
        let finite = match &mut self.sensors {
            Some(sensors) => observe_sensed(&inputs, sensors, &mut self.obs),
            None => observe(&inputs, &mut self.obs),
        };
        if finite {
            if let Some(true_obs) = &mut self.true_obs {
                match self.sensors {
                    // The same quantities as the sensed observation, without the sensor model.
                    Some(_) => {
                        observe(&inputs, true_obs);
                    }
                    None => *true_obs = self.obs,
                }
            }
        }
        finite
    }

    /// Keeps (`on`) or drops the true observation: what perfect sensors (noise-free,
    /// delay-free) would observe, scaled like the observation. Switched on, it is computed at
    /// once from the current state and then with every observation; it is the observation
    /// itself without `sensors.enabled`. Nothing else of the episode changes.
    pub fn set_true_observation(&mut self, on: bool) {
        self.true_obs = on.then_some(self.obs);
        if on {
            self.refresh_true_observation();
        }
    }

    /// Recomputes the kept true observation from the current state, if it is kept, the episode
    /// has sensors and the state gives a finite observation (after a divergence it stays the
    /// last good one).
    fn refresh_true_observation(&mut self) {
        let Some(true_obs) = &mut self.true_obs else {
            return;
        };
        if self.sensors.is_none() {
            *true_obs = self.obs;
            return;
        }
        if let Ok(s) = self.sim.snapshot() {
            let inputs = ObservationInputs {
                snapshot: &s,
                equilibrium: &self.equilibrium.position,
                flap_limit: self.flap_limit,
                capture_window: self.config.capture_window,
            };
            let mut fresh = [0.0; OBS_DIM];
            if observe(&inputs, &mut fresh) {
                *true_obs = fresh;
            }
        }
    }

    /// The true observation of the latest state (see [`Episode::set_true_observation`]), when
    /// it is kept.
    pub fn true_observation(&self) -> Option<&[f32; OBS_DIM]> {
        self.true_obs.as_ref()
    }

    /// One agent step with `action` (four flap commands in [-1, 1], clipped). A non-finite
    /// action is an error and changes nothing; so is stepping an episode that has ended.
    pub fn step(&mut self, action: &[f32]) -> Result<Outcome> {
        self.step_interruptible(action, &AtomicBool::new(false))
    }

    /// [`Episode::step`], stopping with [`SimError::Interrupted`] before any physics step that
    /// finds `stop` set. An interrupted step leaves the episode part-way through its agent step,
    /// so it counts as ended ([`Episode::done`]): reset it (or restore a state) to go on.
    pub fn step_interruptible(&mut self, action: &[f32], stop: &AtomicBool) -> Result<Outcome> {
        let mut step = self.begin(action)?;
        for k in 0..self.substeps {
            if stop.load(Ordering::Relaxed) {
                return Err(self.interrupt(k));
            }
            let result = self.sim.step(step.command);
            if !self.after_physics_step(&mut step.out, result) {
                break;
            }
        }
        Ok(self.finish(step))
    }

    /// The checks and the flap commands of an agent step with `action`, and its outcome so far.
    fn begin(&mut self, action: &[f32]) -> Result<AgentStep> {
        if action.len() != ACT_DIM {
            return Err(SimError::invalid_config(
                "action",
                format!("{} values", action.len()),
                &format!("{ACT_DIM} flap commands"),
            ));
        }
        if let Some((i, v)) = action.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(SimError::invalid_config(
                &format!("action[{i}]"),
                v,
                "a finite value in [-1, 1] (out-of-range values are clipped)",
            ));
        }
        if self.done {
            return Err(SimError::invalid_config(
                "step",
                "after the episode ended",
                "reset() before stepping again",
            ));
        }
        let mut a = [0.0; ACT_DIM];
        let mut command = [0.0; ACT_DIM];
        for i in 0..ACT_DIM {
            a[i] = (action[i] as f64).clamp(-1.0, 1.0);
            command[i] = a[i] * self.flap_limit;
        }
        let out = Outcome {
            peak_tension: self.sim.attachment_tension(),
            distance: self.distance,
            ..Outcome::default()
        };
        Ok(AgentStep {
            action: a,
            command,
            out,
        })
    }

    /// The agent step interrupted before its physics step `k`: the episode ends.
    fn interrupt(&mut self, k: usize) -> SimError {
        self.done = true;
        SimError::Interrupted {
            time: self.sim.time(),
            what: format!(
                "agent step {} after {k} of its {} physics steps",
                self.steps + 1,
                self.substeps
            ),
        }
    }

    /// What follows a physics step that gave `result`: the sensors, the tension, the capture
    /// check, into `out`. Whether the agent step goes on.
    fn after_physics_step(&mut self, out: &mut Outcome, result: Result<()>) -> bool {
        if let Err(e) = result {
            self.diverge(e);
            out.diverged = true;
            return false;
        }
        if let Some(sensors) = &mut self.sensors {
            sensors.physics_step(&self.sim.boom_relative());
        }
        let tension = self.sim.attachment_tension();
        out.peak_tension = out.peak_tension.max(tension);
        if tension > self.overload_tension {
            out.overload = true;
            return false;
        }
        match self.sim.capture_status() {
            Ok(status) if status.captured => {
                out.captured = true;
                false
            }
            Ok(_) => true,
            Err(e) => {
                self.diverge(e);
                out.diverged = true;
                false
            }
        }
    }

    /// The end of an agent step: the observation, the limits, the reward.
    fn finish(&mut self, step: AgentStep) -> Outcome {
        let AgentStep {
            action: a, mut out, ..
        } = step;
        self.steps += 1;
        out.time = self.sim.time();
        if !out.diverged {
            match self.sim.snapshot() {
                Ok(s) if !self.plausible(&s) => {
                    self.diverge(SimError::Diverged {
                        time: s.time,
                        reason: format!(
                            "ACCD speed {:.3e} m/s relative to the aircraft or body rate {:.3e} rad/s beyond physical bounds",
                            s.velocity.norm(),
                            s.omega.norm()
                        ),
                    });
                    out.diverged = true;
                }
                Ok(s) if self.observe(&s) => {
                    out.distance = s.capture.distance;
                    out.relative_speed = s.capture.relative_speed;
                    let limits = &self.config.limits;
                    out.envelope_exit = !out.captured
                        && (s.capture.distance > limits.max_distance
                            || tilt(&s.attitude) > limits.max_tilt_deg.to_radians()
                            || libm::hypot(s.omega.y, s.omega.z) > limits.max_body_rate
                            || s.omega.x.abs() > limits.max_roll_rate);
                }
                Ok(s) => {
                    self.diverge(SimError::Diverged {
                        time: s.time,
                        reason: "non-finite observation".into(),
                    });
                    out.diverged = true;
                }
                Err(e) => {
                    self.diverge(e);
                    out.diverged = true;
                }
            }
        }
        self.distance = out.distance;
        out.terminated = out.captured || out.overload || out.envelope_exit || out.diverged;
        out.truncated = !out.terminated && self.steps >= self.total_steps;
        out.reward = self.reward(&a, &out);
        self.previous_action = a;
        self.done = out.terminated || out.truncated;
        out
    }

    /// False for a state no flight could reach: the ACCD faster than twice the airspeed
    /// relative to the aircraft, or spinning faster than 1000 rad/s (a diverging integration).
    fn plausible(&self, s: &Snapshot) -> bool {
        s.velocity.norm() <= 2.0 * self.config.physics.aircraft.airspeed && s.omega.norm() <= 1e3
    }

    /// Marks the episode of `seeds` ended by a reset that failed with `e` (its physics could not
    /// be built or settled): done, with the reason as its divergence, so that a batch's
    /// automatic reset reports why instead of a bare flag.
    pub fn fail_reset(&mut self, seeds: Seeds, e: SimError) {
        self.seeds = seeds;
        self.done = true;
        self.divergence = Some(format!("reset failed: {e}"));
    }

    fn diverge(&mut self, e: SimError) {
        self.divergence = Some(e.to_string());
    }

    /// The reward of the module docs of [`crate::task`].
    fn reward(&self, a: &[f64; ACT_DIM], out: &Outcome) -> f64 {
        let w = &self.config.reward;
        let effort = a.iter().map(|v| v * v).sum::<f64>() / ACT_DIM as f64;
        let rate = a
            .iter()
            .zip(&self.previous_action)
            .map(|(v, p)| {
                let d = 0.5 * (v - p);
                d * d
            })
            .sum::<f64>()
            / ACT_DIM as f64;
        let mut r = w.proximity * libm::exp(-out.distance / w.proximity_scale)
            - w.effort * effort
            - w.smoothness * rate;
        if out.captured {
            let left = self.total_steps.saturating_sub(self.steps);
            r += w.capture + w.proximity * left as f64;
        }
        if out.overload || out.envelope_exit || out.diverged {
            r -= w.failure;
        }
        r
    }

    /// The latest observation (the last good one after a divergence).
    pub fn observation(&self) -> &[f32; OBS_DIM] {
        &self.obs
    }

    /// The episode's seeds.
    pub fn seeds(&self) -> Seeds {
        self.seeds
    }

    /// Agent steps taken in this episode.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The episode has ended (reset before stepping again).
    pub fn done(&self) -> bool {
        self.done
    }

    /// Why the episode diverged, if it did.
    pub fn divergence(&self) -> Option<&str> {
        self.divergence.as_deref()
    }

    /// The episode's configuration (with randomization, its drawn physics).
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// The open-loop equilibrium (the episode's own with randomized physics).
    pub fn equilibrium(&self) -> &Equilibrium {
        &self.equilibrium
    }

    /// The episode's drawn physical parameters (None without randomization).
    pub fn parameters(&self) -> Option<&Parameters> {
        self.parameters.as_ref()
    }

    /// The env's configuration the episode was built with (with randomization, what the
    /// parameters are drawn around; [`Episode::config`] is the episode's own).
    pub fn base_config(&self) -> &EnvConfig {
        &self.base
    }

    /// The physics (for rendering and analysis).
    pub fn sim(&self) -> &CaptureSim {
        &self.sim
    }

    /// The physics, mutably (snapshots need scratch space).
    pub fn sim_mut(&mut self) -> &mut CaptureSim {
        &mut self.sim
    }

    /// The sensor model, when `sensors.enabled`.
    pub fn sensors(&self) -> Option<&Sensors> {
        self.sensors.as_ref()
    }

    /// The episode's dynamic state (physics, counters, seeds, last action and observation,
    /// sensors).
    pub fn state(&self) -> EpisodeState {
        EpisodeState {
            sim: self.sim.state(),
            steps: self.steps,
            seeds: self.seeds,
            previous_action: self.previous_action,
            observation: self.obs.to_vec(),
            distance: self.distance,
            done: self.done,
            divergence: self.divergence.clone(),
            sensors: self.sensors.as_ref().map(Sensors::state),
        }
    }

    /// Restores a state from [`Episode::state`] of an episode with the same config, checked
    /// whole first: on an error the episode is as it was.
    pub fn set_state(&mut self, state: EpisodeState) -> Result<()> {
        check_len("observation", state.observation.len(), OBS_DIM)?;
        // With randomization the state's seeds name its physics: rebuild them if they differ.
        let physics = self.drawn_physics(state.seeds)?;
        let sim_base = match &physics {
            Some(p) => p.sim.clone(),
            None => self.sim.clone(),
        };
        let mut sensors = self.sensors.clone();
        match (&mut sensors, &state.sensors) {
            (Some(s), Some(saved)) => s.set_state(saved)?,
            (None, None) => {}
            (mine, _) => {
                return Err(StateError::invalid(
                    "sensors",
                    if mine.is_some() {
                        "none"
                    } else {
                        "a sensor state"
                    },
                    "a sensor state exactly when sensors.enabled",
                )
                .into())
            }
        }
        let mut sim = sim_base;
        sim.apply_state(state.sim)?;
        if let Some(p) = physics {
            self.install(p);
        }
        self.sim = sim;
        self.sensors = sensors;
        self.steps = state.steps;
        self.seeds = state.seeds;
        self.previous_action = state.previous_action;
        self.obs.copy_from_slice(&state.observation);
        self.distance = state.distance;
        self.done = state.done;
        self.divergence = state.divergence;
        self.refresh_true_observation();
        Ok(())
    }
}

/// The configuration of an episode of `base` whose randomized physics drew `parameters`
/// ([`Parameters::apply_to`] on its physics), validated whole, with randomization off (it is one
/// An agent step in progress: the clipped action, the flap commands (rad) and the outcome so
/// far.
struct AgentStep {
    action: [f64; ACT_DIM],
    command: [f64; ACT_DIM],
    out: Outcome,
}

/// episode's fixed physics).
pub fn drawn_config(base: &EnvConfig, parameters: &Parameters) -> Result<Valid<EnvConfig>> {
    let mut c = base.clone();
    parameters.apply_to(&mut c.physics);
    c.randomization.enabled = false;
    c.validated()
}

/// Refuses a randomization whose draws cannot all be built, before any episode runs (otherwise
/// every such draw would end its episode at reset as a divergence): the physics at both corners of
/// the ranges must validate and construct (the wake tables' angles, the aerodynamic table, the
/// tether's stability step). The error names `randomization` and the corner, then the field.
fn check_drawable(base: &EnvConfig) -> Result<()> {
    for (upper, end) in [(false, "low"), (true, "high")] {
        let corner = Parameters::corner(&base.randomization, upper);
        let built = drawn_config(base, &corner)
            .and_then(|c| CaptureSim::new(&c.capture(), Seeds::default()).map(|_| ()));
        if let Err(e) = built {
            return Err(SimError::invalid_config(
                "randomization",
                format!("{corner:?}"),
                &format!("ranges whose every draw builds; at their {end} ends: {e}"),
            ));
        }
    }
    Ok(())
}

/// An episode's physics with randomized parameters (built whole, then installed).
struct Physics {
    parameters: Parameters,
    config: Arc<Valid<EnvConfig>>,
    equilibrium: Arc<Equilibrium>,
    sim: CaptureSim,
}

/// One RL episode's state ([`crate::Episode`]).
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeState {
    /// The physics.
    pub sim: CaptureState,
    /// Agent steps taken.
    pub steps: u64,
    /// The episode's seeds.
    pub seeds: Seeds,
    /// The last action (clipped), for the smoothness cost.
    pub previous_action: [f64; ACT_DIM],
    /// The latest observation.
    pub observation: Vec<f32>,
    /// Distance from the capture point to the boom tip at the last step, m.
    pub distance: f64,
    /// The episode has ended.
    pub done: bool,
    /// Why it diverged, if it did.
    pub divergence: Option<String>,
    /// The sensor model's state, when `sensors.enabled`.
    pub sensors: Option<SensorState>,
}
