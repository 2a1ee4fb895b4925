//! An opt-in sensor model for the observation (`sensors` in [`crate::task::config::EnvConfig`]; off by
//! default, and then nothing here runs). It changes what the agent *sees*, never the physics:
//! the reward and the episode end read the true state, and every random number comes from the
//! sensors' own streams, which no physics stream shares.
//!
//! # What is sensed, and how
//! | observation | sensor (component) | model |
//! |---|---|---|
//! | `boom_rel_x/y/z` | vision ([`vision`]: camera on the ACCD looking at the boom tip) | range-dependent noise, update rate, latency, Markov dropouts; held between updates |
//! | `boom_rel_vx/vy/vz` | the same vision measurements | finite difference of the last two *received* measurements |
//! | `quat_*` | AHRS ([`ahrs`]) | constant per-episode attitude bias plus white noise, a small rotation in body axes; unit norm, w >= 0 |
//! | `rate_p/q/r` | gyros of the IMU ([`gyro`]) | constant per-episode bias plus white noise |
//! | `accd_dx/dy/dz`, `accd_vx/vy/vz` | relative (moving-baseline) GNSS between aircraft and ACCD ([`gnss`]) | white noise per axis |
//! | `tension` | load cell at the attachment ([`load_cell`]) | white noise |
//! | `flap_*`, `time_left` | actuator position feedback, clock | exact |
//!
//! Then the whole observation vector can be delayed by `delay_steps` agent steps
//! ([`delay_line`]; the first observations of an episode repeat the initial one). Each sensor's
//! model, defaults and sources are in its module's docs.
//!
//! # Components
//! Each sensor is a component behind the [`Sensor`] trait (reset, physics step, sense, state) in
//! a file of its own. [`Sensors`] holds the configuration, the [`SensedLayout`], the list of
//! components (in the order of the table above: vision, gyro, AHRS, GNSS, load cell; a fixed
//! struct, so the calls are static) and the delay line.
//!
//! # Randomness
//! Each component draws from its **own** stream: ChaCha8 keyed by the episode's initial-conditions
//! seed, with the label [`crate::rng::sensor_stream`] of the sensor's name (`vision`, `gyro`,
//! `ahrs`, `gnss`, `load_cell`). So a sensor's numbers depend on the seed, its name and its own
//! configuration only: adding a sensor, or changing how many numbers one draws (the vision's
//! update rate, for instance), shifts no other sensor's numbers
//! (`changing_one_sensor_leaves_every_other_sensors_numbers_bit_identical`).
//!
//! # Where to add a sensor
//! A file in `sensors/` with its component (and its configuration section, if it has one), a
//! name not used before, one line in the `components!` list below and its construction in
//! [`Sensors::new`]; the state format changes with it
//! ([`crate::state_format::FORMAT_VERSION`]).
//!
//! # Cost and determinism
//! Nothing here allocates after construction. The sensor noise of an episode depends on its
//! initial-conditions seed and the configuration only.

pub mod ahrs;
pub mod delay_line;
pub mod gnss;
pub mod gyro;
pub mod load_cell;
pub mod sensor;
pub mod vision;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::state_format::StateError;
use crate::task::sensors::ahrs::{Ahrs, AhrsState};
use crate::task::sensors::delay_line::{DelayLine, DelayLineState};
use crate::task::sensors::gnss::{Gnss, GnssState};
use crate::task::sensors::gyro::{Gyro, GyroState};
use crate::task::sensors::load_cell::{LoadCell, LoadCellState};
use crate::task::sensors::vision::{Vision, VisionState};
use accd_spec::Rules;

pub use crate::task::sensors::gnss::GnssConfig;
pub use crate::task::sensors::sensor::{Sensor, Truth};
pub use crate::task::sensors::vision::VisionConfig;

type V3 = Vector3<f64>;

accd_spec::config_struct! {
    /// The gyros and the attitude estimate (AHRS) of the ACCD (module docs of `gyro` and `ahrs`).
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct ImuConfig {
        pub rate_noise: f64 = 0.002, "rad/s", "[0, 1]",
            "standard deviation of the white noise of each body rate";
        pub rate_bias: f64 = 0.005, "rad/s", "[0, 1]",
            "standard deviation of each body rate's constant bias, drawn at every reset";
        pub attitude_noise_deg: f64 = 0.1, "deg", "[0, 10]",
            "standard deviation of the white attitude error about each body axis";
        pub attitude_bias_deg: f64 = 0.5, "deg", "[0, 10]",
            "standard deviation of the constant attitude error about each body axis, drawn at every reset";
    }
}

