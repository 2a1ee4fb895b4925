//! One capture episode: the tether (with the ACCD's mass at its tip), the ACCD's attitude
//! dynamics and flaps, the towing aircraft's flight, the air (free stream plus any disturbance:
//! wake, turbulence) and the RLV's boom, stepped together.
//!
//! # Integration
//! The tether coordinates and the ACCD's attitude quaternion and body rates form one state,
//! advanced by the tether crate's one RK4 ([`accd_tether::Rk4`] over the [`System`] `Coupled`)
//! at the tether's fixed step (0.01 s by default). At every stage the
//! ACCD's aerodynamic force (from its attitude, rates, flaps and the air at its position) enters
//! the tether as the tip force, and its moment drives Euler's equations. Once per step, before
//! the RK4 stages: the flap actuators, the boom and the air disturbance advance, and the air
//! density is taken from ISA at the aircraft's altitude (varying linearly with depth below it).
//! The quaternion is renormalised after each step.

use std::sync::Arc;

use accd_tether::{
    Atmosphere, AxialStage, AxialSystem, Rk4, Rosenbrock, Surroundings, System, TetherModel,
    TetherState,
};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::config::CaptureConfig;
use crate::error::{Result, SimError};
use crate::physics::accd::{aero_loads, angular_acceleration, AccdState, Actuators, AeroLoads};
use crate::physics::aero::AeroModel;
use crate::physics::air::{AirDisturbance, AirState};
use crate::physics::aircraft::AircraftConfig;
use crate::physics::boom::{Boom, BoomState, CaptureStatus};
use crate::physics::turbulence::Turbulence;
use crate::physics::wake::{AirSampling, Wake};
use crate::physics::wake_field::WakeField;
use crate::rng::Seeds;
use crate::state_format::check_len;
use crate::valid::Valid;

type V3 = Vector3<f64>;

/// ISA sea-level density, kg/m^3: the densest air an episode meets, for stability estimates.
const SEA_LEVEL_DENSITY: f64 = 1.225;

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
/// loads, the moment for the attitude equations among them, are the tip report).
struct Stage<'a> {
    aircraft: &'a AircraftConfig,
    air: AirAtStep,
    disturbance: &'a dyn AirDisturbance,
    aero: &'a AeroModel,
    accd: AccdState,
    deflection: [f64; 4],
    /// With [`AirSampling::PerStep`]: the disturbance at each segment centre and at the tip,
    /// sampled once at the step's initial state and held over the stages.
    held: Option<(&'a [V3], V3)>,
}

impl Surroundings for Stage<'_> {
    type TipReport = AeroLoads;

    fn air_velocity(&self, time: f64, position: &V3) -> V3 {
        -self.aircraft.velocity(time) + self.disturbance.velocity(time, position)
    }
    #[inline(always)]
    fn held_segment_air(&self, time: f64) -> Option<(V3, &[V3])> {
        self.held
            .map(|(held, _)| (-self.aircraft.velocity(time), held))
    }
    fn air_density(&self, _time: f64, position: &V3) -> f64 {
        self.air.density + self.air.density_per_depth * position.z
    }
    fn frame_acceleration(&self, time: f64) -> V3 {
        self.aircraft.acceleration(time)
    }
    fn tip_force(&self, time: f64, position: &V3, velocity: &V3) -> V3 {
        self.tip_loads(time, position, velocity).0
    }
    fn tip_loads(&self, time: f64, position: &V3, velocity: &V3) -> (V3, AeroLoads) {
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
        (loads.force, loads)
    }
}

/// The first-order states of the coupled system: the ACCD's attitude quaternion (coordinates
/// i, j, k, w) and body rates (rad/s).
const ACCD_STATES: usize = 7;

/// The ACCD state as first-order states.
fn accd_to_states(accd: &AccdState) -> [f64; ACCD_STATES] {
    let q = accd.attitude.coords;
    let w = accd.omega;
    [q[0], q[1], q[2], q[3], w.x, w.y, w.z]
}

