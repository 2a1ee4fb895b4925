//! One capture episode: the tether (with the ACCD's mass at its tip), the ACCD's attitude
//! dynamics and flaps, the towing aircraft's flight, the air (free stream plus any disturbance:
//! wake, turbulence) and the RLV's boom, stepped together.
//!
//! # Integration
//! The tether coordinates and the ACCD's attitude quaternion and body rates form one state,
//! advanced by classical RK4 at the tether's fixed step (0.01 s by default). At every stage the
//! ACCD's aerodynamic force (from its attitude, rates, flaps and the air at its position) enters
//! the tether as the tip force, and its moment drives Euler's equations. Once per step, before
//! the RK4 stages: the flap actuators, the boom and the air disturbance advance, and the air
//! density is taken from ISA at the aircraft's altitude (varying linearly with depth below it).
//! The quaternion is renormalised after each step.

use std::cell::Cell;
use std::sync::Arc;

use accd_tether::{Atmosphere, Surroundings, TetherConfig, TetherModel, TetherState};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::accd::{aero_loads, angular_acceleration, AccdConfig, AccdState, Actuators, AeroLoads};
use crate::aero::AeroModel;
use crate::aircraft::AircraftConfig;
use crate::boom::{Boom, BoomConfig, CaptureStatus};
use crate::error::{Result, SimError};
use crate::state_format::{check_len, AirState, CaptureState, StateError};
use crate::turbulence::{Turbulence, TurbulenceConfig};
use crate::wake::{AirSampling, Wake, WakeConfig};
use crate::wake_field::WakeField;

type V3 = Vector3<f64>;

/// ISA sea-level density, kg/m^3: the densest air an episode meets, for stability estimates.
const SEA_LEVEL_DENSITY: f64 = 1.225;

/// Disturbances of the air relative to the free stream (wake, turbulence), anywhere in the TA
/// frame. `velocity` must be a pure function during a step; `advance` moves time-dependent
/// parts (turbulence) forward once per step.
pub trait AirDisturbance: Send + Sync {
    /// Velocity added to the free stream at `position` (TA frame, m), m/s.
    fn velocity(&self, time: f64, position: &V3) -> V3;

    /// Advances internal state from `time` to `time + dt`.
    fn advance(&mut self, _time: f64, _dt: f64) -> Result<()> {
        Ok(())
    }

    /// Restarts at time 0 with the random streams of `wake_seed`. Must not allocate.
    fn reset(&mut self, _wake_seed: u64) {}

    /// Declares points that will be sampled during the coming step (before any of them is):
    /// a disturbance that generates its field lazily generates it there. Must not allocate.
    fn prepare(&mut self, _points: &[V3]) {}

    /// Declares that the disturbance may be sampled anywhere (the stepper cannot say where
    /// beforehand). Must not allocate.
    fn prepare_all(&mut self) {}

    /// A boxed copy (the episode is cloned for snapshots).
    fn clone_box(&self) -> Box<dyn AirDisturbance>;

    /// The time-dependent state ([`AirState::Steady`] for a steady disturbance).
    fn state(&self) -> AirState {
        AirState::Steady
    }

    /// Restores a state from `state` of a disturbance built from the same config; checks it
    /// first and changes nothing on an error.
    fn set_state(&mut self, state: AirState) -> Result<(), StateError> {
        match state {
            AirState::Steady => Ok(()),
            AirState::Turbulence(_) => Err(StateError::invalid(
                "air",
                "the state of a turbulent wake",
                "the state of a steady disturbance",
            )),
        }
    }
}

/// No disturbance: the free stream alone.
#[derive(Debug, Clone, Copy, Default)]
pub struct CalmAir;

impl AirDisturbance for CalmAir {
    fn velocity(&self, _time: f64, _position: &V3) -> V3 {
        V3::zeros()
    }

    fn clone_box(&self) -> Box<dyn AirDisturbance> {
        Box::new(*self)
    }
}

/// Everything that defines an episode's physics. Missing keys take their defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CaptureConfig {
    /// The tether (Table 3 by default). Its `tip_mass` must stay 0: the ACCD's mass is at the tip.
    pub tether: TetherConfig,
    /// The capturing device.
    pub accd: AccdConfig,
    /// The towing aircraft.
    pub aircraft: AircraftConfig,
    /// The RLV's boom.
    pub boom: BoomConfig,
    /// The towing aircraft's mean wake (on by default, at 8 degrees angle of attack).
    pub wake: WakeConfig,
    /// Wake and ambient turbulence (wake turbulence on by default, ambient off).
    pub turbulence: TurbulenceConfig,
}

