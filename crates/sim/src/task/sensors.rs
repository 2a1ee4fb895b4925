//! An opt-in sensor model for the observation (`sensors` in [`crate::task::config::EnvConfig`]; off by
//! default, and then nothing here runs). It changes what the agent *sees*, never the physics:
//! the reward and the episode end read the true state, and every random number comes from the
//! sensor stream ([`crate::rng::SENSOR_STREAM`], keyed by the episode's initial-conditions seed),
//! which no physics stream shares.
//!
//! # What is sensed, and how
//! | observation | sensor | model |
//! |---|---|---|
//! | `boom_rel_x/y/z` | vision (camera on the ACCD looking at the boom tip) | range-dependent noise, update rate, latency, Markov dropouts; held between updates |
//! | `boom_rel_vx/vy/vz` | the same vision measurements | finite difference of the last two *received* measurements |
//! | `quat_*` | AHRS | constant per-episode attitude bias plus white noise, a small rotation in body axes; unit norm, w >= 0 |
//! | `rate_p/q/r` | gyros (IMU) | constant per-episode bias plus white noise |
//! | `accd_dx/dy/dz`, `accd_vx/vy/vz` | relative (moving-baseline) GNSS between aircraft and ACCD | white noise per axis |
//! | `tension` | load cell at the attachment | white noise |
//! | `flap_*`, `time_left` | actuator position feedback, clock | exact |
//!
//! Then the whole observation vector can be delayed by `delay_steps` agent steps (the first
//! observations of an episode repeat the initial one).
//!
//! ## Vision: noise
//! With `x` the true boom tip minus capture point (TA frame) at the time the measurement shows,
//! `r = |x|` and `u = x / r`, a measurement is `x + n` with
//!
//! ```text
//! sigma_range = noise_floor + range_noise * r^2        along the line of sight u
//! sigma_cross = noise_floor + bearing_noise * r        each of the two directions across it
//! n = sigma_cross g + (sigma_range - sigma_cross) (u . g) u,    g ~ N(0, I_3)
//! ```
//!
//! so that `u . n ~ N(0, sigma_range^2)` and the part of `n` normal to `u` has the standard
//! deviation `sigma_cross` in every direction. The range error grows with the square of the range
//! because a stereo camera triangulates depth from disparity, `Z = f B / d`, so a disparity
//! error `sigma_d` (pixels) gives `sigma_Z = Z^2 sigma_d / (f B)` (focal length `f` in pixels,
//! baseline `B`; e.g. Gallup, Frahm, Mordohai & Pollefeys, "Variable baseline/resolution
//! stereo", CVPR 2008, section 3); a monocular camera ranging on a target of known size `D` from
//! its apparent size `s = f D / Z` has the same form, `sigma_Z = Z^2 sigma_s / (f D)`. The
//! bearing error is an angle (detection and centroiding error over the focal length), so the
//! cross-range error grows linearly. `noise_floor` collects what does not scale with range
//! (the detected point wandering over the boom's tip, calibration). Defaults: `range_noise`
//! 1e-3 1/m is `sigma_d / (f B)` for a 0.25 px disparity error, `f` = 1000 px and a 0.25 m
//! baseline; `bearing_noise` 1 mrad is about one pixel at `f` = 1000 px; the floor is 2 cm.
//! The line of sight is the same in every frame, so this distribution does not depend on the
//! camera frame; the error of rotating a body-frame measurement into the TA frame with the
//! estimated attitude is not modelled (an assumption).
//!
//! ## Vision: timing, latency, dropouts
//! * **Latency.** The true `x` is recorded after every physics step in a ring buffer of
//!   `round(latency / tether.time_step) + 1` entries allocated at construction; a measurement
//!   taken at physics step `n` shows the state of step `n - round(latency / time_step)`. Before
//!   the episode's first step the history is the initial state.
//! * **Update rate.** Measurement `k` is taken at the first physics step at or after
//!   `k / update_rate` (k = 0 at the reset). Between measurements the observation holds the last
//!   received one. Rates that do not divide the physics rate give a period that alternates
//!   between the two neighbouring whole numbers of physics steps, `update_rate` on average.
//! * **Dropouts** (a Gilbert-Elliott two-state Markov chain: E. N. Gilbert, "Capacity of a
//!   burst-noise channel", Bell System Technical Journal 39, 1960): at each measurement the link
//!   goes from *received* to *lost* with probability `a` and from *lost* back to *received* with
//!   probability `b = 1 / dropout_burst`, with `a = dropout b / (1 - dropout)`, so that a fraction
//!   `dropout` of the measurements is lost (the chain's stationary probability of *lost*) in
//!   bursts of `dropout_burst` measurements on average (geometric lengths). A lost measurement
//!   changes nothing: the observation holds the last received one. Independent losses are the
//!   special case `dropout_burst = 1 / (1 - dropout)`. The reset's measurement is always received.
//!
//! ## Vision: the rate
//! `boom_rel_v*` is the finite difference of the last two received measurements over the times
//! of the states they show, `(m_1 - m_0) / (t_1 - t_0)`. This is what a vision sensor gives
//! without a motion model: the noise of the rate follows from the position noise and the update
//! rate (`sqrt(sigma_0^2 + sigma_1^2) / (t_1 - t_0)` per direction), it is as late as the
//! measurements (latency plus half an update period), and after a dropout the difference spans
//! the gap (less noise, more lag). A "noisy true rate" would instead hand the agent a velocity
//! whose error is independent of its position error, which no camera provides; filtering (an
//! alpha-beta or Kalman tracker) is the agent's or controller's job. At the reset the measurement
//! before the first one is a second, independent measurement of the initial state taken one
//! update period earlier (the history before the episode is the initial state held), so the
//! first rates show noise around zero, not the true initial rate.
//!
//! ## IMU and AHRS
//! Body rates: `omega_m = omega + b_g + sigma_g g` per axis, the bias `b_g ~ N(0, rate_bias^2)`
//! per axis drawn at the reset and constant over the episode (the turn-on bias of an
//! uncalibrated MEMS gyro), white noise per observation (IEEE Std 952-1997's rate white noise
//! sampled at the observation). Attitude: `q_m = q (x) exp(delta / 2)` with the body-axes
//! rotation vector `delta = b_a + sigma_a g` (bias per axis drawn at the reset), normalised and
//! put in the hemisphere w >= 0 like the true one. Defaults: 0.002 rad/s noise and 0.005 rad/s
//! bias (0.11 and 0.29 deg/s: an uncalibrated MEMS gyro), 0.1 deg attitude noise and 0.5 deg
//! bias per axis (MEMS AHRS datasheets give about 0.1-0.5 deg in roll and pitch and 0.5-2 deg in
//! heading in dynamic conditions; one value for the three axes here).
//!
//! ## GNSS and load cell
//! The ACCD's position offset and velocity relative to the aircraft from moving-baseline
//! (relative) GNSS between the two: white noise per axis, 5 cm and 5 cm/s by default (RTK
//! accuracy is 1-2 cm horizontally and about twice that vertically; the default allows for
//! the antenna lever arm and multipath under the aircraft). The attachment tension from a load
//! cell: white noise, 100 N by default (0.02 % of the tether's 550 kN breaking tension, a
//! load cell of 0.1 % full-scale accuracy sized for the 275 kN overload limit gives about 275 N
//! of bias-type error, of which the white part here is a fraction). GNSS and load cell have no
//! rate, latency or dropout of their own (they are sampled at the observation; the whole-vector
//! delay covers a common pipeline delay).
//!
//! # Cost and determinism
//! Nothing here allocates after construction. Every draw comes from one stream in a fixed order
//! (the vision's dropout draw and three normals at every measurement, received or not; thirteen
//! normals at every observation; six at the reset for the biases and six for the reset's two
//! vision measurements), so the sensor noise of an episode depends on its initial-conditions
//! seed and the configuration only.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::rng::{NormalSampler, Stream, StreamState, SENSOR_STREAM};
use crate::rotation;
use crate::state_format::{check_len, StateError};
use accd_spec::Rules;