/// The (unnormalised) quaternion and body rates of first-order states.
fn states_to_parts(x: &[f64]) -> (Quaternion<f64>, V3) {
    (
        Quaternion::new(x[3], x[0], x[1], x[2]),
        V3::new(x[4], x[5], x[6]),
    )
}

/// The capture system as the integrator sees it: the tether's coordinates, and the ACCD's
/// attitude and rates as first-order states. At every stage the ACCD's aerodynamic loads at the
/// stage's attitude enter the tether as its tip force and come back (the tip report) to drive
/// Euler's equations and the quaternion kinematics `q' = q (0, omega) / 2`.
struct Coupled<'a> {
    model: &'a mut TetherModel,
    stage: Stage<'a>,
    inertia: V3,
}

impl Coupled<'_> {
    /// Sets the stage's ACCD state from the first-order states `x` (quaternion, body rates) and
    /// returns them, for [`System::derivatives`] and [`AxialSystem::derivatives_axial`] alike.
    #[inline(always)]
    fn take_attitude(&mut self, x: &[f64]) -> (Quaternion<f64>, V3) {
        let (quat, omega) = states_to_parts(x);
        self.stage.accd = AccdState {
            attitude: UnitQuaternion::new_normalize(quat),
            omega,
        };
        (quat, omega)
    }
}

impl System for Coupled<'_> {
    fn dofs(&self) -> usize {
        self.model.dofs()
    }

    fn first_order_states(&self) -> usize {
        ACCD_STATES
    }

    fn derivatives(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        x: &[f64],
        qdd: &mut [f64],
        xd: &mut [f64],
    ) -> accd_tether::Result<()> {
        let (quat, omega) = self.take_attitude(x);
        let loads = self.model.accelerations(time, q, qd, &self.stage, qdd)?;
        accd_rates(&self.inertia, (quat, omega), &loads, xd);
        Ok(())
    }

    /// Renormalises the quaternion (after every step; the integrator has checked that it is
    /// finite); a zero quaternion is a divergence.
    fn project(&self, time: f64, x: &mut [f64]) -> accd_tether::Result<()> {
        let (quat, _) = states_to_parts(x);
        if quat.norm() == 0.0 {
            return Err(accd_tether::TetherError::Diverged {
                time,
                reason: "the ACCD's attitude quaternion vanished".into(),
            });
        }
        let unit = UnitQuaternion::new_normalize(quat);
        x[..4].copy_from_slice(unit.coords.as_slice());
        Ok(())
    }
}

/// The stage solve of the linearly implicit step ([`accd_tether::Scheme::ImplicitAxial`]): the
/// tether's with its axial spring-dampers implicit, the ACCD's rates explicit, as in
/// [`System::derivatives`].
impl AxialSystem for Coupled<'_> {
    fn is_axial(&self, i: usize) -> bool {
        self.model.is_stretch_coordinate(i)
    }

    fn derivatives_axial(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        x: &[f64],
        axial: &AxialStage<'_>,
        qdd: &mut [f64],
        xd: &mut [f64],
    ) -> accd_tether::Result<()> {
        let (quat, omega) = self.take_attitude(x);
        let loads = self
            .model
            .accelerations_axial(time, q, qd, axial, &self.stage, qdd)?;
        accd_rates(&self.inertia, (quat, omega), &loads, xd);
        Ok(())
    }
}