impl Default for CaptureConfig {
    /// The capture mission: Table 3's tether, the default ACCD and boom, the aircraft at 185 m/s
    /// and 6000 m, its wake at 8 degrees angle of attack with wake turbulence.
    fn default() -> Self {
        CaptureConfig {
            tether: TetherConfig::table3(),
            accd: AccdConfig::default(),
            aircraft: AircraftConfig::default(),
            boom: BoomConfig::default(),
            wake: WakeConfig::default(),
            turbulence: TurbulenceConfig::default(),
        }
    }
}

impl CaptureConfig {
    /// Checks every part.
    pub fn validate(&self) -> Result<()> {
        self.tether.validate()?;
        if self.tether.tip_mass != 0.0 {
            return Err(SimError::invalid_config(
                "tether.tip_mass",
                self.tether.tip_mass,
                "0 kg (the ACCD's mass, accd.mass, is the tip mass)",
            ));
        }
        self.accd.validate()?;
        self.aircraft.validate()?;
        self.boom.validate()?;
        self.wake.validate()?;
        self.turbulence.validate()?;
        crate::task::check_cross_fields(self)
    }

    /// The paper's open-loop setting (section 4): no wake, no turbulence ("no wake unless stated").
    pub fn calm() -> Self {
        let mut config = CaptureConfig::default();
        config.wake.enabled = false;
        config.turbulence.wake_turbulence = false;
        config
    }

    /// Parses JSON (unknown keys are errors) and validates.
    pub fn from_json(text: &str) -> Result<Self> {
        let config: CaptureConfig = parse_json(text, "(document)")?;
        config.validate()?;
        Ok(config)
    }

    /// The tether with the ACCD's mass at its tip.
    pub fn tether_with_tip(&self) -> TetherConfig {
        TetherConfig {
            tip_mass: self.accd.mass,
            ..self.tether.clone()
        }
    }
}

/// The capture point (the ACCD's tail, `offset` from its centre of gravity in body axes) and its
/// velocity, from the tether tip's (the centre of gravity's) position and velocity and the ACCD's
/// attitude and body rates. TA frame, m and m/s.
fn capture_point(position: &V3, velocity: &V3, accd: &AccdState, offset: &V3) -> (V3, V3) {
    let attitude = accd.attitude;
    (
        position + attitude.transform_vector(offset),
        velocity + attitude.transform_vector(&accd.omega.cross(offset)),
    )
}

/// Parses a JSON config document; serde's message (unknown field, wrong type, with the line and
/// column) becomes an [`SimError::InvalidConfig`] for `what`.
pub(crate) fn parse_json<T: serde::de::DeserializeOwned>(text: &str, _what: &str) -> Result<T> {
    crate::task::parse_named(text)
}

/// The seeds of an episode's independent random streams.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Seeds {
    /// Initial conditions.
    pub initial: u64,
    /// Wake turbulence (the "wake seed").
    pub wake: u64,
    /// RLV motion (the boom).
    pub rlv: u64,
}

/// The air as seen during one step.
#[derive(Debug, Clone, Copy)]
struct AirAtStep {
    /// ISA density at the aircraft's altitude, kg/m^3.
    density: f64,
    /// d(density)/d(depth below the aircraft), kg/m^4.
    density_per_depth: f64,
}

/// The surroundings of the tether during one RK4 stage: free stream and disturbance at every
/// point, the aircraft's acceleration, and the ACCD's aerodynamic force as the tip force (its
/// loads are kept for the attitude equations).
struct Stage<'a> {
    aircraft: &'a AircraftConfig,
    air: AirAtStep,
    disturbance: &'a dyn AirDisturbance,
    aero: &'a AeroModel,
    accd: AccdState,
    deflection: [f64; 4],
    loads: Cell<AeroLoads>,
    /// With [`AirSampling::PerStep`]: the disturbance at each segment centre and at the tip,
    /// sampled once at the step's initial state and held over the stages.
    held: Option<(&'a [V3], V3)>,
}

impl Surroundings for Stage<'_> {
    fn air_velocity(&self, time: f64, position: &V3) -> V3 {
        -self.aircraft.velocity(time) + self.disturbance.velocity(time, position)
    }
    #[inline(always)]
    fn segment_air_velocity(&self, time: f64, segment: usize, position: &V3) -> V3 {
        match self.held {
            Some((held, _)) => -self.aircraft.velocity(time) + held[segment],
            None => self.air_velocity(time, position),
        }
    }
    fn air_density(&self, _time: f64, position: &V3) -> f64 {
        self.air.density + self.air.density_per_depth * position.z
    }
    fn frame_acceleration(&self, time: f64) -> V3 {
        self.aircraft.acceleration(time)
    }
    fn tip_force(&self, time: f64, position: &V3, velocity: &V3) -> V3 {
        let wind = match self.held {
            Some((_, tip)) => -self.aircraft.velocity(time) + tip,
            None => self.air_velocity(time, position),
        };
        let rho = self.air_density(time, position);
        let loads = aero_loads(
            self.aero,
            &self.accd,
            velocity,
            &wind,
            rho,
            &self.deflection,
        );
        self.loads.set(loads);
        loads.force
    }
}

