//! The batch env: bitwise-identical results whatever the thread count and batch size, both
//! autoreset modes as documented, per-env seeding, bad input named, saved states restored.

use accd_batch::{info, Autoreset, BatchEnv, ResetBuffers, SeedSpec, StepOutputs, WakeSchedule};
use accd_sim::{EnvConfig, ACT_DIM, OBS_DIM};

/// Short episodes (2 s) so that autoresets happen within a test.
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

type Step = StepOutputs;

struct Runner {
    env: BatchEnv,
    s: Step,
}

impl Runner {
    fn new(n: usize, threads: usize, mode: Autoreset) -> Runner {
        let env = BatchEnv::new(config().validated().unwrap(), n, 11, mode, threads).unwrap();
        Runner {
            env,
            s: StepOutputs::new(n),
        }
    }

    fn step(&mut self, actions: &[f32]) -> accd_batch::Result<Step> {
        self.env.step(actions, self.s.buffers())?;
        Ok(self.s.clone())
    }

    fn reset(&mut self, seeds: SeedSpec) -> Vec<f32> {
        let n = self.env.num_envs();
        let mut obs = vec![0.0; n * OBS_DIM];
        let mut wake = vec![0; n];
        self.env
            .reset(
                seeds,
                None,
                ResetBuffers {
                    obs: &mut obs,
                    wake_seed: &mut wake,
                },
            )
            .unwrap();
        obs
    }
}

/// Env `i`'s action at step `k`: different per env, a few beyond the limit.
fn actions(n: usize, k: usize) -> Vec<f32> {
    (0..n * ACT_DIM)
        .map(|j| {
            let (i, c) = (j / ACT_DIM, j % ACT_DIM);
            let t = 0.1 * k as f32 + 0.37 * i as f32;
            let pitch = 1.1 * (0.8 * t).sin();
            let yaw = 0.6 * (0.45 * t + 1.0).cos();
            [pitch, pitch, yaw, yaw][c]
        })
        .collect()
}

/// Env `i`'s row of a per-env array with `width` values per env.
fn row<T: Clone>(v: &[T], i: usize, width: usize) -> Vec<T> {
    v[i * width..(i + 1) * width].to_vec()
}

fn env_history(steps: &[Step], i: usize) -> String {
    steps
        .iter()
        .map(|s| {
            format!(
                "{:?}{:?}{:?}{:?}{:?}{:?}{:?}",
                row(&s.obs, i, OBS_DIM),
                s.reward[i],
                s.terminated[i],
                s.truncated[i],
                row(&s.info, i, info::DIM),
                s.wake_seed[i],
                if s.terminated[i] || s.truncated[i] {
                    row(&s.final_obs, i, OBS_DIM)
                } else {
                    vec![]
                }
            )
        })
        .collect()
}

#[test]
fn results_are_bitwise_identical_whatever_threads_and_batch_size() {
    let run = |n: usize, threads: usize| -> Vec<Step> {
        let mut r = Runner::new(n, threads, Autoreset::SameStep);
        // 45 steps: every env crosses at least one autoreset (2 s = 20 steps).
        (0..45).map(|k| r.step(&actions(n, k)).unwrap()).collect()
    };
    let a = run(5, 1);
    let b = run(5, 2);
    let c = run(3, 2);
    let d = run(8, 1);
    for i in 0..3 {
        let h = env_history(&a, i);
        assert_eq!(h, env_history(&b, i), "env {i}: 1 vs 2 threads");
        assert_eq!(h, env_history(&c, i), "env {i}: batch 5 vs 3");
        assert_eq!(h, env_history(&d, i), "env {i}: batch 5 vs 8");
    }
    assert_ne!(env_history(&a, 0), env_history(&a, 1), "envs differ");
    assert!(a.iter().any(|s| s.truncated.iter().any(|&t| t)));
}

