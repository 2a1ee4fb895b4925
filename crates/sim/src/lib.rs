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
//! # Modules, by concept (no import cycle: `tests/module_graph.rs`)
//! * configuration: [`config`] (the physics' [`CaptureConfig`], its cross-field rules, reading
//!   JSON documents), [`valid`] (a validated configuration, what the constructors take);
//! * tables: [`interp`] (grid look-ups), [`aero`] (the ACCD's coefficient tables),
//!   [`table_file`] (reading a user's table file: regular files of bounded size only);
//! * the air: [`air`] (the [`AirDisturbance`] interface), [`wake`] (mean wake: tables and the
//!   analytic model), [`turbulence`], [`wake_field`] (wake + turbulence as one field);
//! * bodies and scene: [`accd`] (the capturing device, flaps, loads), [`aircraft`], [`boom`];
//! * the simulation: [`capture`] (the coupled step, one RK4 of [`accd_tether::Rk4`]), [`rng`]
//!   (named, seeded streams), [`state_format`] (the snapshot format; each state type lives
//!   beside its owner);
//! * the task: [`task`] (task configuration, observation table, reward, episode end),
//!   [`sensors`] (the opt-in sensor model of the observation), [`episode`] (one RL episode).

#![warn(missing_docs)]

pub mod accd;
pub mod aero;
pub mod air;
pub mod aircraft;
pub mod boom;
pub mod capture;
pub mod config;
pub mod episode;
pub mod error;
pub mod interp;
pub mod linearize;
pub mod randomization;
pub mod rng;
pub mod sensors;
pub mod state_format;
pub mod table_file;
pub mod task;
pub mod turbulence;
pub mod valid;
pub mod wake;
pub mod wake_field;

pub use accd::{AccdConfig, AccdState};
pub use aero::AeroModel;
pub use air::{AirDisturbance, AirState};
pub use aircraft::AircraftConfig;
pub use boom::{BoomConfig, BoomPlacement, CaptureStatus};
pub use capture::{CaptureSim, CaptureState, Snapshot};
pub use config::CaptureConfig;
pub use episode::{Episode, Equilibrium, Outcome};
pub use error::SimError;
pub use linearize::{linearize, Linearization, Linearized};
pub use randomization::{Parameters, RandomizationConfig};
pub use rng::{NormalSampler, Seeds};
pub use sensors::{SensorState, Sensors, SensorsConfig};
pub use state_format::StateError;
pub use task::{
    observation_index, EnvConfig, ObservationField, ObservationInputs, ACT_DIM, OBSERVATION,
    OBS_BOUND, OBS_DIM,
};
pub use turbulence::{AmbientTurbulence, LaneStreams, Turbulence, TurbulenceConfig};
pub use valid::Valid;
pub use wake::{
    AirSampling, AnalyticWake, Wake, WakeConfig, WakeSample, WakeTable, WakeTableData,
    WakeTableFiles, WakeTables,
};
pub use wake_field::WakeField;