/// The ACCD's first-order rates (quaternion kinematics, Euler's equations) under `loads`.
#[inline(always)]
fn accd_rates(
    inertia: &V3,
    (quat, omega): (Quaternion<f64>, V3),
    loads: &AeroLoads,
    xd: &mut [f64],
) {
    let omega_dot = angular_acceleration(inertia, &omega, &loads.moment);
    let quat_dot = quat * Quaternion::from_parts(0.0, omega) * 0.5;
    xd[..4].copy_from_slice(quat_dot.coords.as_slice());
    xd[4..].copy_from_slice(omega_dot.as_slice());
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
    /// The boom tip's nominal position, TA frame, m ([`crate::BoomConfig::nominal`]).
    boom_nominal: V3,
    disturbance: Box<dyn AirDisturbance>,
    rk4: Rk4,
    /// The Rosenbrock-W buffers, for [`accd_tether::Scheme::ImplicitAxial`] only.
    rosenbrock: Option<Rosenbrock>,
    /// Accelerations computed along with the tensions.
    qdd: Vec<f64>,
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
            boom_nominal: self.boom_nominal,
            disturbance: self.disturbance.clone_box(),
            rk4: self.rk4.clone(),
            rosenbrock: self.rosenbrock.clone(),
            qdd: self.qdd.clone(),
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
    pub fn new(config: &Valid<CaptureConfig>, seeds: Seeds) -> Result<Self> {
        let aero = Arc::new(config.accd.aero_model()?);
        let wake = Wake::from_config(&config.wake, config.aircraft.airspeed)?;
        CaptureSim::with_model(config, seeds, aero, wake)
    }

    /// [`CaptureSim::new`] with the aerodynamic model and the mean wake already built from the
    /// config (`config.accd.aero_model()`, `Wake::from_config(&config.wake, airspeed)`): the
    /// same simulation, for callers that build several of one configuration.
    pub fn with_model(
        config: &Valid<CaptureConfig>,
        seeds: Seeds,
        aero: Arc<AeroModel>,
        wake: Wake,
    ) -> Result<Self> {
        let field = Self::field(config, seeds, wake, true)?;
        CaptureSim::with_parts(config, seeds, aero, Box::new(field))
    }

    /// [`CaptureSim::with_model`] for a simulation that is [reset](CaptureSim::reset) before
    /// its first step: its turbulence generates its wake lanes at the reset and after (on
    /// demand, where they are sampled) instead of all of them now, which the reset would
    /// discard. From the reset on, the same simulation to the last bit.
    pub fn with_model_for_reset(
        config: &Valid<CaptureConfig>,
        seeds: Seeds,
        aero: Arc<AeroModel>,
        wake: Wake,
    ) -> Result<Self> {
        let field = Self::field(config, seeds, wake, false)?;
        CaptureSim::with_parts(config, seeds, aero, Box::new(field))
    }

    /// The air of a new simulation: the mean wake and the turbulence from the wake seed, with
    /// every wake lane generated (`all_lanes`) or none yet.
    fn field(
        config: &Valid<CaptureConfig>,
        seeds: Seeds,
        wake: Wake,
        all_lanes: bool,
    ) -> Result<WakeField> {
        let airspeed = config.aircraft.airspeed;
        let turbulence = Turbulence::new(&config.turbulence, airspeed, seeds.wake)?;
        let density = Atmosphere::isa(config.aircraft.altitude)?.density;
        Ok(if all_lanes {
            WakeField::from_parts(wake, turbulence, density)
        } else {
            WakeField::on_demand(wake, turbulence, density)
        })
    }

    /// A new episode with a given (shared) aerodynamic model and air disturbance.
    pub fn with_parts(
        config: &Valid<CaptureConfig>,
        seeds: Seeds,
        aero: Arc<AeroModel>,
        disturbance: Box<dyn AirDisturbance>,
    ) -> Result<Self> {
        let tether_config = config.tether_with_tip();
        let mut model = TetherModel::new(&tether_config)?;
        let tether = TetherState::straight(tether_config.segments, V3::new(-1.0, 0.0, 0.0), 0.0)?;
        let tether = if tether_config.is_distributed() {
            tether.to_distributed()?
        } else {
            tether
        };
        let accd = AccdState::default();
        let capture_offset = config.accd.capture_point();
        let (tip, tip_velocity) = model.tip_state(&tether.q, &tether.qd)?;
        let (capture, _) = capture_point(&tip, &tip_velocity, &accd, &capture_offset);
        let dofs = model.dofs();
        let rk4 = Rk4::new(dofs, ACCD_STATES);
        let mut sim = CaptureSim {
            inertia: config.accd.principal_inertia(),
            capture_offset,
            boom: Boom::new(
                &config.boom,
                seeds.rlv,
                capture.x,
                &config.boom.offset.into(),
            ),
            boom_nominal: config.boom.offset.into(),
            config: CaptureConfig::clone(config),
            model,
            aero,
            tether,
            accd,
            actuators: Actuators::default(),
            disturbance,
            rk4,
            rosenbrock: (tether_config.scheme == accd_tether::Scheme::ImplicitAxial)
                .then(|| Rosenbrock::new(dofs, ACCD_STATES)),
            qdd: vec![0.0; dofs],
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
        state.validate_for(self.model.segments())?;
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
        tether.validate_for(self.model.segments())?;
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
        self.boom = Boom::new(&self.config.boom, seeds.rlv, x, &self.boom_nominal);
        self.disturbance.reset(seeds.wake);
        if self.config.wake.sampling == AirSampling::PerStage {
            // The stages sample where the tether moves: generate the field everywhere.
            self.disturbance.prepare_all();
        }
        Ok(())
    }

    /// Sets where the boom's formation sits (TA frame, m; [`crate::BoomConfig::nominal`]) from
    /// the next [`CaptureSim::reset`] on. A new sim places it at `boom.offset` (an episode sets
    /// it from its equilibrium, [`crate::Equilibrium::boom_nominal`]).
    pub fn set_boom_nominal(&mut self, nominal: V3) -> Result<()> {
        if !nominal.iter().all(|v| v.is_finite()) {
            return Err(SimError::invalid_config(
                "boom_nominal",
                format!("{nominal:?}"),
                "finite values",
            ));
        }
        self.boom_nominal = nominal;
        Ok(())
    }

    /// The boom's nominal tip position (TA frame, m) episodes start from.
    pub fn boom_nominal(&self) -> V3 {
        self.boom_nominal
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

    /// The surroundings of the current step (with the ACCD's current state) and the tether
    /// model, borrowed apart so that the model can run while the stage is alive; with `hold`
    /// ([`AirSampling::PerStep`]), the segments and the tip see the disturbance held over the
    /// step, otherwise the disturbance is prepared at the current state's points.
    fn parts(&mut self, hold: bool) -> Result<(Stage<'_>, &mut TetherModel, &mut Rk4)> {
        let air = self.air_at_step()?;
        if !hold {
            // The stage samples the disturbance at the current state's points.
            self.disturbance.prepare(&self.derived.centres);
            self.disturbance
                .prepare(std::slice::from_ref(&self.derived.tip));
        }
        let held = hold.then_some((&self.held[..], self.held_tip));
        let stage = Stage {
            aircraft: &self.config.aircraft,
            air,
            disturbance: self.disturbance.as_ref(),
            aero: &self.aero,
            accd: self.accd,
            deflection: self.actuators.deflection,
            held,
        };
        Ok((stage, &mut self.model, &mut self.rk4))
    }

    /// Samples the disturbance at the segment centres of the current state into the held
    /// buffer ([`AirSampling::PerStep`]).
    fn hold_disturbance(&mut self, time: f64) {
        let d = &self.derived;
        self.disturbance.prepare(&d.centres);
        self.disturbance.prepare(std::slice::from_ref(&d.tip));
        self.disturbance
            .velocities(time, &d.centres, &mut self.held);
        self.held_tip = self.disturbance.velocity(time, &d.tip);
    }

    /// Advances one physics step with the flap commands `command` (rad; clipped to the limit).
    /// On error the episode keeps its last good state.
    pub fn step(&mut self, command: [f64; 4]) -> Result<()> {
        let start = self.begin_step(command)?;
        self.step_from(start)
    }

    /// Everything of a step before the RK4: the command and the flaps, the boom, the air
    /// disturbance (and, per-step sampling, its held samples).
    fn begin_step(&mut self, command: [f64; 4]) -> Result<StepStart> {
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
        // Per-step sampling: the disturbance at the step's start, held over every (sub)step.
        let hold = self.config.wake.sampling == AirSampling::PerStep;
        if hold {
            self.hold_disturbance(t);
        }
        Ok(StepStart { time: t, dt, hold })
    }

    /// The rest of [`CaptureSim::step`] after [`CaptureSim::begin_step`]: the RK4 of the
    /// coupled system, then [`CaptureSim::end_step`].
    fn step_from(&mut self, start: StepStart) -> Result<()> {
        let mut x = accd_to_states(&self.accd);
        // The state is advanced while the stage borrows the rest: lend it out for the step.
        let mut q = std::mem::take(&mut self.tether.q);
        let mut qd = std::mem::take(&mut self.tether.qd);
        let (inertia, choose) = (self.inertia, self.substep_rule(start.time));
        if let Some(mut rosenbrock) = self.rosenbrock.take() {
            // The substeps from the state alone (the stage matrix depends on the step length).
            let result = self.parts(start.hold).and_then(|(stage, model, _)| {
                let substeps = choose.substeps(model, &q, &qd)?;
                let mut system = Coupled {
                    model,
                    stage,
                    inertia,
                };
                rosenbrock.advance(
                    &mut system,
                    start.time,
                    start.dt,
                    substeps,
                    &mut q,
                    &mut qd,
                    &mut x,
                )?;
                Ok(())
            });
            self.rosenbrock = Some(rosenbrock);
            return self.end_step(start, q, qd, &x, result);
        }
        let result = self.parts(start.hold).and_then(|(stage, model, rk4)| {
            let mut system = Coupled {
                model,
                stage,
                inertia,
            };
            rk4.advance_adaptive(
                &mut system,
                start.time,
                start.dt,
                &mut q,
                &mut qd,
                &mut x,
                |s, q, qd| choose.substeps(s.model, q, qd),
            )?;
            Ok(())
        });
        self.end_step(start, q, qd, &x, result)
    }

    /// Everything of a step after the RK4: the state back, the clock, the ACCD, the derived
    /// quantities; on error only the state back.
    fn end_step(
        &mut self,
        start: StepStart,
        q: Vec<f64>,
        qd: Vec<f64>,
        x: &[f64],
        result: Result<()>,
    ) -> Result<()> {
        self.tether.q = q;
        self.tether.qd = qd;
        result?;
        self.steps += 1;
        self.tether.time = self.time_origin + self.steps as f64 * start.dt;
        let (attitude, omega) = states_to_parts(x);
        self.accd = AccdState {
            attitude: UnitQuaternion::new_unchecked(attitude),
            omega,
        };
        self.refresh()
    }

    /// How a step from `time` chooses its substeps.
    fn substep_rule(&self, time: f64) -> SubstepRule {
        SubstepRule {
            time,
            accd_mass: self.config.accd.mass,
            airspeed: self.config.aircraft.airspeed,
        }
    }

    /// RK4 substeps of the next step ([`accd_tether::TetherConfig::substeps_for`]) under the load of the
    /// current state ([`accd_tether::config::StepLoad::of_state`], the ACCD as tip mass, the
    /// state's effective axial mass [`TetherModel::axial_mass`]), with sea-level density (an
    /// upper bound) at the aircraft's airspeed. One for the default configuration. Evaluates the
    /// tether's accelerations at the current state for the axial mass (which depends on the
    /// coordinates only; a step reads it from its first stage).
    pub fn substeps(&mut self) -> Result<usize> {
        let mut qdd = std::mem::take(&mut self.qdd);
        let s = &self.tether;
        let evaluated =
            self.model
                .accelerations(s.time, &s.q, &s.qd, &accd_tether::Vacuum, &mut qdd);
        self.qdd = qdd;
        evaluated?;
        Ok(substeps_at(
            self.model.config(),
            self.config.accd.mass,
            self.config.aircraft.airspeed,
            &self.tether.q,
            &self.tether.qd,
            self.model.axial_mass(),
        ))
    }

    /// Steps `steps` times with the same commands.
    pub fn step_many(&mut self, steps: usize, command: [f64; 4]) -> Result<()> {
        for _ in 0..steps {
            self.step(command)?;
        }
        Ok(())
    }

    /// Tension at the attachment from the axial element, `k s + c s'` (segment 1's element,
    /// `n k s_1 + n c_s s_1'`, when the elasticity is distributed), N.
    pub fn attachment_tension(&self) -> f64 {
        let c = &self.config.tether;
        c.element_stiffness() * self.tether.q[0] + c.element_damping() * self.tether.qd[0]
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

    /// The boom tip minus the capture point at the current state, m (TA frame; a
    /// [`Snapshot`]'s `boom_tip - capture_point`, without the aerodynamics).
    pub fn boom_relative(&self) -> V3 {
        self.boom.tip(self.tether.time) - self.capture_point_state().0
    }

    /// Everything observable about the current state.
    pub fn snapshot(&mut self) -> Result<Snapshot> {
        let t = self.tether.time;
        let (position, velocity) = self.model.tip_state(&self.tether.q, &self.tether.qd)?;
        let (stage, _, _) = self.parts(false)?;
        let (_, loads) = stage.tip_loads(t, &position, &velocity);
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
        let mut qdd = std::mem::take(&mut self.qdd);
        let result = self
            .parts(false)
            .and_then(|(stage, model, _)| Ok(model.tensions(t, &q, &qd, &stage, &mut qdd, out)?));
        self.qdd = qdd;
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

/// One capture simulation's dynamic state ([`crate::CaptureSim`]), TA frame, SI.
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureState {
    /// Time of the last state set from outside, s.
    pub time_origin: f64,
    /// Physics steps since then.
    pub steps: u64,
    /// Simulation time, s.
    pub time: f64,
    /// Tether coordinates `[s, phi_1, psi_1, ...]` (m, rad).
    pub q: Vec<f64>,
    /// Their rates.
    pub qd: Vec<f64>,
    /// ACCD attitude, body to TA frame, as `[i, j, k, w]`.
    pub attitude: [f64; 4],
    /// Body rates (p, q, r), rad/s.
    pub omega: [f64; 3],
    /// Flap commands, rad.
    pub flap_command: [f64; 4],
    /// Flap deflections, rad.
    pub flap_deflection: [f64; 4],
    /// The boom.
    pub boom: BoomState,
    /// The air disturbance.
    pub air: AirState,
}

/// RK4 substeps of a step of the tether `c` from `(q, qd)` with the ACCD's `accd_mass` (kg) at
/// its tip and effective axial mass `axial_mass` (kg), under sea-level density at the aircraft's
/// `airspeed` (m/s) ([`CaptureSim::substeps`]).
/// What [`CaptureSim::begin_step`] leaves for the RK4 of the step.
struct StepStart {
    /// The step's start, s.
    time: f64,
    /// Its length, s.
    dt: f64,
    /// Whether the disturbance is held over the step ([`AirSampling::PerStep`]).
    hold: bool,
}

/// The substeps of a capture step: for the chain's fastest mode (one at the default
/// discretization), chosen after the first stage, whose evaluation gives the state's axial mass.
#[derive(Clone, Copy)]
struct SubstepRule {
    time: f64,
    accd_mass: f64,
    airspeed: f64,
}

impl SubstepRule {
    fn substeps(&self, model: &TetherModel, q: &[f64], qd: &[f64]) -> accd_tether::Result<usize> {
        let k = substeps_at(
            model.config(),
            self.accd_mass,
            self.airspeed,
            q,
            qd,
            model.axial_mass(),
        );
        if k > accd_tether::config::MAX_SUBSTEPS {
            return Err(accd_tether::TetherError::Diverged {
                time: self.time,
                reason: format!(
                    "the tether's fastest mode needs {k} {} substeps per step (at most {})",
                    model.config().scheme.integrator(),
                    accd_tether::config::MAX_SUBSTEPS
                ),
            });
        }
        Ok(k)
    }
}

fn substeps_at(
    c: &accd_tether::TetherConfig,
    accd_mass: f64,
    airspeed: f64,
    q: &[f64],
    qd: &[f64],
    axial_mass: f64,
) -> usize {
    let load = accd_tether::config::StepLoad::of_coordinates(
        c,
        q,
        qd,
        accd_mass,
        SEA_LEVEL_DENSITY,
        airspeed,
        axial_mass,
    );
    c.substeps_for(&load)
}