/// Each field's range is all there is to check.
impl Rules for ImuConfig {}

accd_spec::config_struct! {
    /// The sensor model of the observation (module docs of `accd_sim::task::sensors`). Off by
    /// default: the observation is then the true state. Only the observation is sensed; the
    /// reward and the episode end use the true state.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct SensorsConfig {
        pub enabled: bool = false, "", "",
            "switches the sensor model on (the other keys of this section apply only then)";
        pub delay_steps: usize = 0, "-", "[0, 100]",
            "the whole observation is this many agent steps old (the first ones repeat the initial observation)";
        pub tension_noise: f64 = 100.0, "N", "[0, 1e5]",
            "standard deviation of the load cell's white noise on the attachment tension";
        pub vision: VisionConfig = VisionConfig::default(), "", "",
            "vision sensor: boom tip relative to the capture point, and its rate";
        pub imu: ImuConfig = ImuConfig::default(), "", "", "gyros and attitude estimate";
        pub gnss: GnssConfig = GnssConfig::default(), "", "",
            "relative GNSS: the ACCD's position offset and velocity";
    }
}

/// Each field's range is all there is to check. At its default (off) the section is left out of
/// written documents, so that configurations without sensors read, write and hash as before.
impl Rules for SensorsConfig {
    fn omitted(&self) -> bool {
        *self == SensorsConfig::default()
    }
}

impl SensorsConfig {
    /// The vision latency in whole physics steps of `time_step` s.
    pub fn latency_steps(&self, time_step: f64) -> usize {
        self.vision.latency_steps(time_step)
    }

    /// Heap bytes of one episode's sensor state at physics step `time_step` s with `dim`
    /// observation values (zero when off).
    pub fn bytes(&self, time_step: f64, dim: usize) -> usize {
        if !self.enabled {
            return 0;
        }
        (self.latency_steps(time_step) + 1) * std::mem::size_of::<[f64; 3]>()
            + (self.delay_steps + 1) * dim * std::mem::size_of::<f32>()
    }
}

/// Where the sensed quantities sit in the observation vector: the index of each group's first
/// value (the groups are contiguous, in the order their docs give).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SensedLayout {
    /// Length of the observation vector.
    pub dim: usize,
    /// Boom tip minus capture point, x, y, z (m).
    pub boom_rel: usize,
    /// Its rate, x, y, z (m/s).
    pub boom_rel_rate: usize,
    /// ACCD position offset, x, y, z (m).
    pub position: usize,
    /// ACCD velocity, x, y, z (m/s).
    pub velocity: usize,
    /// Attitude quaternion w, x, y, z.
    pub attitude: usize,
    /// Body rates p, q, r (rad/s).
    pub body_rates: usize,
    /// Attachment tension (N).
    pub tension: usize,
}

/// Declares the list of sensor components once: the struct of components, the struct of their
/// states (in the list's order, which is the state format's) and the calls that go to every
/// component in that order.
macro_rules! components {
    ($($field:ident: $sensor:ty => $state:ty),* $(,)?) => {
        /// The sensor components of one episode, one field per sensor (module docs).
        #[derive(Debug, Clone)]
        pub struct Components {
            $(
                #[doc = concat!("The `", stringify!($field), "` sensor.")]
                pub $field: $sensor,
            )*
        }

        /// The dynamic state of each sensor component, in the order of [`Components`].
        ///
        /// Part of the state format: a change is a change of
        /// [`crate::state_format::FORMAT_VERSION`].
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        pub struct ComponentStates {
            $(
                #[doc = concat!("The state of the `", stringify!($field), "` sensor.")]
                pub $field: $state,
            )*
        }

        impl Components {
            fn reset(&mut self, seed: u64, truth: &Truth) {
                $(self.$field.reset(seed, truth);)*
            }

            #[inline]
            fn physics_step(&mut self, truth: &Truth) {
                $(self.$field.physics_step(truth);)*
            }

            #[inline]
            fn sense(&mut self, raw: &mut [f64]) {
                $(self.$field.sense(raw);)*
            }

            fn state(&self) -> ComponentStates {
                ComponentStates {
                    $($field: self.$field.state(),)*
                }
            }

            /// Each component's state in turn: on an error, the components before it changed
            /// (the caller restores a copy, [`Sensors::set_state`]).
            fn set_state(&mut self, state: &ComponentStates) -> Result<(), StateError> {
                $(self.$field.set_state(&state.$field)?;)*
                Ok(())
            }
        }
    };
}