type V3 = Vector3<f64>;

accd_spec::config_struct! {
    /// The vision sensor measuring the boom tip relative to the capture point (module docs).
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct VisionConfig {
        /// At most one measurement per physics step: not above 1 / `tether.time_step`.
        pub update_rate: f64 = 20.0, "Hz", "(0, 1000]",
            "measurements per second (at most 1 / tether.time_step); between them the observation holds the last received one";
        pub latency: f64 = 0.05, "s", "[0, 1]",
            "age of the state a measurement shows (rounded to whole physics steps)";
        pub noise_floor: f64 = 0.02, "m", "[0, 10]",
            "standard deviation of the error at zero range (along and across the line of sight)";
        pub range_noise: f64 = 1e-3, "1/m", "[0, 1]",
            "k in the range error noise_floor + k r^2 along the line of sight (stereo triangulation)";
        pub bearing_noise: f64 = 1e-3, "rad", "[0, 0.1]",
            "angular error: the cross-range error is noise_floor + bearing_noise r per direction";
        pub dropout: f64 = 0.05, "-", "[0, 0.5]",
            "fraction of measurements lost (stationary probability of the Markov chain's lost state)";
        pub dropout_burst: f64 = 3.0, "-", "[1, 1000]",
            "mean number of consecutive measurements lost in one dropout";
    }
}

