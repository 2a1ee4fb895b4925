//! # accd-sim
//!
//! One capture episode of DLR's In-Air Capturing, in pure Rust: the Aerodynamically Controlled
//! Capturing Device (ACCD) as a 6-DoF body at the tip of the [`accd_tether`] tether, the towing
//! aircraft's (TA) wake and its turbulence, the TA's flight, and the RLV's capture boom. Nothing
//! here knows about reinforcement learning or batching.
//!
//! Frames and units as in `accd_tether`: SI, TA frame with x forward, y starboard, z down, origin
//! at the tether attachment.
//!
//! # Modules, by concept (no import cycle: `tests/integration/module_graph.rs`)
//! * [`physics`]: the world of one capture, nothing of the RL task. Tables: [`physics::interp`]
//!   (grid look-ups), [`physics::aero`] (the ACCD's coefficient tables); the air: [`physics::air`]
//!   (the [`AirDisturbance`] interface), [`physics::wake`] (mean wake: tables and the analytic
//!   model), [`physics::turbulence`], [`physics::wake_field`] (wake + turbulence as one field);
//!   bodies and scene: [`physics::accd`] (the capturing device, flaps, loads),
//!   [`physics::aircraft`], [`physics::boom`]; the coupled step: [`physics::capture`] (one RK4 of
//!   [`accd_tether::Rk4`]).
//! * [`task`]: the RL task on top of it. [`task::config`] (the task's [`EnvConfig`]),
//!   [`task::observation`] (the observation table), [`task::sensors`] (the opt-in sensor model of
//!   the observation), [`task::randomization`] (domain randomization), [`task::episode`] (one RL
//!   episode: reset, step, reward, episode end), [`task::linearize`] (the plant linearized about
//!   the equilibrium, for controller design).
//! * [`control`]: classical controllers on the linearized plant: [`control::matrix`]
//!   (fixed-order dense arithmetic), [`control::riccati`] (the discrete Riccati equation),
//!   [`control::lqr`] (the LQR baseline's design), [`control::filter`] (its Kalman filter and
//!   control law per step).
//! * Shared by both: [`config`] (the physics' [`CaptureConfig`], its cross-field rules, reading
//!   JSON documents), [`valid`] (a validated configuration, what the constructors take),
//!   [`error`], [`table_file`] (reading a user's table file: regular files of bounded size only),
//!   [`rng`] (named, seeded streams), [`state_format`] (the snapshot format; each
//!   state type lives beside its owner).

#![warn(missing_docs)]

pub mod config;
pub mod control;
pub mod error;
pub mod physics;
pub mod rng;
pub mod rotation;
pub mod state_format;
pub mod table_file;
pub mod task;
pub mod valid;

pub use config::CaptureConfig;
pub use error::SimError;
pub use physics::accd::{AccdConfig, AccdState};
pub use physics::aero::AeroModel;
pub use physics::air::{AirDisturbance, AirState};
pub use physics::aircraft::AircraftConfig;
pub use physics::boom::{BoomConfig, BoomPlacement, CaptureStatus};
pub use physics::capture::{CaptureSim, CaptureState, Snapshot};
pub use physics::turbulence::{AmbientTurbulence, LaneStreams, Turbulence, TurbulenceConfig};
pub use physics::wake::{
    AirSampling, AnalyticWake, Wake, WakeConfig, WakeSample, WakeTable, WakeTableData,
    WakeTableFiles, WakeTables,
};
pub use physics::wake_field::WakeField;
pub use rng::{NormalSampler, Seeds, SEED_END, SEED_RANGE};
pub use state_format::StateError;
pub use task::config::{EnvConfig, InitialConfig, LimitsConfig, RewardConfig};
pub use task::episode::{Episode, EpisodeState, Equilibrium, Outcome};
pub use task::linearize::{linearize, Linearization, Linearized};
pub use task::observation::{
    observation_index, ObservationField, ObservationInputs, ACT_DIM, OBSERVATION, OBS_BOUND,
    OBS_DIM,
};
pub use task::randomization::{Parameters, RandomizationConfig};
pub use task::sensors::{SensorState, Sensors, SensorsConfig};
pub use valid::Valid;