components! {
    vision: Vision => VisionState,
    gyro: Gyro => GyroState,
    ahrs: Ahrs => AhrsState,
    gnss: Gnss => GnssState,
    load_cell: LoadCell => LoadCellState,
}

/// The sensors of one episode (module docs): configuration, layout, components, and the delay
/// line of the whole observation.
#[derive(Debug, Clone)]
pub struct Sensors {
    config: SensorsConfig,
    components: Components,
    delay: DelayLine,
}

impl Sensors {
    /// The sensors of `config` (which must be enabled) at physics step `time_step` s for an
    /// observation of `layout`; every buffer is allocated here. Reset before use.
    pub fn new(config: &SensorsConfig, time_step: f64, layout: SensedLayout) -> Sensors {
        let imu = &config.imu;
        let components = Components {
            vision: Vision::new(
                &config.vision,
                time_step,
                layout.boom_rel,
                layout.boom_rel_rate,
            ),
            gyro: Gyro::new(imu.rate_noise, imu.rate_bias, layout.body_rates),
            ahrs: Ahrs::new(
                imu.attitude_noise_deg.to_radians(),
                imu.attitude_bias_deg.to_radians(),
                layout.attitude,
            ),
            gnss: Gnss::new(&config.gnss, layout.position, layout.velocity),
            load_cell: LoadCell::new(config.tension_noise, layout.tension),
        };
        Sensors {
            config: config.clone(),
            components,
            delay: DelayLine::new(config.delay_steps, layout.dim),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &SensorsConfig {
        &self.config
    }

    /// The components.
    pub fn components(&self) -> &Components {
        &self.components
    }

    /// The vision latency in physics steps.
    pub fn latency_steps(&self) -> usize {
        self.components.vision.latency_steps()
    }

    /// Vision measurements received and lost since the reset (the reset's own two not counted).
    pub fn vision_counts(&self) -> (u64, u64) {
        self.components.vision.counts()
    }

    /// The constant biases of this episode: body rates (rad/s) and attitude (rad, body axes).
    pub fn biases(&self) -> (V3, V3) {
        (self.components.gyro.bias(), self.components.ahrs.bias())
    }

    /// Starts an episode: every component reset with `seed` (the initial-conditions seed) and
    /// the initial boom-relative position `boom_rel`, the delay line emptied.
    pub fn reset(&mut self, seed: u64, boom_rel: &V3) {
        self.components.reset(
            seed,
            &Truth {
                boom_rel: *boom_rel,
            },
        );
        self.delay.reset();
    }

    /// After a physics step: every component records the true boom-relative position
    /// `boom_rel` (m) and measures if a measurement is due.
    #[inline]
    pub fn physics_step(&mut self, boom_rel: &V3) {
        self.components.physics_step(&Truth {
            boom_rel: *boom_rel,
        });
    }

    /// Replaces the true values of the sensed quantities in `raw` (physical units, the layout's
    /// places; the attitude in the hemisphere w >= 0) by their measurements.
    #[inline]
    pub fn sense(&mut self, raw: &mut [f64]) {
        self.components.sense(raw);
    }

    /// Puts `obs` (one scaled observation) into the delay line and replaces it by the one of
    /// `delay_steps` calls ago (the first of the episode while there are fewer).
    #[inline]
    pub fn delay(&mut self, obs: &mut [f32]) {
        self.delay.delay(obs);
    }

    /// The dynamic state: each component's, then the delay line's.
    pub fn state(&self) -> SensorState {
        SensorState {
            components: self.components.state(),
            delay: self.delay.state(),
        }
    }

    /// Restores a state of [`Sensors::state`] of sensors with the same configuration, checked
    /// whole (lengths, indices, each stream's label) into a copy first: on an error nothing
    /// changed.
    pub fn set_state(&mut self, state: &SensorState) -> Result<(), StateError> {
        let mut components = self.components.clone();
        components.set_state(&state.components)?;
        let mut delay = self.delay.clone();
        delay.set_state(&state.delay)?;
        self.components = components;
        self.delay = delay;
        Ok(())
    }
}

/// The dynamic state of [`Sensors`].
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorState {
    /// Each sensor component's state.
    pub components: ComponentStates,
    /// The delay line of the whole observation.
    pub delay: DelayLineState,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::sensor_stream;
    use nalgebra::{Quaternion, UnitQuaternion};

    const DT: f64 = 0.01;
    /// A small observation vector: the groups in the order of the real table, 20 values.
    const LAYOUT: SensedLayout = SensedLayout {
        dim: 20,
        boom_rel: 0,
        boom_rel_rate: 3,
        position: 6,
        velocity: 9,
        attitude: 12,
        body_rates: 16,
        tension: 19,
    };

    fn layout() -> SensedLayout {
        LAYOUT
    }

    /// Every noise off, no dropout, a measurement every physics step, no latency.
    fn exact() -> SensorsConfig {
        SensorsConfig {
            enabled: true,
            delay_steps: 0,
            tension_noise: 0.0,
            vision: VisionConfig {
                update_rate: 1.0 / DT,
                latency: 0.0,
                noise_floor: 0.0,
                range_noise: 0.0,
                bearing_noise: 0.0,
                dropout: 0.0,
                dropout_burst: 1.0,
            },
            imu: ImuConfig {
                rate_noise: 0.0,
                rate_bias: 0.0,
                attitude_noise_deg: 0.0,
                attitude_bias_deg: 0.0,
            },
            gnss: GnssConfig {
                position_noise: 0.0,
                velocity_noise: 0.0,
            },
        }
    }

    /// A ramp: distinct values at every physics step `n`.
    fn ramp(n: u64) -> V3 {
        V3::new(n as f64, -2.0 * n as f64, 0.5 * n as f64 + 3.0)
    }

    /// A raw observation whose attitude is the identity.
    fn raw() -> [f64; 20] {
        let mut r = [0.0; 20];
        r[LAYOUT.attitude] = 1.0;
        r
    }

    /// The vision position the sensors show now.
    fn seen(s: &mut Sensors) -> V3 {
        let mut r = raw();
        s.sense(&mut r);
        V3::new(r[0], r[1], r[2])
    }

    fn seen_rate(s: &mut Sensors) -> V3 {
        let mut r = raw();
        s.sense(&mut r);
        V3::new(r[3], r[4], r[5])
    }

    #[test]
    fn latency_shifts_the_signal_by_exactly_its_physics_steps() {
        for (latency, steps) in [(0.0, 0), (0.05, 5), (0.104, 10), (0.37, 37)] {
            let mut c = exact();
            c.vision.latency = latency;
            let mut s = Sensors::new(&c, DT, layout());
            assert_eq!(s.latency_steps(), steps);
            s.reset(1, &ramp(0));
            assert_eq!(seen(&mut s), ramp(0));
            for n in 1..200u64 {
                s.physics_step(&ramp(n));
                let want = ramp(n.saturating_sub(steps as u64));
                assert_eq!(seen(&mut s), want, "latency {latency}, step {n}");
            }
        }
    }

    #[test]
    fn the_update_rate_holds_values_between_updates() {
        // 25 Hz: every 4 physics steps; 30 Hz: periods of 3 and 4 steps, 30 a second.
        for (rate, period) in [(25.0, Some(4)), (10.0, Some(10)), (30.0, None)] {
            let mut c = exact();
            c.vision.update_rate = rate;
            let mut s = Sensors::new(&c, DT, layout());
            s.reset(2, &ramp(0));
            let mut updates = vec![0u64];
            let mut shown = seen(&mut s);
            for n in 1..=1000u64 {
                s.physics_step(&ramp(n));
                let now = seen(&mut s);
                if now != shown {
                    assert_eq!(now, ramp(n), "an update shows the state of its step");
                    updates.push(n);
                    shown = now;
                }
            }
            // 10 s of physics steps: `rate` updates a second, each the first step at or after
            // k / rate.
            assert_eq!(updates.len() as f64, 1.0 + 10.0 * rate, "{rate} Hz");
            for (k, n) in updates.iter().enumerate() {
                let due = ((k as f64 / rate) / DT - 1e-9).ceil() as u64;
                assert_eq!(*n, due, "{rate} Hz, update {k}");
                if let Some(p) = period {
                    assert_eq!(*n, k as u64 * p);
                }
            }
            assert_eq!(s.vision_counts(), (10 * rate as u64, 0));
        }
    }

    /// The lost fraction and the mean burst length of the Markov chain match the configuration.
    /// Tolerance: the lost fraction of N correlated draws has a standard deviation of about
    /// sqrt(p (1 - p) / N (1 + rho) / (1 - rho)) with rho = 1 - a - b; 5 of those.
    #[test]
    fn dropouts_occur_at_the_configured_rate_in_bursts_of_the_configured_length() {
        for (p, burst) in [(0.05, 3.0), (0.2, 1.25), (0.4, 10.0)] {
            let mut c = exact();
            c.vision.dropout = p;
            c.vision.dropout_burst = burst;
            let mut s = Sensors::new(&c, DT, layout());
            s.reset(3, &ramp(0));
            let n = 200_000u64;
            let (mut bursts, mut in_burst, mut last_seen) = (0u64, false, ramp(0));
            for k in 1..=n {
                s.physics_step(&ramp(k));
                let now = seen(&mut s);
                let lost = now != ramp(k);
                if lost {
                    assert_eq!(
                        now, last_seen,
                        "a lost measurement holds the last received one"
                    );
                    if !in_burst {
                        bursts += 1;
                    }
                } else {
                    last_seen = now;
                }
                in_burst = lost;
            }
            let (received, dropped) = s.vision_counts();
            assert_eq!(received + dropped, n);
            let fraction = dropped as f64 / n as f64;
            let b = 1.0 / burst;
            let a = p * b / (1.0 - p);
            let rho = 1.0 - a - b;
            let sd = (p * (1.0 - p) / n as f64 * (1.0 + rho) / (1.0 - rho)).sqrt();
            assert!(
                (fraction - p).abs() < 5.0 * sd,
                "p {p}: {fraction} (sd {sd})"
            );
            let mean_burst = dropped as f64 / bursts as f64;
            assert!(
                (mean_burst - burst).abs() < 0.05 * burst,
                "burst {burst}: {mean_burst}"
            );
        }
    }

    /// Sample mean and standard deviation of `x`.
    fn stats(x: &[f64]) -> (f64, f64) {
        let n = x.len() as f64;
        let mean = x.iter().sum::<f64>() / n;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var.sqrt())
    }

    /// Along the line of sight the error has sigma_range = floor + k r^2, across it
    /// floor + bearing r, zero mean. Tolerances: 5 standard errors of the mean (sigma / sqrt(N)),
    /// 3 % on the standard deviation (its standard error is sigma / sqrt(2 N), 0.5 % here).
    #[test]
    fn vision_noise_has_the_configured_statistics_along_and_across_the_line_of_sight() {
        let mut c = exact();
        c.vision.noise_floor = 0.02;
        c.vision.range_noise = 1e-3;
        c.vision.bearing_noise = 2e-3;
        let mut s = Sensors::new(&c, DT, layout());
        let x = V3::new(-12.0, 3.0, 4.0); // r = 13
        let r = x.norm();
        let u = x / r;
        let cross1 = u.cross(&V3::x()).normalize();
        let cross2 = u.cross(&cross1);
        s.reset(4, &x);
        let n = 20_000;
        let (mut along, mut a1, mut a2) = (vec![], vec![], vec![]);
        for _ in 0..n {
            s.physics_step(&x);
            let e = seen(&mut s) - x;
            along.push(e.dot(&u));
            a1.push(e.dot(&cross1));
            a2.push(e.dot(&cross2));
        }
        let sigma_range = 0.02 + 1e-3 * r * r;
        let sigma_cross = 0.02 + 2e-3 * r;
        for (what, x, sigma) in [
            ("range", &along, sigma_range),
            ("cross 1", &a1, sigma_cross),
            ("cross 2", &a2, sigma_cross),
        ] {
            let (mean, sd) = stats(x);
            assert!(
                mean.abs() < 5.0 * sigma / (n as f64).sqrt(),
                "{what}: mean {mean}"
            );
            assert!(
                (sd / sigma - 1.0).abs() < 0.03,
                "{what}: sd {sd}, want {sigma}"
            );
        }
    }

    /// The rate is the finite difference of the last two received measurements: exact on a
    /// noiseless ramp (also across dropouts), and on a constant signal its noise has the
    /// standard deviation sqrt(2) sigma / T per direction (3 %).
    #[test]
    fn the_rate_is_the_difference_of_the_last_two_received_measurements() {
        let mut c = exact();
        c.vision.update_rate = 20.0;
        c.vision.dropout = 0.3;
        c.vision.latency = 0.1;
        let mut s = Sensors::new(&c, DT, layout());
        s.reset(5, &ramp(0));
        assert_eq!(
            seen_rate(&mut s),
            V3::zeros(),
            "the history before the start is frozen"
        );
        let per_second = (ramp(1) - ramp(0)) / DT;
        for n in 1..2000u64 {
            s.physics_step(&ramp(n));
            // Once two measurements of the moving signal are in.
            if s.vision_counts().0 >= 2 && n > 20 {
                let rate = seen_rate(&mut s);
                assert!((rate - per_second).norm() < 1e-9, "step {n}: {rate}");
            }
        }
        let mut c = exact();
        c.vision.update_rate = 20.0;
        c.vision.noise_floor = 0.05;
        let mut s = Sensors::new(&c, DT, layout());
        let x = V3::new(-1.0, 0.0, 0.0);
        s.reset(6, &x);
        let mut rates = vec![];
        for n in 1..=100_000u64 {
            s.physics_step(&x);
            if n % 5 == 0 {
                rates.push(seen_rate(&mut s).y);
            }
        }
        let (mean, sd) = stats(&rates);
        let want = 2f64.sqrt() * 0.05 * 20.0;
        assert!(
            mean.abs() < 5.0 * want / (rates.len() as f64).sqrt(),
            "{mean}"
        );
        assert!((sd / want - 1.0).abs() < 0.03, "{sd} vs {want}");
    }

    /// Gyro and attitude errors: within an episode the mean error is the episode's bias and
    /// the spread the white noise; across episodes the biases have the configured spread.
    /// Tolerances as above (5 standard errors, 3 % on standard deviations, 8 % for the 1000
    /// biases, whose standard error is 2.2 %).
    #[test]
    fn imu_errors_are_a_constant_bias_plus_white_noise() {
        let mut c = exact();
        c.imu = ImuConfig {
            rate_noise: 0.002,
            rate_bias: 0.005,
            attitude_noise_deg: 0.2,
            attitude_bias_deg: 0.5,
        };
        let mut s = Sensors::new(&c, DT, layout());
        let l = LAYOUT;
        let truth = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
        let mut input = raw();
        let q = truth.into_inner();
        input[l.attitude..l.attitude + 4].copy_from_slice(&[q.w, q.i, q.j, q.k]);
        input[l.body_rates..l.body_rates + 3].copy_from_slice(&[1.0, -2.0, 0.5]);
        s.reset(7, &V3::x());
        let (rate_bias, attitude_bias) = s.biases();
        let n = 20_000;
        let (mut rate_err, mut att_err) = (vec![vec![]; 3], vec![vec![]; 3]);
        for _ in 0..n {
            let mut r = input;
            s.sense(&mut r);
            let m = UnitQuaternion::new_normalize(Quaternion::new(
                r[l.attitude],
                r[l.attitude + 1],
                r[l.attitude + 2],
                r[l.attitude + 3],
            ));
            // The error rotation in body axes: truth^-1 m.
            let delta = (truth.inverse() * m).scaled_axis();
            for i in 0..3 {
                rate_err[i].push(r[l.body_rates + i] - input[l.body_rates + i]);
                att_err[i].push(delta[i]);
            }
        }
        let sa = 0.2f64.to_radians();
        for i in 0..3 {
            let (mean, sd) = stats(&rate_err[i]);
            assert!((mean - rate_bias[i]).abs() < 5.0 * 0.002 / (n as f64).sqrt());
            assert!((sd / 0.002 - 1.0).abs() < 0.03, "{sd}");
            let (mean, sd) = stats(&att_err[i]);
            // The composition of the bias and noise rotations is their sum to first order.
            assert!((mean - attitude_bias[i]).abs() < 5.0 * sa / (n as f64).sqrt() + 1e-5);
            assert!((sd / sa - 1.0).abs() < 0.03, "{sd}");
        }
        let (mut gyro, mut att) = (vec![], vec![]);
        for seed in 0..1000 {
            s.reset(seed, &V3::x());
            let (g, a) = s.biases();
            gyro.extend(g.iter());
            att.extend(a.iter());
        }
        let (_, sd) = stats(&gyro);
        assert!((sd / 0.005 - 1.0).abs() < 0.08, "{sd}");
        let (_, sd) = stats(&att);
        assert!((sd / 0.5f64.to_radians() - 1.0).abs() < 0.08, "{sd}");
    }

    /// The measured quaternion is a unit quaternion with w >= 0, also where the true one has
    /// w near zero (the noise then flips the hemisphere half of the time).
    #[test]
    fn the_sensed_quaternion_is_unit_with_w_not_negative() {
        let mut c = exact();
        c.imu.attitude_noise_deg = 5.0;
        c.imu.attitude_bias_deg = 2.0;
        let mut s = Sensors::new(&c, DT, layout());
        s.reset(8, &V3::x());
        let a = LAYOUT.attitude;
        for (k, truth) in [
            [0.0, 1.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0],
            [0.01, 0.0, 0.0, 0.99995],
        ]
        .into_iter()
        .enumerate()
        {
            for _ in 0..2000 {
                let mut r = raw();
                r[a..a + 4].copy_from_slice(&truth);
                s.sense(&mut r);
                let q = &r[a..a + 4];
                let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                assert!((norm - 1.0).abs() < 1e-12, "{k}: {q:?}");
                assert!(q[0] >= 0.0, "{k}: {q:?}");
            }
        }
    }

    /// GNSS and the load cell add zero-mean white noise of the configured spread.
    #[test]
    fn gnss_and_load_cell_noise_have_the_configured_spread() {
        let mut c = exact();
        c.gnss.position_noise = 0.05;
        c.gnss.velocity_noise = 0.1;
        c.tension_noise = 150.0;
        let mut s = Sensors::new(&c, DT, layout());
        s.reset(9, &V3::x());
        let l = LAYOUT;
        let n = 20_000;
        let (mut p, mut v, mut t) = (vec![], vec![], vec![]);
        for _ in 0..n {
            let mut r = raw();
            r[l.tension] = 1e4;
            s.sense(&mut r);
            p.push(r[l.position + 2]);
            v.push(r[l.velocity]);
            t.push(r[l.tension] - 1e4);
        }
        for (x, sigma) in [(&p, 0.05), (&v, 0.1), (&t, 150.0)] {
            let (mean, sd) = stats(x);
            assert!(mean.abs() < 5.0 * sigma / (n as f64).sqrt(), "{mean}");
            assert!((sd / sigma - 1.0).abs() < 0.03, "{sd} vs {sigma}");
        }
    }

    #[test]
    fn the_delay_line_returns_the_observation_of_delay_steps_ago() {
        for d in [0usize, 1, 3] {
            let mut c = exact();
            c.delay_steps = d;
            let mut s = Sensors::new(&c, DT, layout());
            s.reset(10, &V3::x());
            let obs = |k: usize| -> Vec<f32> { (0..20).map(|i| (k * 100 + i) as f32).collect() };
            for k in 0..20 {
                let mut o = obs(k);
                s.delay(&mut o);
                assert_eq!(o, obs(k.saturating_sub(d)), "delay {d}, step {k}");
            }
            // A reset starts the line again from the new episode's first observation.
            s.reset(11, &V3::x());
            let mut o = obs(50);
            s.delay(&mut o);
            assert_eq!(o, obs(50));
            let mut o = obs(51);
            s.delay(&mut o);
            assert_eq!(o, if d == 0 { obs(51) } else { obs(50) });
        }
    }

    /// The default configuration's sensors, run over `steps` physics steps with an observation
    /// every 10: every value seen.
    fn run(seed: u64, steps: u64) -> Vec<f64> {
        let c = SensorsConfig {
            enabled: true,
            delay_steps: 2,
            ..SensorsConfig::default()
        };
        let mut s = Sensors::new(&c, DT, layout());
        s.reset(seed, &ramp(0));
        let mut out = vec![];
        for n in 1..=steps {
            s.physics_step(&(ramp(n) * 0.01));
            if n % 10 == 0 {
                let mut r = raw();
                s.sense(&mut r);
                out.extend(r);
            }
        }
        out
    }

    #[test]
    fn sensor_draws_are_deterministic_per_seed_and_differ_between_seeds() {
        let a = run(12, 500);
        assert_eq!(
            a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            run(12, 500).iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        let b = run(13, 500);
        let same = a.iter().zip(&b).filter(|(x, y)| x == y).count();
        // Only the exact entries (flaps, time left: zeros here) and the held ones can agree.
        let noisy = a.len() / 20 * 13;
        assert!(same <= a.len() - noisy, "{same} of {}", a.len());
    }

    #[test]
    fn a_saved_state_continues_exactly_and_bad_states_are_refused() {
        let c = SensorsConfig {
            enabled: true,
            delay_steps: 2,
            ..SensorsConfig::default()
        };
        let mut a = Sensors::new(&c, DT, layout());
        a.reset(14, &ramp(0));
        for n in 1..137 {
            a.physics_step(&ramp(n));
        }
        let bytes = postcard::to_allocvec(&a.state()).unwrap();
        let state: SensorState = postcard::from_bytes(&bytes).unwrap();
        let mut b = Sensors::new(&c, DT, layout());
        b.reset(99, &ramp(5));
        b.set_state(&state).unwrap();
        for n in 137..400 {
            a.physics_step(&ramp(n));
            b.physics_step(&ramp(n));
            let (mut ra, mut rb) = (raw(), raw());
            a.sense(&mut ra);
            b.sense(&mut rb);
            let (mut oa, mut ob) = (vec![n as f32; 20], vec![n as f32; 20]);
            a.delay(&mut oa);
            b.delay(&mut ob);
            assert_eq!(ra, rb);
            assert_eq!(oa, ob);
        }
        let mut bad = state.clone();
        bad.components.vision.history.pop();
        let before = b.state();
        assert!(b
            .set_state(&bad)
            .unwrap_err()
            .to_string()
            .contains("sensors.vision.history"));
        let mut bad = state.clone();
        bad.components.vision.head = bad.components.vision.history.len() as u64;
        assert!(b
            .set_state(&bad)
            .unwrap_err()
            .to_string()
            .contains("sensors.vision.head"));
        let mut bad = state.clone();
        bad.delay.head = 3;
        assert!(b
            .set_state(&bad)
            .unwrap_err()
            .to_string()
            .contains("sensors.delay.head"));
        // A stream of another sensor, after components that restore fine: refused whole.
        let mut bad = state;
        bad.components.load_cell.stream = bad.components.gnss.stream;
        bad.components.vision.steps += 1;
        let e = b.set_state(&bad).unwrap_err().to_string();
        assert!(e.contains("sensors.load_cell.stream.chacha.stream"), "{e}");
        assert_eq!(b.state(), before, "a refused state changes nothing");
    }

    /// Each component on its own, reset with the same seed, draws exactly the numbers it draws
    /// among the others: a sensor's numbers do not depend on which other sensors there are.
    #[test]
    fn a_sensor_alone_measures_what_it_measures_among_the_others() {
        let c = SensorsConfig {
            enabled: true,
            ..SensorsConfig::default()
        };
        let l = LAYOUT;
        let mut all = Sensors::new(&c, DT, layout());
        let mut vision = Vision::new(&c.vision, DT, l.boom_rel, l.boom_rel_rate);
        let mut gyro = Gyro::new(c.imu.rate_noise, c.imu.rate_bias, l.body_rates);
        let mut ahrs = Ahrs::new(
            c.imu.attitude_noise_deg.to_radians(),
            c.imu.attitude_bias_deg.to_radians(),
            l.attitude,
        );
        let mut gnss = Gnss::new(&c.gnss, l.position, l.velocity);
        let mut load_cell = LoadCell::new(c.tension_noise, l.tension);
        let truth = |n: u64| Truth {
            boom_rel: ramp(n) * 0.01,
        };
        all.reset(15, &truth(0).boom_rel);
        vision.reset(15, &truth(0));
        gyro.reset(15, &truth(0));
        ahrs.reset(15, &truth(0));
        gnss.reset(15, &truth(0));
        load_cell.reset(15, &truth(0));
        for n in 1..=300 {
            all.physics_step(&truth(n).boom_rel);
            vision.physics_step(&truth(n));
            if n % 10 == 0 {
                let mut together = raw();
                all.sense(&mut together);
                let mut alone = raw();
                vision.sense(&mut alone);
                gyro.sense(&mut alone);
                ahrs.sense(&mut alone);
                gnss.sense(&mut alone);
                load_cell.sense(&mut alone);
                assert_eq!(
                    together.map(f64::to_bits),
                    alone.map(f64::to_bits),
                    "step {n}"
                );
            }
        }
        // Only the components' own draws: the same seed gives each sensor other numbers.
        let mut r = raw();
        gyro.sense(&mut r);
        let mut q = raw();
        load_cell.sense(&mut q);
        assert_ne!(r[l.body_rates], q[l.tension]);
    }

    /// Every sensor has its own stream label, distinct from each other's and from the physics
    /// streams'.
    #[test]
    fn every_sensor_has_a_stream_of_its_own() {
        let names = [
            Vision::NAME,
            Gyro::NAME,
            Ahrs::NAME,
            Gnss::NAME,
            LoadCell::NAME,
        ];
        let mut labels: Vec<u64> = names.iter().map(|n| sensor_stream(n)).collect();
        labels.extend([
            crate::rng::WAKE_LANES_STREAM,
            crate::rng::AMBIENT_STREAM,
            crate::rng::RLV_STREAM,
            crate::task::episode::INITIAL_STREAM,
            crate::task::randomization::PARAMETERS_STREAM,
        ]);
        let mut sorted = labels.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), labels.len(), "{labels:x?}");
        let state = Sensors::new(&SensorsConfig::default(), DT, layout()).state();
        let c = &state.components;
        for (name, stream) in [
            ("vision", &c.vision.stream),
            ("gyro", &c.gyro.stream),
            ("ahrs", &c.ahrs.stream),
            ("gnss", &c.gnss.stream),
            ("load_cell", &c.load_cell.stream),
        ] {
            assert_eq!(stream.chacha.stream, sensor_stream(name), "{name}");
        }
    }
}
