//! The RL task's episode: observations finite and within bounds, the episode ends as documented,
//! the reward follows its formula, identical seeds give identical episodes, saved states continue
//! bit for bit, and a diverging simulation ends the episode with a flag instead of NaNs.

use std::sync::Arc;

use crate::support;
use support::{episode, seeds, stiff_roll};

use accd_sim::{EnvConfig, Episode, Equilibrium, Outcome, OBS_BOUND};

/// A 5 s window; the capture radius so small that no capture ends the episode early.
fn quick() -> EnvConfig {
    let mut physics = accd_sim::CaptureConfig::default();
    physics.boom.capture_radius = 1e-6;
    EnvConfig {
        physics,
        capture_window: 5.0,
        initial: accd_sim::task::InitialConfig {
            settle_time: 30.0,
            ..Default::default()
        },
        ..EnvConfig::default()
    }
}

/// A deterministic, varied action sequence: pitch and yaw sweeps (beyond the limit at times,
/// clipped) and a little roll.
fn action(k: usize) -> [f32; 4] {
    let t = k as f32 * 0.1;
    let pitch = 1.2 * (0.7 * t).sin();
    let yaw = 0.8 * (0.5 * t).cos();
    let roll = 0.05;
    [pitch + roll, pitch - roll, yaw - roll, yaw + roll]
}

fn run(ep: &mut Episode, steps: usize) -> Vec<(Outcome, Vec<f32>)> {
    (0..steps)
        .map(|k| {
            let o = ep.step(&action(k)).unwrap();
            assert!(!o.terminated, "step {k}: {o:?}");
            (o, ep.observation().to_vec())
        })
        .collect()
}

#[test]
fn episodes_truncate_at_the_capture_window_with_bounded_finite_observations() {
    let mut ep = episode(&quick(), 3);
    let out = run(&mut ep, 50);
    for (k, (o, obs)) in out.iter().enumerate() {
        assert!(obs.iter().all(|v| v.is_finite() && v.abs() <= OBS_BOUND));
        assert!(o.reward.is_finite());
        assert!(!o.terminated, "step {k}: {o:?}");
        assert_eq!(o.truncated, k == 49);
    }
    assert!(ep.done());
    assert!(
        ep.step(&[0.0; 4]).is_err(),
        "stepping an ended episode is an error"
    );
    ep.reset(seeds(4)).unwrap();
    assert!(!ep.done());
}

/// The fast air scheme: per-step sampling, ziggurat normals, on-demand turbulence lanes.
fn fast(mut config: EnvConfig) -> EnvConfig {
    config.physics.wake.sampling = accd_sim::AirSampling::PerStep;
    config.physics.turbulence.normal_sampler = accd_sim::NormalSampler::Ziggurat;
    config.physics.turbulence.lane_streams = accd_sim::LaneStreams::PerLane;
    config
}

#[test]
fn same_seeds_same_episode_and_saved_states_continue_bit_for_bit() {
    same_seeds_and_saved_states(quick());
    same_seeds_and_saved_states(fast(quick()));
}

/// Per-lane streams give the same turbulence whether the lanes are generated on demand (with
/// per-step sampling) or all of them (per-stage sampling): the two schemes differ only in the
/// sampling, which is what `scripts/compare_schemes.py` measures.
#[test]
fn per_lane_streams_do_not_depend_on_the_sampling_scheme() {
    let mut per_stage = fast(quick());
    per_stage.physics.wake.sampling = accd_sim::AirSampling::PerStage;
    let mut a = episode(&per_stage, 3);
    let mut b = episode(&fast(quick()), 3);
    let (ra, rb) = (run(&mut a, 30), run(&mut b, 30));
    // Close (the sampling differs by a first-order term in the forcing), not equal.
    let max = ra
        .iter()
        .zip(&rb)
        .flat_map(|((_, x), (_, y))| x.iter().zip(y).map(|(u, v)| (u - v).abs()))
        .fold(0.0f32, f32::max);
    assert!(
        max > 0.0 && max < 1e-3,
        "largest observation difference {max}"
    );
}

