//! Memory budgeting of a batch: the configuration's estimate of one env's bytes
//! ([`accd_sim::EnvConfig::bytes_per_env`]) times the number of envs, against what the machine
//! can give.

use accd_sim::{EnvConfig, SimError};

/// The most memory a batch may plan to use, bytes, whatever the machine has: 64 GiB.
pub const MAX_BATCH_BYTES: u64 = 64 << 30;

/// Share of the memory available when the batch is built that it may plan to use.
pub const AVAILABLE_SHARE: f64 = 0.8;

/// Memory available to new allocations, bytes: `MemAvailable` of `/proc/meminfo` (Linux), or
/// None where it cannot be read.
pub fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib.saturating_mul(1024))
}

/// The bytes a batch may plan to use: [`AVAILABLE_SHARE`] of the available memory, at most
/// [`MAX_BATCH_BYTES`].
pub fn budget_bytes() -> u64 {
    match available_bytes() {
        Some(a) => ((a as f64 * AVAILABLE_SHARE) as u64).min(MAX_BATCH_BYTES),
        None => MAX_BATCH_BYTES,
    }
}

/// Checks that `num_envs` envs of `config` fit in [`budget_bytes`]; the error names the
/// estimate per env, the total and the budget.
pub fn check_budget(config: &EnvConfig, num_envs: usize) -> Result<(), SimError> {
    let per_env = config.bytes_per_env() as u64;
    let total = per_env.saturating_mul(num_envs as u64);
    let budget = budget_bytes();
    if total <= budget {
        return Ok(());
    }
    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
    if per_env > budget {
        let history = config
            .physics
            .turbulence
            .history_bytes(config.physics.aircraft.airspeed) as u64;
        let (field, value) = if history * 2 > per_env {
            (
                "turbulence.history_distance_m",
                config.physics.turbulence.history_distance_m,
            )
        } else {
            ("tether.segments", config.physics.tether.segments as f64)
        };
        return Err(SimError::invalid_config(
            field,
            value,
            &format!(
                "a value for which one env fits the memory budget of {:.1} MiB (80% of the \
                 available memory, at most 64 GiB): one env needs an estimated {:.1} MiB \
                 (gust history {:.1} MiB: turbulence.history_distance_m / aircraft.airspeed = \
                 {:.0} s of gusts every turbulence.time_step_s)",
                mib(budget),
                mib(per_env),
                mib(history),
                config.physics.turbulence.history_distance_m / config.physics.aircraft.airspeed
            ),
        ));
    }
    Err(SimError::invalid_config(
        "num_envs",
        num_envs,
        &format!(
            "[1, {}]: {num_envs} envs of this configuration need an estimated {:.1} MiB \
             ({:.2} MiB per env, mostly the turbulence history: turbulence.history_distance_m / \
             aircraft.airspeed seconds of gusts), over the budget of {:.1} MiB (80% of the \
             available memory, at most 64 GiB)",
            (budget / per_env.max(1)).max(1),
            mib(total),
            mib(per_env),
            mib(budget)
        ),
    ))
}
