//! Helpers shared by the integration tests (not production API).

#![allow(dead_code)]

pub mod wake_field;

use std::sync::Arc;

use accd_sim::{EnvConfig, Episode, Equilibrium, Seeds};

/// The seeds of test episode `k`: initial `k`, wake `1000 + k`, RLV `2000 + k`.
pub fn seeds(k: u64) -> Seeds {
    Seeds {
        initial: k,
        wake: 1000 + k,
        rlv: 2000 + k,
    }
}

/// An episode of `config` (validated and settled here) with the seeds of test episode `k`.
pub fn episode(config: &EnvConfig, k: u64) -> Episode {
    episode_with_seeds(config, seeds(k))
}

/// An episode of `config` (validated and settled here) with `seeds`.
pub fn episode_with_seeds(config: &EnvConfig, seeds: Seeds) -> Episode {
    let config = Arc::new(config.clone().validated().unwrap());
    let eq = Arc::new(Equilibrium::settle(&config).unwrap());
    Episode::new(config, eq, seeds).unwrap()
}

/// `config` made to diverge: RK4 at 0.1 s is far beyond the stability limit of the axial element
/// (omega dt ~ 5); the tether substeps through that, so what diverges is the
/// ACCD's roll: a roll damping far beyond any body's makes its rate equation stiff at 0.1 s.
pub fn stiff_roll(mut config: EnvConfig) -> EnvConfig {
    config.physics.tether.time_step = 0.1;
    config.initial.settle_time = 0.0;
    config.limits.max_distance = 1e4;
    let mut table: serde_json::Value =
        serde_json::from_str(&accd_sim::AeroModel::accd().to_json()).unwrap();
    table["damping"]["clp"] = (-1e5).into();
    config.physics.accd.aero_table = Some(table.to_string());
    config
}