/// RK4 stage buffers.
#[derive(Debug, Clone)]
struct Buffers {
    q: Vec<f64>,
    qd: Vec<f64>,
    qd_k: [Vec<f64>; 3],
    a_k: [Vec<f64>; 4],
    /// The state between substeps (see [`TetherConfig::substeps_for`]).
    spare_q: Vec<f64>,
    spare_qd: Vec<f64>,
}

/// What the stepper derives from the current state once and uses several times (the boom before
/// a step, the capture check after it, the held disturbance): recomputed whenever the state
/// changes ([`CaptureSim::refresh`]), never saved.
#[derive(Debug, Clone)]
struct Derived {
    /// Segment centres (n), m.
    centres: Vec<V3>,
    /// The tip (the ACCD's centre of gravity), m.
    tip: V3,
    /// The capture point and its velocity, m and m/s.
    capture_point: (V3, V3),
}

/// One RK4 stage's state: `q = q0 + h rate`, `qd = qd0 + h acc` (slices of one length; the
/// equal lengths let the compiler drop the bounds checks).
#[inline(always)]
fn stage_state(
    q: &mut [f64],
    qd: &mut [f64],
    q0: &[f64],
    qd0: &[f64],
    rate: &[f64],
    acc: &[f64],
    h: f64,
) {
    let n = q.len();
    let (qd, q0, qd0, rate, acc) = (&mut qd[..n], &q0[..n], &qd0[..n], &rate[..n], &acc[..n]);
    for i in 0..n {
        q[i] = q0[i] + h * rate[i];
        qd[i] = qd0[i] + h * acc[i];
    }
}

/// RK4's combination `out = x0 + sixth (k1 + 2 (k2 + k3) + k4)`.
#[inline(always)]
fn combine(
    out: &mut [f64],
    x0: &[f64],
    k1: &[f64],
    k2: &[f64],
    k3: &[f64],
    k4: &[f64],
    sixth: f64,
) {
    let n = out.len();
    let (x0, k1, k2, k3, k4) = (&x0[..n], &k1[..n], &k2[..n], &k3[..n], &k4[..n]);
    for i in 0..n {
        out[i] = x0[i] + sixth * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
    }
}

/// A snapshot of everything a user may want to see, in the TA frame, SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Snapshot {
    /// Time, s.
    pub time: f64,
    /// ACCD centre of gravity (the tether tip), m.
    pub position: V3,
    /// Its velocity, m/s.
    pub velocity: V3,
    /// ACCD attitude (body to TA frame).
    pub attitude: UnitQuaternion<f64>,
    /// Body rates (p, q, r), rad/s.
    pub omega: V3,
    /// Flap deflections (right, left, top, bottom), rad.
    pub deflection: [f64; 4],
    /// Flap commands, rad.
    pub command: [f64; 4],
    /// Capture point (the ACCD's tail), m.
    pub capture_point: V3,
    /// Its velocity, m/s.
    pub capture_point_velocity: V3,
    /// Boom tip, m.
    pub boom_tip: V3,
    /// Boom-tip velocity, m/s.
    pub boom_velocity: V3,
    /// Capture criteria.
    pub capture: CaptureStatus,
    /// Aerodynamic loads on the ACCD at this state.
    pub loads: AeroLoads,
    /// Tension at the attachment, N.
    pub attachment_tension: f64,
    /// Velocity of the TA relative to the air, m/s.
    pub aircraft_velocity: V3,
}

/// One capture episode's physics. Cloning copies everything, random streams included: the clone
/// continues exactly as the original would.
pub struct CaptureSim {
    config: CaptureConfig,
    model: TetherModel,
    aero: Arc<AeroModel>,
    inertia: V3,
    capture_offset: V3,
    tether: TetherState,
    accd: AccdState,
    actuators: Actuators,
    boom: Boom,
    disturbance: Box<dyn AirDisturbance>,
    buffers: Buffers,
    derived: Derived,
    /// The disturbance held at each segment centre and at the tip over a step, for
    /// [`AirSampling::PerStep`]; a function of the step's initial state, so not saved.
    held: Vec<V3>,
    held_tip: V3,
    /// Time of the last state set from outside, s; the episode time is
    /// `time_origin + steps * dt`, free of the drift of summing dt.
    time_origin: f64,
    /// Steps taken since `time_origin`.
    steps: u64,
}

