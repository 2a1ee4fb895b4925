//! The vision sensor: a camera on the ACCD measuring the boom tip relative to the capture point
//! (`boom_rel_x/y/z`), and the rate derived from its measurements (`boom_rel_vx/vy/vz`).
//!
//! # Noise
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
//! # Timing, latency, dropouts
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
//! # The rate
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
//! # Draws
//! From the stream of the name `vision`: six normals at the reset (the reset's two
//! measurements), then at every measurement, received or not, the dropout chain's uniform and
//! three normals. Nothing after construction allocates.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::rng::{Stream, StreamState};
use crate::state_format::{check_len, StateError};
use crate::task::sensors::sensor::{noise_stream, restore_stream, Sensor, Truth};
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

impl VisionConfig {
    /// The latency in whole physics steps of `time_step` s.
    pub fn latency_steps(&self, time_step: f64) -> usize {
        (self.latency / time_step).round() as usize
    }
}

/// One received measurement: the value and the time of the state it shows (s, episode time;
/// negative before the episode's start).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Measurement {
    value: V3,
    time: f64,
}

/// The vision sensor of one episode (module docs): configuration, the history of the true
/// boom-relative position, the dropout chain, the last two received measurements.
#[derive(Debug, Clone)]
pub struct Vision {
    config: VisionConfig,
    /// Observation index of `boom_rel_x` and of `boom_rel_vx`.
    position_at: usize,
    rate_at: usize,
    time_step: f64,
    latency_steps: usize,
    /// Markov chain: P(received -> lost), P(lost -> received).
    to_lost: f64,
    to_received: f64,
    stream: Stream,
    /// True boom-relative position after each of the last `latency_steps + 1` physics steps.
    history: Vec<V3>,
    /// Index of the newest entry of `history`.
    head: usize,
    /// Physics steps since the reset.
    steps: u64,
    /// Index of the next measurement.
    next_update: u64,
    lost: bool,
    last: Measurement,
    previous: Measurement,
    received: u64,
    dropped: u64,
}

impl Vision {
    /// The vision sensor of `config` at physics step `time_step` s, writing the position at
    /// observation index `position_at` and the rate at `rate_at` (three values each); its history
    /// is allocated here. Reset before use.
    pub fn new(config: &VisionConfig, time_step: f64, position_at: usize, rate_at: usize) -> Self {
        let latency_steps = config.latency_steps(time_step);
        let to_received = 1.0 / config.dropout_burst;
        let to_lost = (config.dropout * to_received / (1.0 - config.dropout)).min(1.0);
        let blank = Measurement {
            value: V3::zeros(),
            time: 0.0,
        };
        Vision {
            config: config.clone(),
            position_at,
            rate_at,
            time_step,
            latency_steps,
            to_lost,
            to_received,
            stream: noise_stream(0, Self::NAME),
            history: vec![V3::zeros(); latency_steps + 1],
            head: 0,
            steps: 0,
            next_update: 1,
            lost: false,
            last: blank,
            previous: blank,
            received: 0,
            dropped: 0,
        }
    }

    /// The latency in physics steps.
    pub fn latency_steps(&self) -> usize {
        self.latency_steps
    }

    /// Measurements received and lost since the reset (the reset's own two not counted).
    pub fn counts(&self) -> (u64, u64) {
        (self.received, self.dropped)
    }

    /// A draw of the error at the true boom-relative position `x` (module docs).
    fn noise(&mut self, x: &V3) -> V3 {
        let v = &self.config;
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
}

impl Sensor for Vision {
    const NAME: &'static str = "vision";
    type State = VisionState;

    /// The history filled with the initial boom-relative position, the reset's measurement
    /// taken (received) and the one before it (module docs, "The rate").
    fn reset(&mut self, seed: u64, truth: &Truth) {
        self.stream = noise_stream(seed, Self::NAME);
        let x = truth.boom_rel;
        self.history.fill(x);
        self.head = 0;
        self.steps = 0;
        self.next_update = 1;
        self.lost = false;
        self.received = 0;
        self.dropped = 0;
        let shown = -(self.latency_steps as f64) * self.time_step;
        self.previous = Measurement {
            value: x + self.noise(&x),
            time: shown - 1.0 / self.config.update_rate,
        };
        self.last = Measurement {
            value: x + self.noise(&x),
            time: shown,
        };
    }

    fn physics_step(&mut self, truth: &Truth) {
        self.steps += 1;
        self.head = (self.head + 1) % self.history.len();
        self.history[self.head] = truth.boom_rel;
        let elapsed = self.steps as f64 * self.time_step;
        let due = elapsed * self.config.update_rate;
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
        let noise = self.noise(&shown);
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

    /// The last received measurement and the finite difference of the last two.
    fn sense(&mut self, raw: &mut [f64]) {
        let rate = (self.last.value - self.previous.value) / (self.last.time - self.previous.time);
        for i in 0..3 {
            raw[self.position_at + i] = self.last.value[i];
            raw[self.rate_at + i] = rate[i];
        }
    }

    fn state(&self) -> VisionState {
        VisionState {
            stream: self.stream.state(),
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
        }
    }

    fn set_state(&mut self, state: &VisionState) -> Result<(), StateError> {
        check_len(
            "sensors.vision.history",
            state.history.len(),
            self.history.len(),
        )?;
        if state.head >= self.history.len() as u64 {
            return Err(StateError::invalid(
                "sensors.vision.head",
                state.head,
                format!("below {}", self.history.len()),
            ));
        }
        self.stream = restore_stream(Self::NAME, &state.stream)?;
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
        Ok(())
    }
}

/// The dynamic state of [`Vision`].
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VisionState {
    /// The vision's noise stream.
    pub stream: StreamState,
    /// True boom-relative positions of the last physics steps (a ring), m.
    pub history: Vec<[f64; 3]>,
    /// Index of the newest entry of `history`.
    pub head: u64,
    /// Physics steps since the reset.
    pub steps: u64,
    /// Index of the next measurement.
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
}
