//! The sensor model in the episode (`sensors`): switching it on changes the observation only
//! (the physics, reward and episode end are bitwise those of the same seeds without it), its
//! draws are deterministic per seed, the latency and the observation delay shift the true
//! signal by exactly their steps, a saved state continues bit for bit, and each sensor draws
//! from its own stream: changing one sensor's parameters (also the vision's update rate, latency
//! and dropouts, which change how many numbers it draws) leaves every other sensor's measurements
//! bit for bit as they were.

use crate::support;
use support::episode;

use accd_sim::task::observation::{OBS_DIM, SENSED_LAYOUT};
use accd_sim::task::sensors::SensorsConfig;
use accd_sim::{observation_index, EnvConfig, Episode, Outcome, Sensors};
use nalgebra::Vector3;

/// A 5 s window; the capture radius so small that no capture ends the episode early.
fn quick(sensors: SensorsConfig) -> EnvConfig {
    let mut physics = accd_sim::CaptureConfig::default();
    physics.boom.capture_radius = 1e-6;
    EnvConfig {
        physics,
        capture_window: 5.0,
        initial: accd_sim::task::InitialConfig {
            settle_time: 30.0,
            ..Default::default()
        },
        sensors,
        ..EnvConfig::default()
    }
}

fn on() -> SensorsConfig {
    SensorsConfig {
        enabled: true,
        delay_steps: 1,
        ..SensorsConfig::default()
    }
}

/// Sensors on with every error off: no noise, no dropout, no latency, a measurement every
/// physics step.
fn exact() -> SensorsConfig {
    let mut s = on();
    s.delay_steps = 0;
    s.tension_noise = 0.0;
    s.vision.update_rate = 100.0;
    s.vision.latency = 0.0;
    s.vision.noise_floor = 0.0;
    s.vision.range_noise = 0.0;
    s.vision.bearing_noise = 0.0;
    s.vision.dropout = 0.0;
    s.imu.rate_noise = 0.0;
    s.imu.rate_bias = 0.0;
    s.imu.attitude_noise_deg = 0.0;
    s.imu.attitude_bias_deg = 0.0;
    s.gnss.position_noise = 0.0;
    s.gnss.velocity_noise = 0.0;
    s
}

/// Pitch and yaw sweeps and a little roll.
fn action(k: usize) -> [f32; 4] {
    let t = k as f32 * 0.1;
    let pitch = 1.2 * (0.7 * t).sin();
    let yaw = 0.8 * (0.5 * t).cos();
    let roll = 0.05;
    [pitch + roll, pitch - roll, yaw - roll, yaw + roll]
}

/// The outcomes and observations of `steps` agent steps, the initial observation first.
fn run(ep: &mut Episode, steps: usize) -> (Vec<Outcome>, Vec<Vec<f32>>) {
    let mut obs = vec![ep.observation().to_vec()];
    let outcomes = (0..steps)
        .map(|k| {
            let o = ep.step(&action(k)).unwrap();
            obs.push(ep.observation().to_vec());
            o
        })
        .collect();
    (outcomes, obs)
}

fn bits(o: &Outcome) -> [u64; 5] {
    [
        o.reward.to_bits(),
        o.distance.to_bits(),
        o.relative_speed.to_bits(),
        o.peak_tension.to_bits(),
        o.time.to_bits(),
    ]
}

#[test]
fn sensors_change_the_observation_only_never_the_physics() {
    let (off, sensed) = (quick(SensorsConfig::default()), quick(on()));
    for k in [1, 2, 3] {
        let (mut a, mut b) = (episode(&off, k), episode(&sensed, k));
        let (oa, xa) = run(&mut a, 40);
        let (ob, xb) = run(&mut b, 40);
        for (s, (p, q)) in oa.iter().zip(&ob).enumerate() {
            assert_eq!(bits(p), bits(q), "seed {k}, step {s}");
            assert_eq!(
                (
                    p.terminated,
                    p.truncated,
                    p.captured,
                    p.overload,
                    p.envelope_exit
                ),
                (
                    q.terminated,
                    q.truncated,
                    q.captured,
                    q.overload,
                    q.envelope_exit
                )
            );
        }
        assert_eq!(a.state().sim, b.state().sim, "seed {k}: the physics' state");
        let differ = xa.iter().zip(&xb).filter(|(p, q)| p != q).count();
        assert_eq!(
            differ,
            xa.len(),
            "every sensed observation differs from the truth"
        );
        // The same seed gives the same sensed observations; another seed others.
        let (_, again) = run(&mut episode(&sensed, k), 40);
        assert_eq!(again, xb);
        let (_, other) = run(&mut episode(&sensed, k + 10), 40);
        let tension = observation_index("tension").unwrap();
        assert!(other.iter().zip(&xb).all(|(p, q)| p[tension] != q[tension]));
    }
}