impl Clone for CaptureSim {
    fn clone(&self) -> Self {
        CaptureSim {
            config: self.config.clone(),
            model: self.model.clone(),
            aero: Arc::clone(&self.aero),
            inertia: self.inertia,
            capture_offset: self.capture_offset,
            tether: self.tether.clone(),
            accd: self.accd,
            actuators: self.actuators,
            boom: self.boom.clone(),
            disturbance: self.disturbance.clone_box(),
            buffers: self.buffers.clone(),
            derived: self.derived.clone(),
            held: self.held.clone(),
            held_tip: self.held_tip,
            time_origin: self.time_origin,
            steps: self.steps,
        }
    }
}

impl CaptureSim {
    /// A new episode with the aerodynamic model, wake and turbulence of the config (turbulence
    /// from the wake seed): the tether trails straight back (the paper's initial condition), the
    /// ACCD flies level with the aircraft, flaps neutral, t = 0.
    pub fn new(config: &CaptureConfig, seeds: Seeds) -> Result<Self> {
        config.validate()?;
        let aero = Arc::new(config.accd.aero_model()?);
        let airspeed = config.aircraft.airspeed;
        let wake = Wake::from_config(&config.wake, airspeed)?;
        let turbulence = Turbulence::new(&config.turbulence, airspeed, seeds.wake)?;
        let density = Atmosphere::isa(config.aircraft.altitude)?.density;
        let field = WakeField::from_parts(wake, turbulence, density);
        CaptureSim::with_parts(config, seeds, aero, Box::new(field))
    }

    /// A new episode with a given (shared) aerodynamic model and air disturbance.
    pub fn with_parts(
        config: &CaptureConfig,
        seeds: Seeds,
        aero: Arc<AeroModel>,
        disturbance: Box<dyn AirDisturbance>,
    ) -> Result<Self> {
        config.validate()?;
        let tether_config = config.tether_with_tip();
        let mut model = TetherModel::new(&tether_config)?;
        let tether = TetherState::straight(tether_config.segments, V3::new(-1.0, 0.0, 0.0), 0.0)?;
        let accd = AccdState::default();
        let capture_offset = config.accd.capture_point();
        let (tip, tip_velocity) = model.tip_state(&tether.q, &tether.qd)?;
        let (capture, _) = capture_point(&tip, &tip_velocity, &accd, &capture_offset);
        let dofs = model.dofs();
        let z = || vec![0.0; dofs];
        let mut sim = CaptureSim {
            inertia: config.accd.principal_inertia(),
            capture_offset,
            boom: Boom::new(&config.boom, seeds.rlv, capture.x),
            config: config.clone(),
            model,
            aero,
            tether,
            accd,
            actuators: Actuators::default(),
            disturbance,
            buffers: Buffers {
                q: z(),
                qd: z(),
                qd_k: [z(), z(), z()],
                a_k: [z(), z(), z(), z()],
                spare_q: z(),
                spare_qd: z(),
            },
            derived: Derived {
                centres: vec![V3::zeros(); tether_config.segments],
                tip,
                capture_point: (capture, V3::zeros()),
            },
            held: vec![V3::zeros(); tether_config.segments],
            held_tip: V3::zeros(),
            time_origin: 0.0,
            steps: 0,
        };
        sim.refresh()?;
        Ok(sim)
    }

    /// Recomputes what is derived from the state (one walk along the chain): after every change
    /// of the tether's or the ACCD's state.
    /// Per-stage sampling keeps the original scalar walk (its results are bitwise those of the
    /// first version); per-step sampling uses the kinematics pass with vectorised sin/cos.
    fn refresh(&mut self) -> Result<()> {
        let d = &mut self.derived;
        let (q, qd) = (&self.tether.q, &self.tether.qd);
        let (position, velocity) = match self.config.wake.sampling {
            AirSampling::PerStage => self.model.centres_and_tip(q, qd, &mut d.centres)?,
            AirSampling::PerStep => self.model.centres_and_tip_batch(q, qd, &mut d.centres)?,
        };
        d.tip = position;
        d.capture_point = capture_point(&position, &velocity, &self.accd, &self.capture_offset);
        Ok(())
    }

    /// The capture point and its velocity at the current state (TA frame, m and m/s).
    fn capture_point_state(&self) -> (V3, V3) {
        self.derived.capture_point
    }

    /// The configuration.
    pub fn config(&self) -> &CaptureConfig {
        &self.config
    }

    /// Simulation time, s.
    pub fn time(&self) -> f64 {
        self.tether.time
    }

    /// The tether's state.
    pub fn tether_state(&self) -> &TetherState {
        &self.tether
    }

    /// The ACCD's attitude and rates.
    pub fn accd_state(&self) -> &AccdState {
        &self.accd
    }