#[test]
fn same_step_autoreset_returns_the_new_episode_and_keeps_the_final_observation() {
    let mut r = Runner::new(2, 1, Autoreset::SameStep);
    let mut wakes = vec![r.s.wake_seed.clone()];
    let mut last = Vec::new();
    for k in 0..20 {
        let s = r.step(&actions(2, k)).unwrap();
        if k < 19 {
            assert!(!s.truncated[0] && !s.terminated[0], "step {k}");
            last = row(&s.obs, 0, OBS_DIM);
        } else {
            assert!(s.truncated[0] && s.truncated[1]);
            let final0 = row(&s.final_obs, 0, OBS_DIM);
            assert_ne!(final0, last, "final obs is the last step's");
            // The new episode starts with a full window left.
            assert_eq!(s.obs[OBS_DIM - 1], 1.0);
            assert!((final0[OBS_DIM - 1] - 0.0).abs() < 1e-6);
            assert_eq!(s.info[info::EPISODE_STEPS], 20.0);
        }
        wakes.push(s.wake_seed.clone());
    }
    let s = r.step(&actions(2, 20)).unwrap();
    assert_ne!(
        s.wake_seed, wakes[1],
        "the next episode draws new wake seeds"
    );
}

#[test]
fn next_step_autoreset_resets_in_the_following_step() {
    let mut r = Runner::new(1, 1, Autoreset::NextStep);
    for k in 0..20 {
        let s = r.step(&actions(1, k)).unwrap();
        assert_eq!(s.truncated[0], k == 19);
        assert!(!s.autoreset[0]);
    }
    let s = r.step(&[9.0; 4]).unwrap();
    assert!(s.autoreset[0] && !s.truncated[0] && !s.terminated[0]);
    assert_eq!(s.reward[0], 0.0);
    assert_eq!(s.obs[OBS_DIM - 1], 1.0);
    let s = r.step(&actions(1, 0)).unwrap();
    assert!(!s.autoreset[0]);
    assert_eq!(s.info[info::EPISODE_STEPS], 1.0);
}

#[test]
fn seeds_reset_and_replay_and_per_env_seeds_match_a_single_env() {
    let mut a = Runner::new(3, 2, Autoreset::SameStep);
    let first = a.reset(SeedSpec::Base(5));
    let h1: Vec<Step> = (0..5).map(|k| a.step(&actions(3, k)).unwrap()).collect();
    assert_eq!(a.reset(SeedSpec::Base(5)), first);
    let h2: Vec<Step> = (0..5).map(|k| a.step(&actions(3, k)).unwrap()).collect();
    assert_eq!(h1, h2);
    assert_ne!(a.reset(SeedSpec::Next), first);

    let per_env = a.reset(SeedSpec::PerEnv(vec![40, 41, 42]));
    let mut single = Runner::new(1, 1, Autoreset::SameStep);
    assert_eq!(single.reset(SeedSpec::Base(41)), row(&per_env, 1, OBS_DIM));
    // An int seed s gives env i the base s + i, as gymnasium's SyncVectorEnv seeds sub-envs.
    assert_eq!(a.reset(SeedSpec::Base(40)), per_env);
}

#[test]
fn a_base_seed_never_leaves_the_seed_range() {
    let end = accd_sim::SEED_END;
    let top = end - 3;
    let mut a = Runner::new(3, 1, Autoreset::SameStep);
    let highest = a.reset(SeedSpec::Base(top));
    assert_eq!(
        highest,
        a.reset(SeedSpec::PerEnv(vec![top, top + 1, end - 1]))
    );
    a.step(&actions(3, 0)).unwrap();
    let mut obs = vec![0.0; 3 * OBS_DIM];
    let mut wake = vec![0; 3];
    for seed in [top + 1, end - 1, u64::MAX] {
        let buffers = ResetBuffers {
            obs: &mut obs,
            wake_seed: &mut wake,
        };
        let e = a
            .env
            .reset(SeedSpec::Base(seed), None, buffers)
            .unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains(&format!("`seed` = {seed}")) && text.contains(&top.to_string()),
            "{text}"
        );
        let e = BatchEnv::new(
            config().validated().unwrap(),
            3,
            seed,
            Autoreset::SameStep,
            1,
        )
        .err()
        .unwrap();
        assert!(e.to_string().contains("`seed`"), "{e}");
    }
    // A refused reset changed nothing: the envs step on as they would have.
    let mut b = Runner::new(3, 1, Autoreset::SameStep);
    b.reset(SeedSpec::Base(top));
    b.step(&actions(3, 0)).unwrap();
    assert_eq!(
        a.step(&actions(3, 1)).unwrap(),
        b.step(&actions(3, 1)).unwrap()
    );
    assert!(BatchEnv::new(
        config().validated().unwrap(),
        1,
        end - 1,
        Autoreset::SameStep,
        1
    )
    .is_ok());
    // A per-env list entry and a wake seed outside the range are refused, quoting the value.
    for seed in [end, u64::MAX] {
        let buffers = ResetBuffers {
            obs: &mut obs,
            wake_seed: &mut wake,
        };
        let e = a
            .env
            .reset(SeedSpec::PerEnv(vec![0, seed, 1]), None, buffers)
            .unwrap_err();
        assert!(e.to_string().contains(&format!("`seed` = {seed}")), "{e}");
        for schedule in [WakeSchedule::Fixed(seed), WakeSchedule::List(vec![1, seed])] {
            let e = a.env.set_wake_schedule(schedule).unwrap_err().to_string();
            assert!(
                e.contains(&format!("= {seed}")) && e.contains("[0, 2^63)"),
                "{e}"
            );
        }
    }
}

