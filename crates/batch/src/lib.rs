//! # accd-batch
//!
//! N In-Air Capturing episodes ([`accd_sim::Episode`]) stepped by one call, in parallel over
//! threads, into struct-of-arrays buffers, with same-step or next-step autoreset and the seed
//! scheme of [`seeds`]. Nothing here knows about Python.

#![warn(missing_docs)]

pub mod batch;
pub mod error;
pub mod memory;
pub mod seeds;
mod shared;

pub use batch::{
    check_base_seed, check_env_seed, info, Autoreset, BatchEnv, BatchState, ResetBuffers, SeedSpec,
    SlotState, StepBuffers, StepOutputs, MAX_ENVS, MAX_THREADS,
};
pub use error::{BatchError, Result};
pub use seeds::{
    episode_seeds, WakeSchedule, HELD_OUT_WAKE_SEEDS, TRAINING_WAKE_SEEDS, VALIDATION_WAKE_SEEDS,
};