    /// Replaces the ACCD's attitude and rates (e.g. to test its stability).
    pub fn set_accd_state(&mut self, state: AccdState) -> Result<()> {
        Self::check_accd_state(&state)?;
        self.accd = state;
        self.refresh()
    }

    fn check_accd_state(state: &AccdState) -> Result<()> {
        if !(state.attitude.coords.iter().all(|v| v.is_finite())
            && state.omega.iter().all(|v| v.is_finite()))
        {
            return Err(SimError::invalid_config(
                "accd_state",
                format!("{state:?}"),
                "finite values",
            ));
        }
        Ok(())
    }

    /// Replaces the tether's state (its time becomes the episode's time).
    pub fn set_tether_state(&mut self, state: TetherState) -> Result<()> {
        if state.q.len() != self.model.dofs() {
            return Err(accd_tether::TetherError::WrongSize {
                what: "tether state",
                expected: self.model.dofs(),
                found: state.q.len(),
            }
            .into());
        }
        state.validate()?;
        self.time_origin = state.time;
        self.steps = 0;
        self.tether = state;
        self.refresh()
    }

    /// Starts a new episode at t = 0 from the tether state `tether` (its time is ignored) and
    /// the ACCD state `accd`, flaps neutral, the boom and the air disturbance restarted from
    /// `seeds`. Allocates nothing.
    pub fn reset(&mut self, seeds: Seeds, tether: &TetherState, accd: AccdState) -> Result<()> {
        if tether.q.len() != self.model.dofs() || tether.qd.len() != self.model.dofs() {
            return Err(accd_tether::TetherError::WrongSize {
                what: "tether state",
                expected: self.model.dofs(),
                found: tether.q.len().min(tether.qd.len()),
            }
            .into());
        }
        tether.validate()?;
        Self::check_accd_state(&accd)?;
        self.accd = accd;
        self.tether.q.copy_from_slice(&tether.q);
        self.tether.qd.copy_from_slice(&tether.qd);
        self.tether.time = 0.0;
        self.time_origin = 0.0;
        self.steps = 0;
        self.actuators = Actuators::default();
        self.refresh()?;
        let x = self.capture_point_state().0.x;
        self.boom = Boom::new(&self.config.boom, seeds.rlv, x);
        self.disturbance.reset(seeds.wake);
        if self.config.wake.sampling == AirSampling::PerStage {
            // The stages sample where the tether moves: generate the field everywhere.
            self.disturbance.prepare_all();
        }
        Ok(())
    }

    /// The episode's dynamic state (tether, ACCD, flaps, boom, air disturbance, clock); the
    /// configuration is not included.
    pub fn state(&self) -> CaptureState {
        let coords = &self.accd.attitude.coords;
        CaptureState {
            time_origin: self.time_origin,
            steps: self.steps,
            time: self.tether.time,
            q: self.tether.q.clone(),
            qd: self.tether.qd.clone(),
            attitude: [coords[0], coords[1], coords[2], coords[3]],
            omega: self.accd.omega.into(),
            flap_command: self.actuators.command,
            flap_deflection: self.actuators.deflection,
            boom: self.boom.state(),
            air: self.disturbance.state(),
        }
    }

    /// Restores a state from [`CaptureSim::state`] of an episode with the same configuration;
    /// it then continues bit for bit as the saved one would. The state is checked whole
    /// (lengths, the disturbance's structure) before anything changes: on an error the
    /// episode is as it was.
    pub fn set_state(&mut self, state: CaptureState) -> Result<()> {
        let mut next = self.clone();
        next.apply_state(state)?;
        *self = next;
        Ok(())
    }

    /// [`CaptureSim::set_state`] without the copy: on an error `self` may be half restored
    /// (callers restore into a copy).
    pub(crate) fn apply_state(&mut self, state: CaptureState) -> Result<()> {
        let dofs = self.model.dofs();
        check_len("sim.q", state.q.len(), dofs)?;
        check_len("sim.qd", state.qd.len(), dofs)?;
        self.disturbance.set_state(state.air)?;
        self.time_origin = state.time_origin;
        self.steps = state.steps;
        self.tether.time = state.time;
        self.tether.q.copy_from_slice(&state.q);
        self.tether.qd.copy_from_slice(&state.qd);
        let [i, j, k, w] = state.attitude;
        self.accd = AccdState {
            attitude: UnitQuaternion::new_unchecked(Quaternion::new(w, i, j, k)),
            omega: V3::from(state.omega),
        };
        self.actuators.command = state.flap_command;
        self.actuators.deflection = state.flap_deflection;
        self.boom.set_state(&state.boom);
        self.refresh()
    }

