//! Per-env controllers stepped in the batch's threads: the commands of a filter stepped alone
//! on the env's observations, bit for bit, whatever the thread count and batch size, across
//! automatic resets; states restored exactly; bad states refused.

use std::sync::Arc;

use accd_batch::{Autoreset, BatchEnv, ResetBuffers, SeedSpec, StepOutputs};
use accd_sim::control::controller::{Controller, LqrController};
use accd_sim::control::filter::LqrFilter;
use accd_sim::control::lqr::{EXTRA_STATES, MEASURED_DIM};
use accd_sim::control::matrix::Matrix;
use accd_sim::{EnvConfig, ACT_DIM, OBS_DIM};

/// A filter of `n` plant states with deterministic pseudo-random (stable) matrices.
pub fn random_filter(n: usize) -> LqrFilter {
    let nz = n + EXTRA_STATES;
    let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut m = |r: usize, c: usize, s: f64| Matrix::from_fn(r, c, |_, _| s * next());
    let (f, g, h, l) = (
        m(nz, nz, 0.1),
        m(nz, ACT_DIM, 1.0),
        m(MEASURED_DIM, nz, 1.0),
        m(nz, MEASURED_DIM, 0.1),
    );
    let (k, k_ff) = (m(ACT_DIM, n, 0.2), m(ACT_DIM, 4, 1.0));
    LqrFilter::from_parts(n, &f, &g, &h, &l, &k, &k_ff, [0.01; MEASURED_DIM]).unwrap()
}

fn config() -> EnvConfig {
    EnvConfig {
        capture_window: 2.0,
        initial: accd_sim::task::InitialConfig {
            settle_time: 20.0,
            ..Default::default()
        },
        ..EnvConfig::default()
    }
}

/// Env `i`'s action at step `k`.
fn actions(n: usize, k: usize) -> Vec<f32> {
    (0..n * ACT_DIM)
        .map(|j| (((j / ACT_DIM) * 3 + j % ACT_DIM + 5 * k) % 9) as f32 / 3.5 - 1.2)
        .collect()
}

/// Per step: every env's observation, controller command, final command and done flag.
type History = Vec<(Vec<f32>, Vec<f32>, Vec<f32>, Vec<bool>)>;

fn run(n: usize, threads: usize, filter: &Arc<LqrFilter>, steps: usize) -> History {
    let mut env = BatchEnv::new(
        config().validated().unwrap(),
        n,
        11,
        Autoreset::SameStep,
        threads,
    )
    .unwrap();
    let f = Arc::clone(filter);
    let make = move || -> Box<dyn Controller> { Box::new(LqrController::new(Arc::clone(&f))) };
    env.set_controllers(Some(&make));
    let (mut obs, mut wake) = (vec![0.0; n * OBS_DIM], vec![0; n]);
    let reset = ResetBuffers {
        obs: &mut obs,
        wake_seed: &mut wake,
    };
    env.reset(SeedSpec::Base(11), None, reset).unwrap();
    let mut commands = vec![0.0; n * ACT_DIM];
    let mut finals = vec![0.0; n * ACT_DIM];
    env.controller_commands(&mut commands).unwrap();
    let mut out = vec![(
        obs.clone(),
        commands.clone(),
        finals.clone(),
        vec![false; n],
    )];
    let mut s = StepOutputs::new(n);
    for k in 0..steps {
        env.step(&actions(n, k), s.buffers()).unwrap();
        env.controller_commands(&mut commands).unwrap();
        env.final_controller_commands(&mut finals).unwrap();
        let done: Vec<bool> = (0..n).map(|i| s.terminated[i] || s.truncated[i]).collect();
        let mut obs = s.obs.clone();
        for (i, d) in done.iter().enumerate() {
            if *d {
                // the final observation, for the oracle's peek
                obs.extend_from_slice(&s.final_obs[i * OBS_DIM..(i + 1) * OBS_DIM]);
            }
        }
        out.push((obs, commands.clone(), finals.clone(), done));
    }
    out
}

fn row<T: Clone>(v: &[T], i: usize, w: usize) -> Vec<T> {
    v[i * w..(i + 1) * w].to_vec()
}