/// Each field's range is all there is to check (the update rate against the physics step is
/// the environment's rule).
impl Rules for VisionConfig {}

accd_spec::config_struct! {
    /// The gyros and the attitude estimate (AHRS) of the ACCD (module docs).
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
    /// Relative GNSS between the aircraft and the ACCD (module docs).
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct GnssConfig {
        pub position_noise: f64 = 0.05, "m", "[0, 10]",
            "standard deviation of the white noise of each component of the ACCD's position";
        pub velocity_noise: f64 = 0.05, "m/s", "[0, 10]",
            "standard deviation of the white noise of each component of the ACCD's velocity";
    }
}

/// Each field's range is all there is to check.
impl Rules for GnssConfig {}

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
        (self.vision.latency / time_step).round() as usize
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

/// One received vision measurement: the value and the time of the state it shows (s, episode
/// time; negative before the episode's start).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Measurement {
    value: V3,
    time: f64,
}

/// The sensors of one episode (module docs): configuration, biases, vision history and hold,
/// observation delay line, and the stream.
#[derive(Debug, Clone)]
pub struct Sensors {
    config: SensorsConfig,
    layout: SensedLayout,
    time_step: f64,
    latency_steps: usize,
    /// Markov chain: P(received -> lost), P(lost -> received).
    to_lost: f64,
    to_received: f64,
    stream: Stream,
    rate_bias: V3,
    attitude_bias: V3,
    /// True boom-relative position after each of the last `latency_steps + 1` physics steps.
    history: Vec<V3>,
    /// Index of the newest entry of `history`.
    head: usize,
    /// Physics steps since the reset.
    steps: u64,
    /// Index of the next vision measurement.
    next_update: u64,
    lost: bool,
    last: Measurement,
    previous: Measurement,
    received: u64,
    dropped: u64,
    /// The last `delay_steps + 1` observations, `dim` values each.
    delayed: Vec<f32>,
    /// Index (in observations) of the newest entry of `delayed`.
    delayed_head: usize,
    /// `delayed` holds this episode's observations (false after a reset until the first one).
    delayed_filled: bool,
}