    /// The state behind a header ([`crate::state_format`], kind
    /// [`StateKind::CaptureSim`](crate::state_format::StateKind::CaptureSim), the hash of the
    /// configuration).
    pub fn save(&self) -> Result<Vec<u8>> {
        use crate::state_format::{config_hash, encode, StateKind};
        let hash = config_hash(&self.config)?;
        Ok(encode(StateKind::CaptureSim, &hash, 1, &self.state())?)
    }

    /// Restores a state from [`CaptureSim::save`]: a corrupted, truncated or foreign blob (of
    /// another kind or configuration) is a [`SimError::State`] naming what is wrong, and
    /// changes nothing.
    pub fn load(&mut self, bytes: &[u8]) -> Result<()> {
        use crate::state_format::{config_hash, decode, Expected, StateKind};
        let expected = Expected {
            kind: StateKind::CaptureSim,
            config_hash: config_hash(&self.config)?,
            num_envs: 1,
        };
        self.set_state(decode(bytes, &expected)?)
    }

    /// The flap actuators.
    pub fn actuators(&self) -> &Actuators {
        &self.actuators
    }

    /// Fixed physics step, s.
    pub fn time_step(&self) -> f64 {
        self.config.tether.time_step
    }

    fn air_at_step(&self) -> Result<AirAtStep> {
        let altitude = self.config.aircraft.altitude_at(self.tether.time);
        let here = Atmosphere::isa(altitude.clamp(-500.0, 20_000.0))?;
        let below = Atmosphere::isa((altitude - 100.0).clamp(-500.0, 20_000.0))?;
        Ok(AirAtStep {
            density: here.density,
            density_per_depth: (below.density - here.density) / 100.0,
        })
    }

    /// The surroundings of the current step (with the ACCD's current state), the tether model and
    /// the stage buffers, borrowed apart so that the model can run while the stage is alive.
    fn parts(&mut self) -> Result<(Stage<'_>, &mut TetherModel, &mut Buffers)> {
        self.parts_with(false)
    }

    /// [`CaptureSim::parts`]; with `hold`, the segments see the disturbance held in the buffers.
    fn parts_with(&mut self, hold: bool) -> Result<(Stage<'_>, &mut TetherModel, &mut Buffers)> {
        let air = self.air_at_step()?;
        if !hold {
            // The stage samples the disturbance at the current state's points.
            self.disturbance.prepare(&self.derived.centres);
            self.disturbance
                .prepare(std::slice::from_ref(&self.derived.tip));
        }
        let (model, buffers) = (&mut self.model, &mut self.buffers);
        let held = hold.then_some((&self.held[..], self.held_tip));
        let stage = Stage {
            aircraft: &self.config.aircraft,
            air,
            disturbance: self.disturbance.as_ref(),
            aero: &self.aero,
            accd: self.accd,
            deflection: self.actuators.deflection,
            loads: Cell::new(AeroLoads::default()),
            held,
        };
        Ok((stage, model, buffers))
    }

    /// Samples the disturbance at the segment centres of the current state into the held
    /// buffer ([`AirSampling::PerStep`]).
    fn hold_disturbance(&mut self, time: f64) {
        let d = &self.derived;
        self.disturbance.prepare(&d.centres);
        self.disturbance.prepare(std::slice::from_ref(&d.tip));
        for (held, centre) in self.held.iter_mut().zip(&d.centres) {
            *held = self.disturbance.velocity(time, centre);
        }
        self.held_tip = self.disturbance.velocity(time, &d.tip);
    }

    /// Derivatives at one stage: tether accelerations into `qdd`, and the quaternion and body-rate
    /// rates returned.
    #[allow(clippy::too_many_arguments)]
    fn stage(
        model: &mut TetherModel,
        stage: &mut Stage<'_>,
        inertia: &V3,
        time: f64,
        q: &[f64],
        qd: &[f64],
        quat: &Quaternion<f64>,
        omega: &V3,
        qdd: &mut [f64],
    ) -> Result<(Quaternion<f64>, V3)> {
        stage.accd = AccdState {
            attitude: UnitQuaternion::new_normalize(*quat),
            omega: *omega,
        };
        model.accelerations(time, q, qd, &*stage, qdd)?;
        let loads = stage.loads.get();
        let omega_dot = angular_acceleration(inertia, omega, &loads.moment);
        let quat_dot = quat * Quaternion::from_parts(0.0, *omega) * 0.5;
        Ok((quat_dot, omega_dot))
    }