/// The true observation of an episode with sensors is, bit for bit, the observation of the same
/// episode (same seeds, same actions) without them, from the first observation on; keeping it
/// changes nothing else (the sensed observations, the outcomes and the physics are those of the
/// episode without it). Without sensors it is the observation itself.
#[test]
fn the_true_observation_is_the_observation_without_sensors() {
    let (off, sensed) = (quick(SensorsConfig::default()), quick(on()));
    for k in [1, 2] {
        let mut truth = episode(&off, k);
        let mut plain = episode(&sensed, k);
        let mut kept = episode(&sensed, k);
        kept.set_true_observation(true);
        assert!(plain.true_observation().is_none());
        let (_, expected) = run(&mut truth, 40);
        let (plain_outcomes, plain_obs) = run(&mut plain, 40);
        let mut true_obs = vec![kept.true_observation().unwrap().to_vec()];
        let mut outcomes = Vec::new();
        let mut obs = vec![kept.observation().to_vec()];
        for s in 0..40 {
            outcomes.push(kept.step(&action(s)).unwrap());
            obs.push(kept.observation().to_vec());
            true_obs.push(kept.true_observation().unwrap().to_vec());
        }
        let bits_of = |v: &[Vec<f32>]| -> Vec<Vec<u32>> {
            v.iter()
                .map(|o| o.iter().map(|x| x.to_bits()).collect())
                .collect()
        };
        assert_eq!(bits_of(&true_obs), bits_of(&expected), "seed {k}");
        assert_eq!(
            bits_of(&obs),
            bits_of(&plain_obs),
            "seed {k}: the sensed observations"
        );
        assert_ne!(
            obs, true_obs,
            "seed {k}: the sensors change the observation"
        );
        for (p, q) in outcomes.iter().zip(&plain_outcomes) {
            assert_eq!(bits(p), bits(q));
        }
        assert_eq!(
            kept.state().sim,
            truth.state().sim,
            "seed {k}: the physics' state"
        );
    }
    let mut bare = episode(&off, 3);
    bare.set_true_observation(true);
    for s in 0..10 {
        bare.step(&action(s)).unwrap();
        assert_eq!(bare.true_observation().unwrap(), bare.observation());
    }
}

#[test]
fn exact_sensors_show_the_true_state() {
    let (mut a, mut b) = (
        episode(&quick(SensorsConfig::default()), 4),
        episode(&quick(exact()), 4),
    );
    let (_, truth) = run(&mut a, 30);
    let (_, seen) = run(&mut b, 30);
    let rate = observation_index("boom_rel_vx").unwrap();
    for (k, (t, s)) in truth.iter().zip(&seen).enumerate() {
        for i in 0..t.len() {
            if (rate..rate + 3).contains(&i) {
                continue; // a finite difference of positions, not the true rate
            }
            // Positions and everything added to bitwise; the quaternion renormalised.
            assert!(
                (t[i] - s[i]).abs() <= 1e-6,
                "step {k}, entry {i}: {} vs {}",
                t[i],
                s[i]
            );
        }
        assert_eq!(t[..3], s[..3], "step {k}: the boom position exactly");
    }
}

/// A latency of 5 physics steps shows the boom-relative position of 0.05 s earlier: the
/// observation of an episode with sensors at agent step k is, bit for bit, the true one at
/// physics step 10 k - 5 (read from the same episode without sensors stepped one physics step
/// per agent step with the same commands).
#[test]
fn the_vision_latency_delays_the_true_signal_by_its_physics_steps() {
    let mut s = exact();
    s.vision.latency = 0.05;
    let mut fine = quick(SensorsConfig::default());
    fine.agent_step = 0.01;
    let (mut sensed, mut truth) = (episode(&quick(s), 5), episode(&fine, 5));
    let mut true_x = vec![truth.observation()[..3].to_vec()];
    for k in 0..300 {
        truth.step(&action(k / 10)).unwrap();
        true_x.push(truth.observation()[..3].to_vec());
    }
    assert_eq!(
        sensed.observation()[..3],
        true_x[0][..],
        "before the start: the initial state"
    );
    for k in 0..30 {
        sensed.step(&action(k)).unwrap();
        let step = 10 * (k + 1) - 5;
        assert_eq!(
            sensed.observation()[..3],
            true_x[step][..],
            "agent step {k}"
        );
    }
}

/// The observation delay repeats the observations of `delay_steps` agent steps earlier (the
/// initial one at first).
#[test]
fn the_observation_delay_shifts_the_whole_vector_by_its_agent_steps() {
    let mut s = on();
    s.delay_steps = 0;
    let mut d = on();
    d.delay_steps = 3;
    let (_, now) = run(&mut episode(&quick(s), 6), 30);
    let (_, late) = run(&mut episode(&quick(d), 6), 30);
    for k in 0..now.len() {
        assert_eq!(late[k], now[k.saturating_sub(3)], "step {k}");
    }
}

