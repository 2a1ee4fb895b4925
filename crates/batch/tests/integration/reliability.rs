//! Regression tests for the batch: memory is budgeted before anything is allocated,
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
    // About 44 MiB per env at 10 m/s with a 5 km history
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

fn quick() -> EnvConfig {
    let mut c = EnvConfig {
        capture_window: 2.0,
        ..EnvConfig::default()
    };
    c.initial.settle_time = 2.0;
    c
}

/// Steps `env` with an interruption check that says yes at once: the step fails as interrupted
/// after asking exactly once.
fn interrupt_a_step(env: &mut BatchEnv, actions: &[f32], out: &mut accd_batch::StepOutputs) {
    let mut calls = 0;
    let err = env
        .step_interruptible(actions, out.buffers(), &mut || {
            calls += 1;
            true
        })
        .unwrap_err();
    assert!(
        matches!(err, BatchError::Sim(SimError::Interrupted { .. })),
        "{err}"
    );
    assert_eq!(calls, 1, "asked once, then stopped");
}

#[test]
fn an_interruptible_step_is_bitwise_the_plain_step() {
    // The interruptible step shares the envs with the calling thread (after its first step);
    // the plain one runs them on the pool: the same bits whatever the split.
    for (threads, n) in [(1, 3), (2, 3), (2, 1), (3, 5)] {
        let make = || {
            BatchEnv::new(
                quick().validated().unwrap(),
                n,
                7,
                Autoreset::SameStep,
                threads,
            )
            .unwrap()
        };
        let (mut a, mut b) = (make(), make());
        let actions: Vec<f32> = (0..n * 4).map(|k| ((k % 5) as f32 - 2.0) / 2.0).collect();
        let (mut oa, mut ob) = (
            accd_batch::StepOutputs::new(n),
            accd_batch::StepOutputs::new(n),
        );
        for _ in 0..30 {
            a.step(&actions, oa.buffers()).unwrap();
            b.step_interruptible(&actions, ob.buffers(), &mut || false)
                .unwrap();
            assert_eq!(oa, ob, "{threads} threads, {n} envs");
        }
        assert_eq!(a.save().unwrap(), b.save().unwrap());
    }
}

#[test]
fn an_interrupted_step_stops_part_way_and_the_batch_refuses_until_reset() {
    // 10 s agent steps of 1000 physics steps each of a 100-segment tether (about 50 ms per env,
    // the two envs one after the other on one thread): a step takes far longer than one check
    // interval, so the check runs while the first env is part-way through it.
    let mut c = quick();
    c.agent_step = 10.0;
    c.capture_window = 20.0;
    c.physics.tether.segments = 100;
    let mut env =
        BatchEnv::new(c.clone().validated().unwrap(), 2, 1, Autoreset::SameStep, 1).unwrap();
    let actions = [0.0f32; 8];
    let mut out = accd_batch::StepOutputs::new(2);
    let start = std::time::Instant::now();
    interrupt_a_step(&mut env, &actions, &mut out);
    let time = env.episode(0).unwrap().sim().time();
    assert!(time > 0.0 && time < 10.0, "t = {time}"); // stopped part-way
    assert!(start.elapsed() < std::time::Duration::from_secs(1));
    for e in [
        env.step(&actions, out.buffers()).unwrap_err(),
        env.save().unwrap_err(),
    ] {
        assert!(
            matches!(e, BatchError::Interrupted { env: 0 }) && e.to_string().contains("reset()"),
            "{e}"
        );
    }
    let mut reset = accd_batch::StepOutputs::new(2);
    env.reset(
        accd_batch::SeedSpec::Base(1),
        Some(&[true, false]),
        accd_batch::ResetBuffers {
            obs: &mut reset.obs,
            wake_seed: &mut reset.wake_seed,
        },
    )
    .unwrap();
    assert!(matches!(
        env.step(&actions, out.buffers()).unwrap_err(),
        BatchError::Interrupted { env: 1 }
    ));
    env.reset(
        accd_batch::SeedSpec::Base(1),
        None,
        accd_batch::ResetBuffers {
            obs: &mut reset.obs,
            wake_seed: &mut reset.wake_seed,
        },
    )
    .unwrap();
    env.save().unwrap();
    // after the reset the batch runs as a fresh one does
    let mut fresh = BatchEnv::new(c.validated().unwrap(), 2, 1, Autoreset::SameStep, 1).unwrap();
    let mut out2 = accd_batch::StepOutputs::new(2);
    env.step(&actions, out.buffers()).unwrap();
    fresh.step(&actions, out2.buffers()).unwrap();
    assert_eq!(out, out2);
}

#[test]
fn a_shared_step_is_interrupted_between_the_callers_envs() {
    // 64 envs of 1 s agent steps (100 physics steps, about 1 ms each: under the 5 ms at which
    // the calling thread stops taking envs itself): after a first, watched-only step the caller
    // steps envs beside the pool and asks the check between them. A batch step takes far longer
    // than one check interval, so the interruption stops it with envs not yet stepped.
    let mut c = quick();
    c.agent_step = 1.0;
    c.capture_window = 60.0;
    let n = 64;
    let mut env = BatchEnv::new(c.validated().unwrap(), n, 1, Autoreset::SameStep, 2).unwrap();
    let actions = vec![0.0f32; n * 4];
    let mut out = accd_batch::StepOutputs::new(n);
    env.step_interruptible(&actions, out.buffers(), &mut || false)
        .unwrap();
    let start = std::time::Instant::now();
    env.step_interruptible(&actions, out.buffers(), &mut || false)
        .unwrap();
    let whole_step = start.elapsed();
    let start = std::time::Instant::now();
    interrupt_a_step(&mut env, &actions, &mut out);
    let interrupted_after = start.elapsed();
    // Stopped part-way: some envs are still at the end of the previous step (t = 2 s).
    let times: Vec<f64> = (0..n)
        .map(|i| env.episode(i).unwrap().sim().time())
        .collect();
    assert!(
        times.iter().any(|&t| (t - 2.0).abs() < 1e-9),
        "every env was stepped: {times:?}"
    );
    assert!(
        interrupted_after < whole_step,
        "{interrupted_after:?} against a whole step of {whole_step:?}"
    );
    assert!(matches!(
        env.step(&actions, out.buffers()).unwrap_err(),
        BatchError::Interrupted { .. }
    ));
}