fn same_seeds_and_saved_states(config: EnvConfig) {
    let quick = || config.clone();
    let mut a = episode(&quick(), 7);
    let mut b = episode(&quick(), 7);
    let ra = run(&mut a, 20);
    let rb = run(&mut b, 20);
    assert_eq!(format!("{ra:?}"), format!("{rb:?}"));

    let bytes = postcard::to_allocvec(&a.state()).unwrap();
    let mut c = episode(&quick(), 99);
    c.set_state(postcard::from_bytes(&bytes).unwrap()).unwrap();
    assert_eq!(a.observation(), c.observation());
    let cloned = a.clone();
    let tail_a = run(&mut a, 25);
    let tail_c = run(&mut c, 25);
    let mut d = cloned;
    let tail_d = run(&mut d, 25);
    assert_eq!(format!("{tail_a:?}"), format!("{tail_c:?}"));
    assert_eq!(format!("{tail_a:?}"), format!("{tail_d:?}"));

    let mut e = episode(&quick(), 8);
    assert_ne!(format!("{:?}", run(&mut e, 5)), format!("{:?}", &ra[..5]));
}

#[test]
fn non_finite_actions_are_rejected_and_out_of_range_ones_clipped() {
    let mut a = episode(&quick(), 1);
    let mut b = episode(&quick(), 1);
    let e = a.step(&[0.0, f32::NAN, 0.0, 0.0]).unwrap_err().to_string();
    assert!(e.contains("action[1]"), "{e}");
    assert_eq!(a.steps(), 0);
    let oa = a.step(&[5.0, -7.0, 1.0, -1.0]).unwrap();
    let ob = b.step(&[1.0, -1.0, 1.0, -1.0]).unwrap();
    assert_eq!(oa, ob);
    assert_eq!(a.observation(), b.observation());
}

#[test]
fn capture_ends_the_episode_with_the_documented_bonus() {
    let mut config = quick();
    config.physics.boom.capture_radius = 100.0;
    config.physics.boom.max_closing_speed = 1000.0;
    let w = config.reward.clone();
    let mut ep = episode(&config, 2);
    let o = ep.step(&[0.0; 4]).unwrap();
    assert!(o.captured && o.terminated && !o.truncated);
    assert!(
        (o.time - 0.01).abs() < 1e-12,
        "captured at the first physics step"
    );
    let left = 49.0;
    let expected =
        w.proximity * (-o.distance / w.proximity_scale).exp() + w.capture + w.proximity * left;
    assert!(
        (o.reward - expected).abs() < 1e-12,
        "{} vs {expected}",
        o.reward
    );
}

#[test]
fn overload_and_envelope_exit_end_the_episode_with_the_penalty() {
    let mut config = quick();
    config.limits.overload_fraction = 1e-3;
    let w = config.reward.clone();
    let mut ep = episode(&config, 2);
    let o = ep.step(&[0.0; 4]).unwrap();
    assert!(o.overload && o.terminated && !o.captured);
    let expected = w.proximity * (-o.distance / w.proximity_scale).exp() - w.failure;
    assert!((o.reward - expected).abs() < 1e-12);

    let mut config = quick();
    config.limits.max_distance = 0.01;
    let mut ep = episode(&config, 2);
    let o = ep.step(&[1.0, 1.0, -1.0, -1.0]).unwrap();
    assert!(o.envelope_exit && o.terminated);
    let effort = 0.05 * 1.0 + 0.05 * 0.25;
    let expected = (-o.distance / 10.0f64).exp() - effort - 50.0;
    assert!(
        (o.reward - expected).abs() < 1e-12,
        "{} vs {expected}",
        o.reward
    );
}

#[test]
fn a_diverging_simulation_ends_with_a_flag_and_the_last_good_observation() {
    let config = Arc::new(stiff_roll(quick()).validated().unwrap());
    let eq = Arc::new(Equilibrium::settle(&config).unwrap());
    let mut ep = Episode::new(config, eq, seeds(1)).unwrap();
    let mut diverged = None;
    for k in 0..50 {
        let before = *ep.observation();
        let o = ep.step(&action(k)).unwrap();
        assert!(ep.observation().iter().all(|v| v.is_finite()));
        assert!(o.reward.is_finite());
        if o.diverged {
            assert!(o.terminated);
            assert_eq!(&before, ep.observation());
            diverged = Some(k);
            break;
        }
        assert!(!o.terminated, "ended otherwise: {o:?}");
    }
    assert!(diverged.is_some(), "expected a divergence");
    assert!(ep.divergence().is_some());
}