    /// Advances one physics step with the flap commands `command` (rad; clipped to the limit).
    /// On error the episode keeps its last good state.
    pub fn step(&mut self, command: [f64; 4]) -> Result<()> {
        let dt = self.time_step();
        let t = self.tether.time;
        self.actuators.set_command(&self.config.accd, command)?;
        self.actuators.advance(&self.config.accd, dt);
        // Only an approaching RLV needs to know where the capture point is.
        let capture_x = if self.boom.approaching() {
            Some(self.capture_point_state().0.x)
        } else {
            None
        };
        self.boom.advance(t, dt, capture_x);
        self.disturbance.advance(t, dt)?;
        // Substeps for the chain's fastest mode (one at the default discretization).
        let k = self.substeps();
        if k > accd_tether::config::MAX_SUBSTEPS {
            return Err(SimError::Diverged {
                time: t,
                reason: format!(
                    "the tether's fastest mode needs {k} RK4 substeps per step (at most {})",
                    accd_tether::config::MAX_SUBSTEPS
                ),
            });
        }
        // Per-step sampling: the disturbance at the step's start, held over every (sub)step.
        if self.config.wake.sampling == AirSampling::PerStep {
            self.hold_disturbance(t);
        }
        // The state is read while the stage buffers are written: lend it out for the step.
        let q0 = std::mem::take(&mut self.tether.q);
        let qd0 = std::mem::take(&mut self.tether.qd);
        let h = dt / k as f64;
        let mut result = self.integrate(t, h, &q0, &qd0);
        if k > 1 {
            let accd0 = self.accd;
            let mut q = std::mem::take(&mut self.buffers.spare_q);
            let mut qd = std::mem::take(&mut self.buffers.spare_qd);
            for j in 1..k {
                let Ok((attitude, omega)) = result else { break };
                self.accd = AccdState {
                    attitude: UnitQuaternion::new_normalize(attitude),
                    omega,
                };
                std::mem::swap(&mut q, &mut self.buffers.q);
                std::mem::swap(&mut qd, &mut self.buffers.qd);
                result = self.integrate(t + j as f64 * h, h, &q, &qd);
            }
            self.buffers.spare_q = q;
            self.buffers.spare_qd = qd;
            if result.is_err() {
                self.accd = accd0;
            }
        }
        match result {
            Ok((attitude, omega)) => {
                // The new state is in the buffers; the old vectors become the next buffers.
                self.tether.q = std::mem::replace(&mut self.buffers.q, q0);
                self.tether.qd = std::mem::replace(&mut self.buffers.qd, qd0);
                self.steps += 1;
                self.tether.time = self.time_origin + self.steps as f64 * dt;
                self.accd = AccdState {
                    attitude: UnitQuaternion::new_normalize(attitude),
                    omega,
                };
                self.refresh()
            }
            Err(e) => {
                self.tether.q = q0;
                self.tether.qd = qd0;
                Err(e)
            }
        }
    }

    /// One RK4 step of the coupled state from (q0, qd0) and the current ACCD state; writes the new
    /// tether state into the buffers and returns the new (unnormalised) quaternion and body rates.
    fn integrate(
        &mut self,
        t: f64,
        dt: f64,
        q0: &[f64],
        qd0: &[f64],
    ) -> Result<(Quaternion<f64>, V3)> {
        let inertia = self.inertia;
        let (att0, w0) = (*self.accd.attitude.quaternion(), self.accd.omega);
        let hold = self.config.wake.sampling == AirSampling::PerStep;
        let (mut stage, model, b) = self.parts_with(hold)?;
        let h = 0.5 * dt;

        let (dq1, dw1) = Self::stage(
            model,
            &mut stage,
            &inertia,
            t,
            q0,
            qd0,
            &att0,
            &w0,
            &mut b.a_k[0],
        )?;
        stage_state(&mut b.q, &mut b.qd_k[0], q0, qd0, qd0, &b.a_k[0], h);
        let (att, w) = (att0 + dq1 * h, w0 + dw1 * h);
        let (dq2, dw2) = Self::stage(
            model,
            &mut stage,
            &inertia,
            t + h,
            &b.q,
            &b.qd_k[0],
            &att,
            &w,
            &mut b.a_k[1],
        )?;
        {
            let [k0, k1, _] = &mut b.qd_k;
            stage_state(&mut b.q, k1, q0, qd0, k0, &b.a_k[1], h);
        }
        let (att, w) = (att0 + dq2 * h, w0 + dw2 * h);
        let (dq3, dw3) = Self::stage(
            model,
            &mut stage,
            &inertia,
            t + h,
            &b.q,
            &b.qd_k[1],
            &att,
            &w,
            &mut b.a_k[2],
        )?;
        {
            let [_, k1, k2] = &mut b.qd_k;
            stage_state(&mut b.q, k2, q0, qd0, k1, &b.a_k[2], dt);
        }
        let (att, w) = (att0 + dq3 * dt, w0 + dw3 * dt);
        let (dq4, dw4) = Self::stage(
            model,
            &mut stage,
            &inertia,
            t + dt,
            &b.q,
            &b.qd_k[2],
            &att,
            &w,
            &mut b.a_k[3],
        )?;

        let sixth = dt / 6.0;
        combine(&mut b.q, q0, qd0, &b.qd_k[0], &b.qd_k[1], &b.qd_k[2], sixth);
        combine(
            &mut b.qd, qd0, &b.a_k[0], &b.a_k[1], &b.a_k[2], &b.a_k[3], sixth,
        );
        let att = att0 + (dq1 + (dq2 + dq3) * 2.0 + dq4) * sixth;
        let w = w0 + (dw1 + (dw2 + dw3) * 2.0 + dw4) * sixth;
        let finite = b.q.iter().chain(b.qd.iter()).all(|v| v.is_finite())
            && att.coords.iter().all(|v| v.is_finite())
            && w.iter().all(|v| v.is_finite())
            && att.norm() > 0.0;
        if !finite {
            return Err(SimError::Diverged {
                time: t + dt,
                reason: "state became non-finite".into(),
            });
        }
        Ok((att, w))
    }