#[test]
fn a_masked_reset_restarts_only_the_selected_envs_and_cancels_their_pending_autoreset() {
    let mut r = Runner::new(3, 2, Autoreset::NextStep);
    let first = r.reset(SeedSpec::Base(20));
    let stepped = r.step(&actions(3, 0)).unwrap();
    let (n, mut obs, mut wake) = (3, vec![0.0; 3 * OBS_DIM], vec![0; 3]);
    let mask = [false, true, false];
    r.env
        .reset(
            SeedSpec::Base(20),
            Some(&mask),
            ResetBuffers {
                obs: &mut obs,
                wake_seed: &mut wake,
            },
        )
        .unwrap();
    assert_eq!(
        row(&obs, 1, OBS_DIM),
        row(&first, 1, OBS_DIM),
        "env 1 restarted"
    );
    for i in [0, 2] {
        assert_eq!(
            row(&obs, i, OBS_DIM),
            row(&stepped.obs, i, OBS_DIM),
            "env {i} left alone"
        );
    }
    assert_eq!(r.env.episode(0).unwrap().steps(), 1);
    assert_eq!(r.env.episode(1).unwrap().steps(), 0);
    // Run env 0 to its end, then reset it by mask: no autoreset happens at the next step.
    for k in 1..20 {
        r.step(&actions(n, k)).unwrap();
    }
    let mask = [true, true, true];
    r.env
        .reset(
            SeedSpec::Next,
            Some(&mask),
            ResetBuffers {
                obs: &mut obs,
                wake_seed: &mut wake,
            },
        )
        .unwrap();
    let s = r.step(&actions(n, 0)).unwrap();
    assert!(!s.autoreset.iter().any(|&a| a));
    assert!(r
        .env
        .reset(
            SeedSpec::Next,
            Some(&[true]),
            ResetBuffers {
                obs: &mut obs,
                wake_seed: &mut wake
            }
        )
        .is_err());
}

#[test]
fn disabled_autoreset_refuses_to_step_an_ended_env_until_it_is_reset() {
    let mut r = Runner::new(2, 1, Autoreset::Disabled);
    r.reset(SeedSpec::Base(4));
    for k in 0..20 {
        let s = r.step(&actions(2, k)).unwrap();
        assert_eq!(s.truncated[0], k == 19);
        assert!(!s.autoreset[0]);
    }
    let e = r.step(&actions(2, 20)).unwrap_err().to_string();
    assert!(e.contains("env 0") && e.contains("disabled"), "{e}");
    let (mut obs, mut wake) = (vec![0.0; 2 * OBS_DIM], vec![0; 2]);
    r.env
        .reset(
            SeedSpec::Next,
            Some(&[true, true]),
            ResetBuffers {
                obs: &mut obs,
                wake_seed: &mut wake,
            },
        )
        .unwrap();
    let s = r.step(&actions(2, 0)).unwrap();
    assert_eq!(s.info[info::EPISODE_STEPS], 1.0);
}

