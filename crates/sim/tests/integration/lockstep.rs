//! Four episodes stepped together (`Episode::step_four`: their physics steps through
//! `CaptureSim::step_four`, the tether's recursion four AVX2 lanes wide) step bit for bit as
//! each steps alone: outcomes, observations and whole states after every agent step, under the
//! default and the exact air scheme, with randomized physics and sensors, with a lane that
//! diverges and takes fewer physics steps per agent step, and with episodes that end at
//! different times.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::support;
use support::{episode, seeds, stiff_roll};

use accd_sim::{EnvConfig, Episode, Equilibrium};
use accd_tether::LockstepWork;

/// A window of `seconds`, the default capture radius.
fn window(seconds: f64) -> EnvConfig {
    EnvConfig {
        capture_window: seconds,
        initial: accd_sim::task::InitialConfig {
            settle_time: 30.0,
            ..Default::default()
        },
        ..EnvConfig::default()
    }
}

/// Lane j's action at agent step k: sweeps of different phases, beyond the limit at times.
fn action(j: usize, k: usize) -> [f32; 4] {
    let t = k as f32 * 0.1 + j as f32;
    let pitch = 1.2 * (0.7 * t).sin();
    let yaw = 0.8 * (0.5 * t).cos();
    [pitch + 0.05, pitch - 0.05, yaw - 0.05, yaw + 0.05]
}

/// Steps `four` together and `alone` one by one until every episode has ended (and once
/// more: stepping an ended episode is an error, the same either way), comparing the outcome,
/// the observation and the whole state after every agent step; returns the lanes' outcomes.
fn compare(mut four: Vec<Episode>, mut alone: Vec<Episode>, steps: usize) -> Vec<Vec<String>> {
    let stop = AtomicBool::new(false);
    let mut work = LockstepWork::default();
    let mut history = vec![Vec::new(); 4];
    for k in 0..steps {
        let actions: [[f32; 4]; 4] = std::array::from_fn(|j| action(j, k));
        let results = {
            let [a, b, c, d] = &mut four[..] else {
                unreachable!()
            };
            Episode::step_four(
                [a, b, c, d],
                std::array::from_fn(|j| &actions[j][..]),
                &stop,
                &mut work,
            )
        };
        for (j, together) in results.into_iter().enumerate() {
            let single = alone[j].step(&actions[j]);
            let what = format!("agent step {k}, lane {j}");
            let (x, y) = (format!("{together:?}"), format!("{single:?}"));
            assert_eq!(x, y, "{what}");
            let bits = |e: &Episode| e.observation().map(f32::to_bits);
            assert_eq!(bits(&four[j]), bits(&alone[j]), "{what}");
            assert_eq!(
                format!("{:?}", four[j].state()),
                format!("{:?}", alone[j].state()),
                "{what}"
            );
            history[j].push(x);
        }
        if four.iter().all(|e| e.done()) {
            break;
        }
    }
    history
}

fn episodes(configs: &[EnvConfig; 4]) -> Vec<Episode> {
    (0..4).map(|j| episode(&configs[j], j as u64 + 1)).collect()
}

#[test]
fn four_episodes_in_lockstep_step_as_each_alone() {
    let exact = {
        let mut c = window(4.0);
        c.physics.wake.sampling = accd_sim::AirSampling::PerStage;
        c
    };
    let randomized = {
        let mut c = window(3.0);
        c.randomization.enabled = true;
        c
    };
    let sensed = {
        let mut c = window(3.0);
        c.sensors.enabled = true;
        c
    };
    // Episodes of 2, 3 and 4 s: lanes end, and then refuse steps, at different times.
    let configs = [window(2.0), exact, randomized, sensed];
    let four = episodes(&configs);
    let history = compare(four.clone(), four, 45);
    // Until the 4 s episode ends: 40 agent steps.
    assert!(history.iter().all(|h| h.len() == 40));
    let refused = |j: usize| history[j].iter().filter(|o| o.starts_with("Err")).count();
    assert_eq!(
        [refused(0), refused(1), refused(2), refused(3)],
        [20, 0, 10, 10]
    );
}

/// A lane whose ACCD diverges (a stiff roll damping at a 0.1 s physics step, one physics step
/// per agent step against the others' ten) leaves the others as they would be alone.
#[test]
fn a_diverging_lane_and_uneven_physics_steps_leave_the_others_as_alone() {
    let stiff = {
        let config = Arc::new(stiff_roll(window(5.0)).validated().unwrap());
        let eq = Arc::new(Equilibrium::settle(&config).unwrap());
        Episode::new(config, eq, seeds(9)).unwrap()
    };
    let mut four = episodes(&[window(3.0), window(3.0), window(3.0), window(3.0)]);
    four[2] = stiff;
    let history = compare(four.clone(), four, 35);
    assert!(
        history[2].iter().any(|o| o.contains("diverged: true")),
        "lane 2 diverges: {:?}",
        history[2].last()
    );
}