#[test]
fn a_state_saved_mid_episode_with_sensors_continues_bit_for_bit() {
    let config = quick(on());
    let mut a = episode(&config, 7);
    run(&mut a, 17);
    let state = a.state();
    assert!(state.sensors.is_some());
    let bytes = postcard::to_allocvec(&state).unwrap();
    let mut b = episode(&config, 8);
    b.set_state(postcard::from_bytes(&bytes).unwrap()).unwrap();
    let (oa, xa) = run(&mut a, 25);
    let (ob, xb) = run(&mut b, 25);
    assert_eq!(xa, xb);
    assert_eq!(
        oa.iter().map(bits).collect::<Vec<_>>(),
        ob.iter().map(bits).collect::<Vec<_>>()
    );
    // A sensor state into an episode without sensors, and the other way round, is refused.
    let mut off = episode(&quick(SensorsConfig::default()), 7);
    let e = off.set_state(state.clone()).unwrap_err().to_string();
    assert!(e.contains("sensors"), "{e}");
    let e = b.set_state(off.state()).unwrap_err().to_string();
    assert!(e.contains("sensors"), "{e}");
}

/// The physics step of the isolation test's sensors, s.
const TIME_STEP: f64 = 0.01;

/// The observation slots of each sensor: vision (position and rate), gyros, AHRS, GNSS, load cell.
fn slots() -> [(&'static str, Vec<usize>); 5] {
    let l = SENSED_LAYOUT;
    let run = |start: usize, n: usize| (start..start + n).collect::<Vec<_>>();
    [
        (
            "vision",
            [run(l.boom_rel, 3), run(l.boom_rel_rate, 3)].concat(),
        ),
        ("gyro", run(l.body_rates, 3)),
        ("ahrs", run(l.attitude, 4)),
        ("gnss", [run(l.position, 3), run(l.velocity, 3)].concat()),
        ("load_cell", vec![l.tension]),
    ]
}

/// The sensors' measurements (raw values, bits) of a moving signal over 600 physics steps, an
/// observation every 10 steps.
fn measurements(config: &SensorsConfig, seed: u64) -> Vec<[u64; OBS_DIM]> {
    let mut sensors = Sensors::new(config, TIME_STEP, SENSED_LAYOUT);
    let boom = |n: u64| Vector3::new(-20.0 + 0.01 * n as f64, 1.0 - 0.002 * n as f64, 2.0);
    sensors.reset(seed, &boom(0));
    let mut out = vec![];
    for n in 1..=600u64 {
        sensors.physics_step(&boom(n));
        if n % 10 == 0 {
            let mut raw = [0.0f64; OBS_DIM];
            raw[SENSED_LAYOUT.attitude] = 0.8;
            raw[SENSED_LAYOUT.attitude + 2] = 0.6;
            raw[SENSED_LAYOUT.body_rates] = 0.1;
            raw[SENSED_LAYOUT.tension] = 1.0e4;
            sensors.sense(&mut raw);
            out.push(raw.map(f64::to_bits));
        }
    }
    out
}

fn defaults() -> SensorsConfig {
    SensorsConfig {
        enabled: true,
        ..SensorsConfig::default()
    }
}

#[test]
fn changing_one_sensor_leaves_every_other_sensors_numbers_bit_identical() {
    let base = defaults();
    let mut variants: Vec<(&str, SensorsConfig)> = vec![];
    let mut c = defaults();
    c.vision.update_rate = 30.0;
    c.vision.latency = 0.08;
    c.vision.dropout = 0.2;
    variants.push(("vision", c));
    let mut c = defaults();
    c.imu.rate_noise *= 3.0;
    c.imu.rate_bias *= 2.0;
    variants.push(("gyro", c));
    let mut c = defaults();
    c.imu.attitude_noise_deg *= 3.0;
    c.imu.attitude_bias_deg *= 2.0;
    variants.push(("ahrs", c));
    let mut c = defaults();
    c.gnss.position_noise *= 3.0;
    c.gnss.velocity_noise *= 2.0;
    variants.push(("gnss", c));
    let mut c = defaults();
    c.tension_noise *= 3.0;
    variants.push(("load_cell", c));
    for seed in [3, 11] {
        let before = measurements(&base, seed);
        for (changed, config) in &variants {
            let after = measurements(config, seed);
            for (sensor, indices) in slots() {
                let differing = before
                    .iter()
                    .zip(&after)
                    .filter(|(b, a)| indices.iter().any(|&i| b[i] != a[i]))
                    .count();
                if sensor == *changed {
                    assert!(differing > 0, "{changed} changed, its numbers did not");
                } else {
                    assert_eq!(
                        differing, 0,
                        "seed {seed}: changing the {changed} shifted the {sensor}'s numbers"
                    );
                }
            }
        }
    }
}