#[test]
fn controllers_step_as_their_filter_alone_whatever_threads_and_batch_size() {
    let filter = Arc::new(random_filter(33));
    let steps = 45; // every env crosses an automatic reset (2 s = 20 steps)
    let a = run(4, 1, &filter, steps);
    for (n, threads) in [(4, 2), (2, 2), (5, 3)] {
        let b = run(n, threads, &filter, steps);
        for i in 0..2 {
            for (k, (x, y)) in a.iter().zip(&b).enumerate() {
                assert_eq!(
                    row(&x.1, i, ACT_DIM),
                    row(&y.1, i, ACT_DIM),
                    "{n}/{threads} env {i} step {k}"
                );
                if x.3[i] {
                    assert_eq!(
                        row(&x.2, i, ACT_DIM),
                        row(&y.2, i, ACT_DIM),
                        "final, step {k}"
                    );
                }
            }
        }
    }
    // The oracle: env 1's filter stepped alone on its observations, told the clipped action sent,
    // restarted at each new episode; the ended episode's last observation peeked without advancing.
    let n = 4;
    let i = 1;
    let mut state = filter.new_state();
    let mut command = [0.0_f32; ACT_DIM];
    let widen = |o: &[f32]| -> [f64; OBS_DIM] { std::array::from_fn(|j| f64::from(o[j])) };
    filter
        .step(&mut state, &widen(&row(&a[0].0, i, OBS_DIM)), &mut command)
        .unwrap();
    assert_eq!(command.to_vec(), row(&a[0].1, i, ACT_DIM));
    let mut ended = 0;
    for (k, (obs, commands, finals, done)) in a.iter().enumerate().skip(1) {
        let sent = row(&actions(n, k - 1), i, ACT_DIM);
        for j in 0..ACT_DIM {
            let d = f64::from(sent[j].clamp(-1.0, 1.0)) - f64::from(command[j]);
            if d != 0.0 {
                state.u[j] += d;
            }
        }
        if done[i] {
            ended += 1;
            let at = n * OBS_DIM + done[..i].iter().filter(|d| **d).count() * OBS_DIM;
            let mut peek = state.clone();
            let mut last = [0.0_f32; ACT_DIM];
            filter
                .step(&mut peek, &widen(&obs[at..at + OBS_DIM]), &mut last)
                .unwrap();
            assert_eq!(
                last.to_vec(),
                row(finals, i, ACT_DIM),
                "final command, step {k}"
            );
            state.fresh = true;
        }
        filter
            .step(&mut state, &widen(&row(obs, i, OBS_DIM)), &mut command)
            .unwrap();
        assert_eq!(command.to_vec(), row(commands, i, ACT_DIM), "step {k}");
    }
    assert!(ended >= 2);
}

#[test]
fn controller_states_restore_exactly_and_bad_ones_change_nothing() {
    let filter = Arc::new(random_filter(21));
    let n = 3;
    let mut env =
        BatchEnv::new(config().validated().unwrap(), n, 5, Autoreset::NextStep, 2).unwrap();
    let mut commands = vec![0.0; n * ACT_DIM];
    assert!(env.controller_commands(&mut commands).is_err()); // no controllers yet
    let f = Arc::clone(&filter);
    let make = move || -> Box<dyn Controller> { Box::new(LqrController::new(Arc::clone(&f))) };
    env.set_controllers(Some(&make));
    let mut s = StepOutputs::new(n);
    for k in 0..7 {
        env.step(&actions(n, k), s.buffers()).unwrap();
    }
    let saved_env = env.state();
    let saved = env.controller_states().unwrap();
    let mut bad = saved.clone();
    bad[2].filter.z.pop();
    let err = env.set_controller_states(&bad).unwrap_err().to_string();
    assert!(
        err.contains("env 2") && err.contains("controller.z"),
        "{err}"
    );
    assert_eq!(env.controller_states().unwrap(), saved);
    let mut later = Vec::new();
    for k in 7..30 {
        env.step(&actions(n, k), s.buffers()).unwrap();
        env.controller_commands(&mut commands).unwrap();
        later.push(commands.clone());
    }
    env.set_state(saved_env).unwrap();
    env.set_controller_states(&saved).unwrap();
    for (k, want) in (7..30).zip(&later) {
        env.step(&actions(n, k), s.buffers()).unwrap();
        env.controller_commands(&mut commands).unwrap();
        assert_eq!(&commands, want, "step {k}");
    }
}