impl Sensors {
    /// The sensors of `config` (which must be enabled) at physics step `time_step` s for an
    /// observation of `layout`; every buffer is allocated here. Reset before use.
    pub fn new(config: &SensorsConfig, time_step: f64, layout: SensedLayout) -> Sensors {
        let latency_steps = config.latency_steps(time_step);
        let v = &config.vision;
        let to_received = 1.0 / v.dropout_burst;
        let to_lost = (v.dropout * to_received / (1.0 - v.dropout)).min(1.0);
        let blank = Measurement {
            value: V3::zeros(),
            time: 0.0,
        };
        Sensors {
            config: config.clone(),
            layout,
            time_step,
            latency_steps,
            to_lost,
            to_received,
            stream: Stream::with_sampler(0, SENSOR_STREAM, NormalSampler::Ziggurat),
            rate_bias: V3::zeros(),
            attitude_bias: V3::zeros(),
            history: vec![V3::zeros(); latency_steps + 1],
            head: 0,
            steps: 0,
            next_update: 1,
            lost: false,
            last: blank,
            previous: blank,
            received: 0,
            dropped: 0,
            delayed: vec![0.0; (config.delay_steps + 1) * layout.dim],
            delayed_head: 0,
            delayed_filled: false,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &SensorsConfig {
        &self.config
    }

    /// The vision latency in physics steps.
    pub fn latency_steps(&self) -> usize {
        self.latency_steps
    }

    /// Vision measurements received and lost since the reset (the reset's own two not counted).
    pub fn vision_counts(&self) -> (u64, u64) {
        (self.received, self.dropped)
    }

    /// The constant biases of this episode: body rates (rad/s) and attitude (rad, body axes).
    pub fn biases(&self) -> (V3, V3) {
        (self.rate_bias, self.attitude_bias)
    }

    /// Starts an episode: a fresh stream of `seed` (the initial-conditions seed), biases drawn,
    /// the vision history filled with the initial boom-relative position `boom_rel` and the
    /// reset's measurement taken (received), the delay line emptied.
    pub fn reset(&mut self, seed: u64, boom_rel: &V3) {
        self.stream = Stream::with_sampler(seed, SENSOR_STREAM, NormalSampler::Ziggurat);
        let imu = &self.config.imu;
        let (rb, ab) = (imu.rate_bias, imu.attitude_bias_deg.to_radians());
        self.rate_bias = V3::new(self.normal(rb), self.normal(rb), self.normal(rb));
        self.attitude_bias = V3::new(self.normal(ab), self.normal(ab), self.normal(ab));
        self.history.fill(*boom_rel);
        self.head = 0;
        self.steps = 0;
        self.next_update = 1;
        self.lost = false;
        self.received = 0;
        self.dropped = 0;
        let shown = -(self.latency_steps as f64) * self.time_step;
        self.previous = Measurement {
            value: boom_rel + self.vision_noise(boom_rel),
            time: shown - 1.0 / self.config.vision.update_rate,
        };
        self.last = Measurement {
            value: boom_rel + self.vision_noise(boom_rel),
            time: shown,
        };
        self.delayed_filled = false;
        self.delayed_head = 0;
    }

    /// After a physics step: records the true boom-relative position `boom_rel` (m) and takes a
    /// vision measurement if one is due (module docs).
    pub fn physics_step(&mut self, boom_rel: &V3) {
        self.steps += 1;
        self.head = (self.head + 1) % self.history.len();
        self.history[self.head] = *boom_rel;
        let elapsed = self.steps as f64 * self.time_step;
        let due = elapsed * self.config.vision.update_rate;
        if due + 1e-9 < self.next_update as f64 {
            return;
        }
        self.next_update = (due + 1e-9).floor() as u64 + 1;
        // The oldest entry: `latency_steps` physics steps before the newest.
        let shown = self.history[(self.head + 1) % self.history.len()];
        let u = self.stream.uniform();
        self.lost = if self.lost {
            u >= self.to_received
        } else {
            u < self.to_lost
        };
        let noise = self.vision_noise(&shown);
        if self.lost {
            self.dropped += 1;
        } else {
            self.received += 1;
            self.previous = self.last;
            self.last = Measurement {
                value: shown + noise,
                time: elapsed - self.latency_steps as f64 * self.time_step,
            };
        }
    }

    /// Replaces the true values of the sensed quantities in `raw` (physical units, the layout's
    /// places; the attitude in the hemisphere w >= 0) by their measurements.
    pub fn sense(&mut self, raw: &mut [f64]) {
        let l = self.layout;
        let rate = (self.last.value - self.previous.value) / (self.last.time - self.previous.time);
        for i in 0..3 {
            raw[l.boom_rel + i] = self.last.value[i];
            raw[l.boom_rel_rate + i] = rate[i];
        }
        let gnss = &self.config.gnss;
        let (sp, sv) = (gnss.position_noise, gnss.velocity_noise);
        for i in 0..3 {
            raw[l.position + i] += self.normal(sp);
        }
        for i in 0..3 {
            raw[l.velocity + i] += self.normal(sv);
        }
        let sa = self.config.imu.attitude_noise_deg.to_radians();
        let delta = self.attitude_bias + V3::new(self.normal(sa), self.normal(sa), self.normal(sa));
        let a = l.attitude;
        let q = UnitQuaternion::new_normalize(Quaternion::new(
            raw[a],
            raw[a + 1],
            raw[a + 2],
            raw[a + 3],
        ));
        let m = (q * rotation::from_scaled_axis(delta)).into_inner();
        let sign = if m.w < 0.0 { -1.0 } else { 1.0 };
        raw[a] = sign * m.w;
        raw[a + 1] = sign * m.i;
        raw[a + 2] = sign * m.j;
        raw[a + 3] = sign * m.k;
        let sg = self.config.imu.rate_noise;
        for i in 0..3 {
            raw[l.body_rates + i] += self.rate_bias[i] + self.normal(sg);
        }
        raw[l.tension] += self.normal(self.config.tension_noise);
    }

    /// Puts `obs` (one scaled observation) into the delay line and replaces it by the one of
    /// `delay_steps` calls ago (the first of the episode while there are fewer).
    pub fn delay(&mut self, obs: &mut [f32]) {
        let dim = self.layout.dim;
        let slots = self.config.delay_steps + 1;
        if !self.delayed_filled {
            for slot in self.delayed.chunks_exact_mut(dim) {
                slot.copy_from_slice(obs);
            }
            self.delayed_filled = true;
            self.delayed_head = 0;
            return;
        }
        self.delayed_head = (self.delayed_head + 1) % slots;
        let at = self.delayed_head * dim;
        self.delayed[at..at + dim].copy_from_slice(obs);
        let oldest = ((self.delayed_head + 1) % slots) * dim;
        obs.copy_from_slice(&self.delayed[oldest..oldest + dim]);
    }

    /// `sigma` times a standard normal deviate of the stream.
    #[inline]
    fn normal(&mut self, sigma: f64) -> f64 {
        sigma * self.stream.gaussian()
    }

    /// A draw of the vision error at the true boom-relative position `x` (module docs).
    fn vision_noise(&mut self, x: &V3) -> V3 {
        let v = &self.config.vision;
        let r = x.norm();
        let along = v.noise_floor + v.range_noise * r * r;
        let across = v.noise_floor + v.bearing_noise * r;
        let g = V3::new(
            self.stream.gaussian(),
            self.stream.gaussian(),
            self.stream.gaussian(),
        );
        let u = if r > 0.0 { x / r } else { V3::zeros() };
        across * g + (along - across) * u.dot(&g) * u
    }

    /// The dynamic state (stream, biases, vision history and hold, delay line).
    pub fn state(&self) -> SensorState {
        SensorState {
            stream: self.stream.state(),
            rate_bias: self.rate_bias.into(),
            attitude_bias: self.attitude_bias.into(),
            history: self.history.iter().map(|v| (*v).into()).collect(),
            head: self.head as u64,
            steps: self.steps,
            next_update: self.next_update,
            lost: self.lost,
            last: self.last.value.into(),
            last_time: self.last.time,
            previous: self.previous.value.into(),
            previous_time: self.previous.time,
            received: self.received,
            dropped: self.dropped,
            delayed: self.delayed.clone(),
            delayed_head: self.delayed_head as u64,
            delayed_filled: self.delayed_filled,
        }
    }

    /// Restores a state of [`Sensors::state`] of sensors with the same configuration, checked
    /// whole first (lengths and indices): on an error nothing changed.
    pub fn set_state(&mut self, state: &SensorState) -> Result<(), StateError> {
        check_len("sensors.history", state.history.len(), self.history.len())?;
        check_len("sensors.delayed", state.delayed.len(), self.delayed.len())?;
        if state.head >= self.history.len() as u64 {
            return Err(StateError::invalid(
                "sensors.head",
                state.head,
                format!("below {}", self.history.len()),
            ));
        }
        let slots = self.config.delay_steps as u64 + 1;
        if state.delayed_head >= slots {
            return Err(StateError::invalid(
                "sensors.delayed_head",
                state.delayed_head,
                format!("below {slots}"),
            ));
        }
        if state.stream.chacha.stream != SENSOR_STREAM {
            return Err(StateError::invalid(
                "sensors.stream.chacha.stream",
                state.stream.chacha.stream,
                format!("the sensor stream's label {SENSOR_STREAM}"),
            ));
        }
        self.stream = Stream::from_state(&state.stream, NormalSampler::Ziggurat);
        self.rate_bias = state.rate_bias.into();
        self.attitude_bias = state.attitude_bias.into();
        for (h, s) in self.history.iter_mut().zip(&state.history) {
            *h = (*s).into();
        }
        self.head = state.head as usize;
        self.steps = state.steps;
        self.next_update = state.next_update;
        self.lost = state.lost;
        self.last = Measurement {
            value: state.last.into(),
            time: state.last_time,
        };
        self.previous = Measurement {
            value: state.previous.into(),
            time: state.previous_time,
        };
        self.received = state.received;
        self.dropped = state.dropped;
        self.delayed.copy_from_slice(&state.delayed);
        self.delayed_head = state.delayed_head as usize;
        self.delayed_filled = state.delayed_filled;
        Ok(())
    }
}

/// The dynamic state of [`Sensors`].
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorState {
    /// The sensor stream.
    pub stream: StreamState,
    /// Body-rate biases, rad/s.
    pub rate_bias: [f64; 3],
    /// Attitude biases (body axes), rad.
    pub attitude_bias: [f64; 3],
    /// True boom-relative positions of the last physics steps (a ring), m.
    pub history: Vec<[f64; 3]>,
    /// Index of the newest entry of `history`.
    pub head: u64,
    /// Physics steps since the reset.
    pub steps: u64,
    /// Index of the next vision measurement.
    pub next_update: u64,
    /// The dropout chain is in its lost state.
    pub lost: bool,
    /// The last received measurement, m.
    pub last: [f64; 3],
    /// The time of the state it shows, s.
    pub last_time: f64,
    /// The one before, m.
    pub previous: [f64; 3],
    /// The time of the state it shows, s.
    pub previous_time: f64,
    /// Measurements received since the reset.
    pub received: u64,
    /// Measurements lost since the reset.
    pub dropped: u64,
    /// The delay line of scaled observations (a ring of `delay_steps + 1`).
    pub delayed: Vec<f32>,
    /// Index of its newest observation.
    pub delayed_head: u64,
    /// The delay line holds this episode's observations.
    pub delayed_filled: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn raw() -> Vec<f64> {
        let mut r = vec![0.0; layout().dim];
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
            let mut r = input.clone();
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
        bad.history.pop();
        let before = b.state();
        assert!(b
            .set_state(&bad)
            .unwrap_err()
            .to_string()
            .contains("sensors.history"));
        let mut bad = state.clone();
        bad.head = bad.history.len() as u64;
        assert!(b
            .set_state(&bad)
            .unwrap_err()
            .to_string()
            .contains("sensors.head"));
        let mut bad = state;
        bad.delayed_head = 3;
        assert!(b
            .set_state(&bad)
            .unwrap_err()
            .to_string()
            .contains("sensors.delayed_head"));
        assert_eq!(b.state(), before, "a refused state changes nothing");
    }
}
