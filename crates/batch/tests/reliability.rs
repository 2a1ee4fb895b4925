//! Regression tests of issue 13 for the batch: memory is budgeted before anything is allocated,
//! construction stops when its interruption check says so, and a read-back of errors names them.

use accd_batch::memory::{budget_bytes, check_budget, MAX_BATCH_BYTES};
use accd_batch::{Autoreset, BatchEnv, BatchError};
use accd_sim::{EnvConfig, SimError};

fn low_and_slow() -> EnvConfig {
    let mut c = EnvConfig::default();
    c.physics.aircraft.airspeed = 10.0;
    c.physics.turbulence.history_distance_m = 5000.0;
    c
}

#[test]
fn the_estimate_follows_the_gust_history() {
    let default = EnvConfig::default().bytes_per_env();
    assert!((1 << 10..16 << 20).contains(&default), "{default} bytes");
    // issue 13: about 44 MiB per env at 10 m/s with a 5 km history
    let slow = low_and_slow().bytes_per_env();
    assert!((30 << 20..60 << 20).contains(&slow), "{slow} bytes");
}

#[test]
fn a_batch_over_the_budget_is_a_config_error_naming_the_estimate() {
    assert!(budget_bytes() <= MAX_BATCH_BYTES);
    let err = check_budget(&low_and_slow(), 65_536)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("`num_envs` = 65536") && err.contains("MiB per env") && err.contains("budget"),
        "{err}"
    );
    let err = BatchEnv::new(
        low_and_slow().validated().unwrap(),
        65_536,
        0,
        Autoreset::SameStep,
        1,
    )
    .err()
    .expect("refused");
    assert!(matches!(
        err,
        BatchError::Sim(SimError::InvalidConfig { ref field, .. }) if field == "num_envs"
    ));
    check_budget(&EnvConfig::default(), 16).unwrap();
}

#[test]
fn construction_stops_when_interrupted() {
    let mut calls = 0;
    let err = BatchEnv::new_interruptible(
        EnvConfig::default().validated().unwrap(),
        2,
        0,
        Autoreset::SameStep,
        1,
        &mut || {
            calls += 1;
            calls > 5
        },
    )
    .err()
    .expect("interrupted");
    assert!(
        matches!(err, BatchError::Sim(SimError::Interrupted { .. })),
        "{err}"
    );
    assert_eq!(calls, 6);
}
