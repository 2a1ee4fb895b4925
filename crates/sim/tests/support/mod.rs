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