    /// RK4 substeps of the next step ([`TetherConfig::substeps_for`]) under the load of the
    /// current state ([`accd_tether::config::StepLoad::of_state`], the ACCD as tip mass), with
    /// sea-level density (an upper bound) at the aircraft's airspeed. One for the default
    /// configuration.
    pub fn substeps(&self) -> usize {
        let c = &self.config.tether;
        let load = accd_tether::config::StepLoad::of_state(
            c,
            &self.tether,
            self.config.accd.mass,
            SEA_LEVEL_DENSITY,
            self.config.aircraft.airspeed,
        );
        c.substeps_for(&load)
    }

    /// Steps `steps` times with the same commands.
    pub fn step_many(&mut self, steps: usize, command: [f64; 4]) -> Result<()> {
        for _ in 0..steps {
            self.step(command)?;
        }
        Ok(())
    }

    /// Tension at the attachment from the axial element, `k s + c s'`, N.
    pub fn attachment_tension(&self) -> f64 {
        let c = &self.config.tether;
        c.axial_stiffness * self.tether.q[0] + c.axial_damping() * self.tether.qd[0]
    }

    /// The capture criteria at the current state (cheaper than a [`CaptureSim::snapshot`]: no
    /// aerodynamics).
    pub fn capture_status(&mut self) -> Result<CaptureStatus> {
        let (point, point_velocity) = self.capture_point_state();
        Ok(CaptureStatus::evaluate(
            &self.config.boom,
            &point,
            &point_velocity,
            &self.boom.tip(self.tether.time),
            &self.boom.velocity(),
        ))
    }

    /// Everything observable about the current state.
    pub fn snapshot(&mut self) -> Result<Snapshot> {
        let t = self.tether.time;
        let (position, velocity) = self.model.tip_state(&self.tether.q, &self.tether.qd)?;
        let (stage, _, _) = self.parts()?;
        stage.tip_force(t, &position, &velocity);
        let loads = stage.loads.get();
        let attitude = self.accd.attitude;
        let (capture_point, capture_point_velocity) =
            capture_point(&position, &velocity, &self.accd, &self.capture_offset);
        let boom_tip = self.boom.tip(t);
        let boom_velocity = self.boom.velocity();
        Ok(Snapshot {
            time: t,
            position,
            velocity,
            attitude,
            omega: self.accd.omega,
            deflection: self.actuators.deflection,
            command: self.actuators.command,
            capture_point,
            capture_point_velocity,
            boom_tip,
            boom_velocity,
            capture: CaptureStatus::evaluate(
                &self.config.boom,
                &capture_point,
                &capture_point_velocity,
                &boom_tip,
                &boom_velocity,
            ),
            loads,
            attachment_tension: self.attachment_tension(),
            aircraft_velocity: self.config.aircraft.velocity(t),
        })
    }

    /// Tension along the chain at the current state (n + 1 values, N; see
    /// [`accd_tether::TetherModel::tensions`]).
    pub fn tensions(&mut self, out: &mut [f64]) -> Result<()> {
        let t = self.tether.time;
        let q = std::mem::take(&mut self.tether.q);
        let qd = std::mem::take(&mut self.tether.qd);
        let result = self.parts().and_then(|(stage, model, buffers)| {
            Ok(model.tensions(t, &q, &qd, &stage, &mut buffers.a_k[0], out)?)
        });
        self.tether.q = q;
        self.tether.qd = qd;
        result
    }

    /// Joint positions of the tether (n + 1 points, m; see
    /// [`accd_tether::TetherModel::joint_positions`]).
    pub fn joint_positions(&self, out: &mut [V3]) -> Result<()> {
        Ok(self.model.joint_positions(&self.tether.q, out)?)
    }
}