#[test]
fn wake_schedules_fix_or_cycle_the_wake_seed() {
    let mut r = Runner::new(2, 1, Autoreset::SameStep);
    r.env
        .set_wake_schedule(WakeSchedule::List(vec![
            1_000_000_000,
            1_000_000_001,
            1_000_000_002,
        ]))
        .unwrap();
    let n = r.env.num_envs();
    let mut wake = vec![0; n];
    let mut obs = vec![0.0; n * OBS_DIM];
    r.env
        .reset(
            SeedSpec::Base(3),
            None,
            ResetBuffers {
                obs: &mut obs,
                wake_seed: &mut wake,
            },
        )
        .unwrap();
    assert_eq!(wake, vec![1_000_000_000, 1_000_000_001]);
    let mut seen = vec![];
    for k in 0..21 {
        let s = r.step(&actions(2, k)).unwrap();
        seen.push(s.wake_seed.clone());
    }
    assert_eq!(seen[20], vec![1_000_000_002, 1_000_000_000]);
    r.env.set_wake_schedule(WakeSchedule::Fixed(9)).unwrap();
    r.env
        .reset(
            SeedSpec::Next,
            None,
            ResetBuffers {
                obs: &mut obs,
                wake_seed: &mut wake,
            },
        )
        .unwrap();
    assert_eq!(wake, vec![9, 9]);
    assert!(r.env.set_wake_schedule(WakeSchedule::List(vec![])).is_err());
}

#[test]
fn bad_actions_and_shapes_are_named_and_step_nothing() {
    let mut r = Runner::new(3, 1, Autoreset::SameStep);
    let before = r.s.clone();
    let mut a = actions(3, 0);
    a[2 * ACT_DIM + 1] = f32::INFINITY;
    let e = r.step(&a).unwrap_err().to_string();
    assert!(e.contains("env 2") && e.contains("component 1"), "{e}");
    assert_eq!(r.s, before);
    let e = r.step(&a[..5]).unwrap_err().to_string();
    assert!(e.contains("actions") && e.contains("12"), "{e}");
    assert_eq!(r.env.episode(0).unwrap().steps(), 0);
    assert!(r.env.episode(3).is_err());
    assert!(BatchEnv::new(config().validated().unwrap(), 0, 1, Autoreset::SameStep, 1).is_err());
}

#[test]
fn a_saved_batch_continues_bit_for_bit_and_foreign_states_are_refused() {
    let mut a = Runner::new(3, 2, Autoreset::SameStep);
    for k in 0..12 {
        a.step(&actions(3, k)).unwrap();
    }
    let saved = a.env.save().unwrap();
    let tail_a: Vec<Step> = (12..40).map(|k| a.step(&actions(3, k)).unwrap()).collect();
    let mut b = Runner::new(3, 1, Autoreset::SameStep);
    b.env.load(&saved).unwrap();
    let tail_b: Vec<Step> = (12..40).map(|k| b.step(&actions(3, k)).unwrap()).collect();
    assert_eq!(tail_a, tail_b);

    let mut c = Runner::new(2, 1, Autoreset::SameStep);
    assert!(c
        .env
        .load(&saved)
        .unwrap_err()
        .to_string()
        .contains("3 envs"));
    assert!(c.env.load(&saved[..saved.len() - 3]).is_err());
    let mut other = config();
    other.capture_window = 3.0;
    let mut d = BatchEnv::new(other.validated().unwrap(), 3, 1, Autoreset::SameStep, 1).unwrap();
    assert!(d
        .load(&saved)
        .unwrap_err()
        .to_string()
        .contains("configuration"));
}

#[test]
fn a_state_that_fails_in_its_last_env_changes_no_env() {
    let mut a = Runner::new(3, 2, Autoreset::SameStep);
    for k in 0..6 {
        a.step(&actions(3, k)).unwrap();
    }
    let mut b = Runner::new(3, 5, Autoreset::SameStep);
    b.step(&actions(3, 9)).unwrap();
    let before = b.env.state();
    // Envs 0 and 1 are fine; env 2's tether has one coordinate too many.
    let mut bad = a.env.state();
    bad.envs[2].episode.sim.q.push(0.0);
    let e = b.env.set_state(bad).unwrap_err().to_string();
    assert!(e.contains("envs[2].sim.q"), "{e}");
    assert_eq!(b.env.state(), before, "nothing half-applied");
    // Another wrong part, inside the turbulence.
    let mut bad = a.env.state();
    if let accd_sim::AirState::Turbulence(t) = &mut bad.envs[1].episode.sim.air {
        t.ring.pop();
    } else {
        panic!("the default config has turbulence");
    }
    let e = b.env.set_state(bad).unwrap_err().to_string();
    assert!(e.contains("envs[1].turbulence.ring"), "{e}");
    assert_eq!(b.env.state(), before);
    // The good state applies whole.
    b.env.set_state(a.env.state()).unwrap();
    assert_eq!(b.env.state(), a.env.state());
}
