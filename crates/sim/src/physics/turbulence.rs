//! Turbulent velocity fluctuations: the wake's (RMS from its turbulent kinetic energy, paper
//! Eq. 1) and, optionally, the ambient atmosphere's (MIL-F-8785C), time-correlated, drawn from
//! the episode's **wake seed**, deterministic and cheap per step.
//!
//! # Model
//!
//! **Gust histories.** Each gust component is a unit-variance first-order Gauss-Markov process
//! (the Dryden longitudinal form, exponential autocorrelation `exp(-U_inf tau / L_t)`), advanced
//! on a fixed time grid of step `dt` ([`TurbulenceConfig::time_step_s`]) with the exact
//! discretisation
//!
//! ```text
//! g[j+1] = a g[j] + sqrt(1 - a^2) n[j],   a = exp(-U_inf dt / L_t),   n[j] ~ N(0, 1) iid,
//! ```
//!
//! started from the stationary distribution (`g ~ N(0, 1)`), so the variance is 1 at every step
//! and the autocorrelation at lag `m dt` is `a^m` exactly. All three components (x, y, z) use the
//! same first-order form and length scale (a simplification of Dryden's second-order lateral and
//! vertical filters; documented choice).
//!
//! **Frozen turbulence (Taylor).** The air moves through the TA frame at `-U_inf` along x, so a
//! point at `x < 0` sees at time `t` the air that crossed the plane `x = 0` (the attachment) at
//! time `t - tau`, `tau = -x / U_inf`. The histories are generated at that plane and kept in a
//! ring buffer (allocated once) covering `tau` up to
//! [`TurbulenceConfig::history_distance_m`]` / U_inf` (default 400 m, 2.2 s at 185 m/s);
//! points farther behind use the oldest sample, points ahead of the plane (`x > 0`) the newest.
//! Between grid times the history is interpolated linearly, `(1 - f) g[j] + f g[j+1]`, and divided
//! by `sqrt((1 - f)^2 + f^2 + 2 f (1 - f) a)` so that the variance stays exactly 1.
//!
//! **Lanes across the wake.** Wake turbulence has a small length scale
//! ([`TurbulenceConfig::wake_length_scale_m`] `L_t`, default 10 m: of the order of the fuselage
//! diameter and the wing chord of a 70 m aircraft; our choice). Independent histories ("lanes")
//! are generated on a grid in (y, z) spaced by `L_t` (default y in [-30, 30] m, z in [-10, 90] m:
//! 7 x 11 lanes around the trailing tether and the capturing device). A point is sampled from the
//! four lanes around it with bilinear weights `w_i`, renormalised to keep unit variance:
//! `sum w_i g_i / sqrt(sum w_i^2)`. Two points one spacing apart or more apart laterally are
//! uncorrelated; points outside the lane grid use its edge lanes.
//!
//! **Wake amplitude.** The wake fluctuation at `p` is `sqrt(2 k(p) / 3) g(p)` per component,
//! `k` from the wake tables (paper Eq. 1); zero where `k = 0`.
//!
//! **Ambient turbulence** (optional, [`AmbientTurbulence`]) follows MIL-F-8785C above 2000 ft:
//! length scale 1750 ft (533.4 m) for all components and, at 6000 m, sigma 1.7 (light),
//! 2.8 (moderate) or 7.0 m/s (severe) per component, or a custom sigma and length scale. It is one
//! lane (its length scale dwarfs the wake region, so it is coherent across it) from an independent
//! random stream, added to the wake fluctuation.
//!
//! # Random numbers and seeds
//!
//! Every random number comes from ChaCha8 ([`rand_chacha::ChaCha8Rng`], a fixed algorithm) via
//! our own derivation and Gaussian transform, so histories are bitwise reproducible across
//! platforms and library versions:
//!
//! * **Streams** ([`crate::rng::stream_rng`]): the 256-bit ChaCha key is four successive outputs of
//!   SplitMix64 started at the wake seed (little-endian), and the ChaCha stream (nonce) is a
//!   fixed label per use: [`crate::rng::WAKE_LANES_STREAM`] for the wake lanes, [`crate::rng::AMBIENT_STREAM`] for the
//!   ambient process. SplitMix64's output function is a bijective avalanche mix, so neighbouring
//!   seeds give unrelated keys, and distinct labels give independent ChaCha streams under one key.
//!   Adding ambient turbulence does not change the wake lanes' history.
//! * **Gaussians** ([`crate::rng::Stream`]): Box-Muller on two uniforms built from the top 53 bits of one
//!   `u64` each, `u1 = 1 - m1 2^-53` in (0, 1], `u2 = m2 2^-53` in [0, 1):
//!   `r = sqrt(-2 ln u1)`, `z0 = r cos(2 pi u2)`, `z1 = r sin(2 pi u2)`; both are used, in that
//!   order. |z| <= 8.57.
//!
//! The `u64` streams are identical on every platform. The Gaussians go through the platform's
//! `ln`, `sqrt`, `sin` and `cos`: histories are bitwise identical on one platform (same seed, same
//! history) and may differ in the last bits across platforms' math libraries.
//!
//! Per grid step the lanes' Gaussians are drawn lane by lane (lane index `iy * nz + iz`),
//! components x, y, z; then the ambient's x, y, z from its own stream.
//!
//! # Cost
//!
//! `advance` draws `3 * lanes (+ 3)` Gaussians per grid step (234 with the defaults);
//! [`Turbulence::sample`] reads 24 (+ 6) ring entries. Neither allocates.

use accd_spec::{join, out_of_range, Fields, OutOfRange, Range, Rules};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Result, SimError};
use crate::rng::StreamState;
use crate::rng::{NormalSampler, Stream, AMBIENT_STREAM, WAKE_LANES_STREAM};
use crate::state_format::{check_len, StateError};

/// MIL-F-8785C turbulence length scale above 2000 ft (1750 ft), m.
pub const MIL_LENGTH_SCALE_M: f64 = 533.4;

/// Most ring-buffer entries a turbulence may hold (lanes x components x history), 16 Mi.
const MAX_RING_ENTRIES: usize = 16 << 20;
/// Most wake lanes.
const MAX_LANES: usize = 4096;

/// Ambient (atmospheric) turbulence, MIL-F-8785C at 6000 m. Serialized in lowercase:
/// `"none"`, `"light"`, `"moderate"`, `"severe"`, or
/// `{"custom": {"sigma_mps": 2.0, "length_scale_m": 533.4}}`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum AmbientTurbulence {
    /// No ambient turbulence.
    #[default]
    None,
    /// Light: sigma 1.7 m/s per component, length scale 533.4 m.
    Light,
    /// Moderate: sigma 2.8 m/s per component, length scale 533.4 m.
    Moderate,
    /// Severe: sigma 7.0 m/s per component, length scale 533.4 m.
    Severe,
    /// Any level.
    Custom {
        /// RMS per component, m/s, [0, 50].
        sigma_mps: f64,
        /// Length scale, m, [1, 10000].
        length_scale_m: f64,
    },
}

impl AmbientTurbulence {
    /// RMS velocity per component, m/s.
    pub fn sigma_mps(&self) -> f64 {
        match *self {
            AmbientTurbulence::None => 0.0,
            AmbientTurbulence::Light => 1.7,
            AmbientTurbulence::Moderate => 2.8,
            AmbientTurbulence::Severe => 7.0,
            AmbientTurbulence::Custom { sigma_mps, .. } => sigma_mps,
        }
    }

    /// Length scale, m.
    pub fn length_scale_m(&self) -> f64 {
        match *self {
            AmbientTurbulence::Custom { length_scale_m, .. } => length_scale_m,
            _ => MIL_LENGTH_SCALE_M,
        }
    }

    fn is_on(&self) -> bool {
        !matches!(self, AmbientTurbulence::None)
    }
}

/// Where the wake lanes' random numbers come from ([`TurbulenceConfig::lane_streams`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LaneStreams {
    /// One stream for every lane, drawn lane by lane (x, y, z) at every grid step: every lane is
    /// generated all the time.
    Shared,
    /// Each lane from its own stream (label [`WAKE_LANES_STREAM`]` + 1 + lane`), so that a lane's
    /// history is a function of the seed and the lane alone. A lane can then be generated late,
    /// from the episode's start, once a point to be sampled comes near it
    /// ([`Turbulence::activate_box`]): which lanes are generated changes the cost, never a value.
    /// The capture simulation generates lanes on demand with `wake.sampling = "per_step"` (which
    /// declares every point it samples) and all of them otherwise; a standalone
    /// [`crate::WakeField`] generates all of them.
    #[default]
    PerLane,
}

accd_spec::config_struct! {
    /// Configuration of the turbulence (model in the [module docs](self)).
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct TurbulenceConfig {
        /// Off saves their cost when there is no wake; the wake fluctuation is then zero.
        pub wake_turbulence: bool = true, "", "", "generate the wake-turbulence lanes";
        pub wake_length_scale_m: f64 = 10.0, "m", "[1, 1000]",
            "length scale L_t of the wake turbulence and spacing of its lanes";
        pub lanes_y_m: [f64; 2] = [-30.0, 30.0], "m", "[-1000, 1000]",
            "lateral extent [min, max] of the lane grid (TA frame y)";
        pub lanes_z_m: [f64; 2] = [-10.0, 90.0], "m", "[-1000, 1000]",
            "vertical extent [min, max] of the lane grid (TA frame z, down)";
        pub history_distance_m: f64 = 400.0, "m", "[0, 5000]",
            "distance behind the attachment over which the frozen history is kept (400: the 250 m tether with margin)";
        pub time_step_s: f64 = 0.01, "s", "[1e-4, 0.1]", "step of the gust time grid (0.01: the physics step)";
        pub ambient: AmbientTurbulence = AmbientTurbulence::None, "", "",
            "ambient turbulence: \"none\", a preset or {\"custom\": {\"sigma_mps\", \"length_scale_m\"}}";
        /// [`NormalSampler`]: the ziggurat is 4-5x cheaper than Box-Muller (the first releases'
        /// sampler), another realisation of the same process per seed.
        pub normal_sampler: NormalSampler = NormalSampler::Ziggurat, "", "",
            "how the gusts' normal deviates are drawn: \"ziggurat\" or \"box_muller\" (the exact scheme)";
        /// [`LaneStreams`]: with `"per_lane"`, lanes far from the tether are not generated.
        pub lane_streams: LaneStreams = LaneStreams::PerLane, "", "",
            "where the wake lanes' random numbers come from: \"per_lane\" or \"shared\" (one stream, the exact scheme)";
    }
}

accd_spec::no_range!(AmbientTurbulence, NormalSampler, LaneStreams);

fn lane_count(range: [f64; 2], spacing: f64) -> usize {
    ((range[1] - range[0]) / spacing - 1e-9).ceil().max(0.0) as usize + 1
}

/// The lane extents in order, at most `MAX_LANES` (4096) lanes, a custom ambient turbulence's
/// intensity and length scale within their ranges.
impl Rules for TurbulenceConfig {
    fn check_rules(&self, prefix: &str) -> std::result::Result<(), OutOfRange> {
        let l = self.wake_length_scale_m;
        for (name, r) in [("lanes_y_m", self.lanes_y_m), ("lanes_z_m", self.lanes_z_m)] {
            if r[1] < r[0] {
                return Err(out_of_range(
                    &format!("{}[1]", join(prefix, name)),
                    r[1],
                    format!("[{}, 1000] m (not below {name}[0])", r[0]),
                ));
            }
        }
        let lanes = lane_count(self.lanes_y_m, l) * lane_count(self.lanes_z_m, l);
        if lanes > MAX_LANES {
            return Err(out_of_range(
                &join(prefix, "wake_length_scale_m"),
                l,
                format!(
                    "a spacing giving at most {MAX_LANES} lanes over the lane extents (gives {lanes})"
                ),
            ));
        }
        if let AmbientTurbulence::Custom {
            sigma_mps,
            length_scale_m,
        } = self.ambient
        {
            Range::closed(0.0, 50.0).check(
                &join(prefix, "ambient.custom.sigma_mps"),
                sigma_mps,
                "m/s",
            )?;
            Range::closed(1.0, 10_000.0).check(
                &join(prefix, "ambient.custom.length_scale_m"),
                length_scale_m,
                "m",
            )?;
        }
        Ok(())
    }
}

impl TurbulenceConfig {
    /// Number of wake-turbulence lanes (0 when wake turbulence is off).
    pub fn lanes(&self) -> usize {
        if !self.wake_turbulence {
            return 0;
        }
        let spacing = self.wake_length_scale_m;
        lane_count(self.lanes_y_m, spacing) * lane_count(self.lanes_z_m, spacing)
    }

    /// Channels per grid time: 3 per lane, then 3 ambient when on.
    pub fn channels(&self) -> usize {
        3 * self.lanes() + if self.ambient.is_on() { 3 } else { 0 }
    }

    /// Grid times the history keeps at `airspeed_mps` (one when there are no channels: nothing
    /// to keep, and filling an empty history of 4e10 grid times at 1e-6 m/s took hours).
    pub fn history_slots(&self, airspeed_mps: f64) -> usize {
        if self.channels() == 0 {
            return 1;
        }
        let max_delay = self.history_distance_m / airspeed_mps;
        (max_delay / self.time_step_s).ceil() as usize + 3
    }

    /// Bytes of one episode's gust history at `airspeed_mps` (f32 per channel and grid time).
    pub fn history_bytes(&self, airspeed_mps: f64) -> usize {
        self.history_slots(airspeed_mps)
            .saturating_mul(self.channels())
            .saturating_mul(std::mem::size_of::<f32>())
    }

    /// Checks that the gust history at `airspeed_mps` (the value of the field `airspeed_field`)
    /// holds at most [`MAX_RING_ENTRIES`] entries. The size follows from several fields, and
    /// the error names each of them: `history_distance_m` (the one refused), the airspeed, the
    /// grid step `time_step_s` and the channels (the lanes and the ambient turbulence).
    pub fn check_history(
        &self,
        airspeed_mps: f64,
        airspeed_field: &str,
    ) -> std::result::Result<(), OutOfRange> {
        let entries = self
            .history_slots(airspeed_mps)
            .saturating_mul(self.channels());
        if entries <= MAX_RING_ENTRIES {
            return Ok(());
        }
        Err(out_of_range(
            "turbulence.history_distance_m",
            self.history_distance_m,
            format!(
                "a distance giving at most {MAX_RING_ENTRIES} history entries (gives {entries}, \
                 {:.1} MiB per env: \
                 history_distance_m / {airspeed_field} / turbulence.time_step_s grid times at \
                 {airspeed_field} = {airspeed_mps} m/s and turbulence.time_step_s = {} s, times {} \
                 channels from turbulence.lanes_y_m, lanes_z_m, wake_length_scale_m and ambient); \
                 shorten turbulence.history_distance_m, raise {airspeed_field} or \
                 turbulence.time_step_s, or use fewer lanes",
                self.history_bytes(airspeed_mps) as f64 / (1024.0 * 1024.0),
                self.time_step_s,
                self.channels()
            ),
        ))
    }

    /// Checks every value against its declared range and the [`Rules`]; errors name the field
    /// as `turbulence.<field>`.
    pub fn validate(&self) -> Result<()> {
        Ok(self.check_fields("turbulence")?)
    }
}

/// Position of a point on a 1D lane axis: the first lane, the fraction towards the second, and
/// whether there is a second. Not [`crate::physics::interp::Axis`]: the lanes are a computed uniform
/// grid (first lane and spacing, no stored points) that may have a single lane, and beyond the
/// outer lanes a point takes the outer lane's gusts (a clamp, `Edge::Hold` in the table
/// interpolator's terms); its values (the lane histories) live in the turbulence's ring buffer.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LaneAxis {
    first: f64,
    inv_spacing: f64,
    count: usize,
}

impl LaneAxis {
    /// `(i, f)` with lanes i and i + 1 (i + 1 only when count > 1; f = 0 otherwise).
    #[inline]
    fn locate(&self, x: f64) -> (usize, usize, f64) {
        if self.count == 1 {
            return (0, 0, 0.0);
        }
        let r = ((x - self.first) * self.inv_spacing).clamp(0.0, (self.count - 1) as f64);
        let r = if r.is_nan() { 0.0 } else { r };
        let i = (r as usize).min(self.count - 2);
        (i, i + 1, r - i as f64)
    }
}

/// Interpolation in time: two ring slots, the fraction, and the variance-restoring factor.
#[derive(Debug, Clone, Copy)]
struct TimeStencil {
    slot0: usize,
    slot1: usize,
    f: f64,
}

/// Time-correlated wake and ambient turbulence of one episode. Build once, [`Turbulence::reset`]
/// per episode, [`Turbulence::advance`] once per physics step, [`Turbulence::sample`] anywhere.
#[derive(Debug, Clone)]
pub struct Turbulence {
    config: TurbulenceConfig,
    seed: u64,
    inv_airspeed: f64,
    dt: f64,
    inv_dt: f64,
    max_delay: f64,
    lanes_y: LaneAxis,
    lanes_z: LaneAxis,
    /// Number of wake lanes (0 when wake turbulence is off).
    lanes: usize,
    a_wake: f64,
    b_wake: f64,
    a_ambient: f64,
    b_ambient: f64,
    sigma_ambient: f64,
    ambient: bool,
    /// Channels per grid time: 3 per lane, then 3 ambient when on.
    channels: usize,
    /// Grid times kept.
    slots: usize,
    /// `slots * channels` values, lane-major: the history of each group of three channels (a
    /// wake lane, then the ambient) is contiguous, `ring[(group * slots + slot) * 3 + c]`; slot
    /// of grid index j is j mod slots. A point's samples at successive steps then sit side by
    /// side (a lane's history advances 12 bytes a step), where a slot-major ring put them a row
    /// of every channel apart: with many envs per thread the ring no longer streams from
    /// memory (BENCHMARKS.md). Saved states keep the slot-major order
    /// ([`TurbulenceState::ring`]).
    ring: Vec<f32>,
    /// Current value of every channel (full precision).
    state: Vec<f64>,
    /// Grid index of the newest generated time.
    newest: i64,
    /// Its ring slot, `newest mod slots`.
    newest_slot: usize,
    time: f64,
    /// The shared stream of every wake lane ([`LaneStreams::Shared`]).
    wake_rng: Stream,
    ambient_rng: Stream,
    /// [`LaneStreams::PerLane`]: one stream per lane, which lanes are generated, and the
    /// generated ones in the order they were activated.
    on_demand: bool,
    lane_rngs: Vec<Stream>,
    active: Vec<bool>,
    active_list: Vec<usize>,
    /// Lane-index rectangle `[iy0, iy1, iz0, iz1]` whose lanes are all generated.
    covered: Option<[usize; 4]>,
}

/// The ChaCha stream label of wake lane `lane` under [`LaneStreams::PerLane`].
pub fn lane_stream(lane: usize) -> u64 {
    WAKE_LANES_STREAM.wrapping_add(1 + lane as u64)
}

impl Turbulence {
    /// Turbulence advected at `airspeed_mps` (U_inf, m/s, (0, 400]) from the wake seed `seed`,
    /// at time 0 with its history filled (stationary from the start).
    pub fn new(config: &TurbulenceConfig, airspeed_mps: f64, seed: u64) -> Result<Turbulence> {
        config.validate()?;
        crate::physics::aircraft::check_airspeed("airspeed_mps", airspeed_mps)?;
        let dt = config.time_step_s;
        let spacing = config.wake_length_scale_m;
        let lanes_y = LaneAxis {
            first: config.lanes_y_m[0],
            inv_spacing: 1.0 / spacing,
            count: lane_count(config.lanes_y_m, spacing),
        };
        let lanes_z = LaneAxis {
            first: config.lanes_z_m[0],
            inv_spacing: 1.0 / spacing,
            count: lane_count(config.lanes_z_m, spacing),
        };
        let lanes = config.lanes();
        let ambient = config.ambient.is_on();
        let channels = config.channels();
        let max_delay = config.history_distance_m / airspeed_mps;
        let slots = config.history_slots(airspeed_mps);
        config.check_history(airspeed_mps, "airspeed_mps")?;
        let on_demand = config.lane_streams == LaneStreams::PerLane && lanes > 0;
        let a_wake = libm::exp(-airspeed_mps * dt / spacing);
        let a_ambient = libm::exp(-airspeed_mps * dt / config.ambient.length_scale_m());
        let mut t = Turbulence {
            config: config.clone(),
            seed,
            inv_airspeed: 1.0 / airspeed_mps,
            dt,
            inv_dt: 1.0 / dt,
            max_delay,
            lanes_y,
            lanes_z,
            lanes,
            a_wake,
            b_wake: (1.0 - a_wake * a_wake).sqrt(),
            a_ambient,
            b_ambient: (1.0 - a_ambient * a_ambient).sqrt(),
            sigma_ambient: config.ambient.sigma_mps(),
            ambient,
            channels,
            slots,
            ring: vec![0.0; slots * channels],
            state: vec![0.0; channels],
            newest: 0,
            newest_slot: 0,
            time: 0.0,
            wake_rng: Stream::with_sampler(seed, WAKE_LANES_STREAM, config.normal_sampler),
            ambient_rng: Stream::with_sampler(seed, AMBIENT_STREAM, config.normal_sampler),
            on_demand,
            lane_rngs: if on_demand {
                (0..lanes)
                    .map(|l| Stream::with_sampler(seed, lane_stream(l), config.normal_sampler))
                    .collect()
            } else {
                Vec::new()
            },
            active: vec![!on_demand; lanes],
            active_list: Vec::with_capacity(if on_demand { lanes } else { 0 }),
            covered: None,
        };
        t.reset(seed);
        Ok(t)
    }

    /// Restarts at time 0 from wake seed `seed`: new streams, a fresh stationary history.
    /// Allocates nothing.
    pub fn reset(&mut self, seed: u64) {
        self.seed = seed;
        let sampler = self.config.normal_sampler;
        self.wake_rng = Stream::with_sampler(seed, WAKE_LANES_STREAM, sampler);
        self.ambient_rng = Stream::with_sampler(seed, AMBIENT_STREAM, sampler);
        self.time = 0.0;
        // Grid indices -(slots - 1) ..= 0; the first from the stationary distribution.
        self.newest = self.first_index();
        let wake_channels = 3 * self.lanes;
        if self.on_demand {
            for (l, rng) in self.lane_rngs.iter_mut().enumerate() {
                *rng = Stream::with_sampler(seed, lane_stream(l), sampler);
            }
            self.active.fill(false);
            self.active_list.clear();
            // A clone's list has the capacity of its length: give it room for every lane here,
            // so that activating lanes while stepping never allocates.
            self.active_list.reserve(self.lanes);
            self.covered = None;
        } else {
            for c in 0..wake_channels {
                self.state[c] = self.wake_rng.gaussian();
            }
        }
        if self.ambient {
            for c in wake_channels..self.channels {
                self.state[c] = self.ambient_rng.gaussian();
            }
        }
        self.store_newest();
        while self.newest < 0 {
            self.generate();
        }
    }

    fn store_newest(&mut self) {
        let slot = self.newest.rem_euclid(self.slots as i64) as usize;
        self.newest_slot = slot;
        // The generated wake lanes (every lane with one stream), then the ambient group.
        if self.on_demand {
            for i in 0..self.active_list.len() {
                self.store_group(self.active_list[i], slot);
            }
        } else {
            for lane in 0..self.lanes {
                self.store_group(lane, slot);
            }
        }
        for group in self.lanes..self.channels / 3 {
            self.store_group(group, slot);
        }
    }

    /// Stores channel group `group`'s current values at `slot` of the ring.
    #[inline(always)]
    fn store_group(&mut self, group: usize, slot: usize) {
        let at = self.at(group, slot);
        let values = &self.state[3 * group..3 * group + 3];
        for (r, v) in self.ring[at..at + 3].iter_mut().zip(values) {
            *r = *v as f32;
        }
    }

    /// Grid index of the first (stationary) sample of every history.
    fn first_index(&self) -> i64 {
        -(self.slots as i64 - 1)
    }

    /// Index in the ring of channel group `group`'s (a wake lane's, or the ambient's: group
    /// `lanes`) three values at `slot`.
    #[inline(always)]
    fn at(&self, group: usize, slot: usize) -> usize {
        Self::ring_at(self.slots, group, slot)
    }

    /// [`Turbulence::at`] for a ring of `slots` grid times (where `self` is borrowed apart).
    #[inline(always)]
    fn ring_at(slots: usize, group: usize, slot: usize) -> usize {
        (group * slots + slot) * 3
    }

    /// The ring in the slot-major order of [`TurbulenceState::ring`].
    fn ring_slot_major(&self) -> Vec<f32> {
        let mut out = vec![0.0; self.ring.len()];
        for group in 0..self.channels / 3 {
            for slot in 0..self.slots {
                let from = self.at(group, slot);
                let to = slot * self.channels + 3 * group;
                out[to..to + 3].copy_from_slice(&self.ring[from..from + 3]);
            }
        }
        out
    }

    /// Takes a slot-major ring ([`TurbulenceState::ring`], of the ring's length) into the ring.
    fn set_ring_slot_major(&mut self, ring: &[f32]) {
        for group in 0..self.channels / 3 {
            for slot in 0..self.slots {
                let to = self.at(group, slot);
                let from = slot * self.channels + 3 * group;
                self.ring[to..to + 3].copy_from_slice(&ring[from..from + 3]);
            }
        }
    }

    /// Generates wake lane `lane` from the start up to the newest grid time, if it is not yet
    /// ([`LaneStreams::PerLane`]); the values are those it would have had if generated from
    /// the start. Allocates nothing.
    fn activate(&mut self, lane: usize) {
        if self.active[lane] {
            return;
        }
        self.active[lane] = true;
        self.active_list.push(lane);
        let (a, b) = (self.a_wake, self.b_wake);
        let first = self.first_index();
        let slots = self.slots;
        let rng = &mut self.lane_rngs[lane];
        let kept = self.newest - slots as i64 + 1;
        let mut g = [0.0; 3];
        for j in first..=self.newest {
            for gc in &mut g {
                *gc = if j == first {
                    rng.gaussian()
                } else {
                    a * *gc + b * rng.gaussian()
                };
            }
            if j >= kept {
                let slot = j.rem_euclid(slots as i64) as usize;
                let at = Self::ring_at(slots, lane, slot);
                for (r, gc) in self.ring[at..at + 3].iter_mut().zip(&g) {
                    *r = *gc as f32;
                }
            }
        }
        self.state[3 * lane..3 * lane + 3].copy_from_slice(&g);
    }

    /// Makes sure the wake lanes read by samples anywhere in the box `y in [y_min, y_max]`,
    /// `z in [z_min, z_max]` (TA frame, m) are generated ([`LaneStreams::PerLane`]; nothing
    /// otherwise): every lane of the cells the box touches. Call for the points to be sampled
    /// before sampling them. Cheap when the box lies in the region already generated.
    /// Allocates nothing.
    pub fn activate_box(&mut self, y_min: f64, y_max: f64, z_min: f64, z_max: f64) {
        if !self.on_demand {
            return;
        }
        let (y0, _, _) = self.lanes_y.locate(y_min);
        let (_, y1, _) = self.lanes_y.locate(y_max);
        let (z0, _, _) = self.lanes_z.locate(z_min);
        let (_, z1, _) = self.lanes_z.locate(z_max);
        let mut rect = [y0, y1, z0, z1];
        if let Some(c) = self.covered {
            if c[0] <= rect[0] && rect[1] <= c[1] && c[2] <= rect[2] && rect[3] <= c[3] {
                return;
            }
            rect = [c[0].min(y0), c[1].max(y1), c[2].min(z0), c[3].max(z1)];
        }
        let nz = self.lanes_z.count;
        for iy in rect[0]..=rect[1] {
            for iz in rect[2]..=rect[3] {
                self.activate(iy * nz + iz);
            }
        }
        self.covered = Some(rect);
    }

    /// Generates every wake lane (for owners that cannot declare their sample points).
    pub fn activate_all(&mut self) {
        if self.on_demand {
            for lane in 0..self.lanes {
                self.activate(lane);
            }
            self.covered = Some([0, self.lanes_y.count - 1, 0, self.lanes_z.count - 1]);
        }
    }

    /// Number of wake lanes generated so far.
    pub fn active_lanes(&self) -> usize {
        self.active.iter().filter(|a| **a).count()
    }

    /// Generates the next grid time.
    fn generate(&mut self) {
        let wake_channels = 3 * self.lanes;
        let (a, b) = (self.a_wake, self.b_wake);
        if self.on_demand {
            for &l in &self.active_list {
                let rng = &mut self.lane_rngs[l];
                for g in &mut self.state[3 * l..3 * l + 3] {
                    *g = a * *g + b * rng.gaussian();
                }
            }
        } else {
            for g in &mut self.state[..wake_channels] {
                *g = a * *g + b * self.wake_rng.gaussian();
            }
        }
        if self.ambient {
            let (a, b) = (self.a_ambient, self.b_ambient);
            for g in &mut self.state[wake_channels..] {
                *g = a * *g + b * self.ambient_rng.gaussian();
            }
        }
        self.newest += 1;
        self.store_newest();
    }

    /// Advances the clock by `dt` (s, finite, >= 0), generating the grid times it passes.
    /// Call once per physics step; samples are held between calls. Allocates nothing.
    pub fn advance(&mut self, dt: f64) -> Result<()> {
        if !(dt.is_finite() && dt >= 0.0) {
            return Err(SimError::invalid_config("dt", dt, "a finite step >= 0 s"));
        }
        self.time += dt;
        while (self.newest as f64) * self.dt < self.time {
            self.generate();
        }
        Ok(())
    }

    /// The dynamic state (seed, clock, history ring, processes, streams, generated lanes).
    pub fn state(&self) -> TurbulenceState {
        TurbulenceState {
            seed: self.seed,
            time: self.time,
            newest: self.newest,
            ring: self.ring_slot_major(),
            processes: self.state.clone(),
            wake_stream: self.wake_rng.state(),
            ambient_stream: self.ambient_rng.state(),
            lanes: self.on_demand.then(|| LaneState {
                streams: self.lane_rngs.iter().map(Stream::state).collect(),
                generated: self.active_list.iter().map(|&l| l as u64).collect(),
                covered: self.covered.map(|c| c.map(|v| v as u64)),
            }),
        }
    }

    /// Restores a state from [`Turbulence::state`] of turbulence with the same config. Its
    /// structure (lengths, lane indices, the clock against the grid) is checked first; on an
    /// error nothing is changed.
    pub fn set_state(&mut self, state: TurbulenceState) -> Result<(), StateError> {
        check_len("turbulence.ring", state.ring.len(), self.ring.len())?;
        check_len(
            "turbulence.processes",
            state.processes.len(),
            self.state.len(),
        )?;
        // The clock and the newest grid time as `advance` leaves them.
        let grid = |j: i64| j as f64 * self.dt;
        let consistent = state.time.is_finite()
            && state.time >= 0.0
            && (0..i64::MAX / 2).contains(&state.newest)
            && grid(state.newest) >= state.time
            && (state.newest == 0 || grid(state.newest - 1) < state.time);
        if !consistent {
            return Err(StateError::invalid(
                "turbulence.time",
                format!("{} s with newest grid index {}", state.time, state.newest),
                format!(
                    "a time in ((newest - 1) dt, newest dt] with dt = {} s",
                    self.dt
                ),
            ));
        }
        let lanes = match (self.on_demand, state.lanes) {
            (false, None) => None,
            (true, Some(lanes)) => {
                check_len("turbulence.lanes.streams", lanes.streams.len(), self.lanes)?;
                let mut active = vec![false; self.lanes];
                for &l in &lanes.generated {
                    if l >= self.lanes as u64 || active[l as usize] {
                        return Err(StateError::invalid(
                            "turbulence.lanes.generated",
                            l,
                            format!("distinct lane indices below {}", self.lanes),
                        ));
                    }
                    active[l as usize] = true;
                }
                let (ny, nz) = (self.lanes_y.count as u64, self.lanes_z.count as u64);
                if let Some(c) = lanes.covered {
                    let inside = c[0] <= c[1] && c[1] < ny && c[2] <= c[3] && c[3] < nz;
                    if !inside
                        || !(c[0]..=c[1])
                            .all(|iy| (c[2]..=c[3]).all(|iz| active[(iy * nz + iz) as usize]))
                    {
                        return Err(StateError::invalid(
                            "turbulence.lanes.covered",
                            format!("{c:?}"),
                            format!("a rectangle of generated lanes within the {ny} x {nz} grid"),
                        ));
                    }
                }
                Some((lanes, active))
            }
            (on_demand, found) => {
                return Err(StateError::invalid(
                    "turbulence.lanes",
                    if found.is_some() {
                        "per-lane streams"
                    } else {
                        "none"
                    },
                    if on_demand {
                        "per-lane streams (this config generates lanes on demand)"
                    } else {
                        "none (this config has no per-lane streams)"
                    },
                ))
            }
        };
        // Checked: apply.
        let sampler = self.config.normal_sampler;
        self.seed = state.seed;
        self.time = state.time;
        self.newest = state.newest;
        self.newest_slot = self.newest.rem_euclid(self.slots as i64) as usize;
        self.set_ring_slot_major(&state.ring);
        self.state = state.processes;
        self.wake_rng = Stream::from_state(&state.wake_stream, sampler);
        self.ambient_rng = Stream::from_state(&state.ambient_stream, sampler);
        if let Some((lanes, active)) = lanes {
            for (rng, s) in self.lane_rngs.iter_mut().zip(&lanes.streams) {
                *rng = Stream::from_state(s, sampler);
            }
            self.active = active;
            self.active_list.clear();
            self.active_list.reserve(self.lanes);
            self.active_list
                .extend(lanes.generated.iter().map(|&l| l as usize));
            self.covered = lanes.covered.map(|c| c.map(|v| v as usize));
        }
        Ok(())
    }

    /// Time since the last reset, s.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// The wake seed of the current history.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The configuration.
    pub fn config(&self) -> &TurbulenceConfig {
        &self.config
    }

    /// Size of the lane grid: (lanes along y, lanes along z). Whether they are generated at all
    /// is [`Turbulence::wake_lanes`] (0 when wake turbulence is off).
    pub fn lane_grid(&self) -> (usize, usize) {
        (self.lanes_y.count, self.lanes_z.count)
    }

    /// Number of wake lanes generated (0 when wake turbulence is off).
    pub fn wake_lanes(&self) -> usize {
        self.lanes
    }

    /// Time step of the gust grid, s.
    pub fn time_step(&self) -> f64 {
        self.dt
    }

    /// Stencil in time for a point at TA-frame x coordinate `x` (m).
    #[inline]
    fn time_stencil(&self, x: f64) -> TimeStencil {
        let delay = (-x * self.inv_airspeed).clamp(0.0, self.max_delay);
        let delay = if delay.is_nan() { 0.0 } else { delay };
        let r = (self.time - delay) * self.inv_dt;
        // floor(r) without a libm call (r is finite and small here).
        let t = r as i64;
        let mut j0 = if (t as f64) > r { t - 1 } else { t };
        let mut f = r - j0 as f64;
        if j0 >= self.newest {
            j0 = self.newest - 1;
            f = 1.0;
        }
        let oldest = self.newest - self.slots as i64 + 1;
        if j0 < oldest {
            j0 = oldest;
            f = 0.0;
        }
        // Slots from the newest one's, without an integer division: j0 in [oldest, newest - 1].
        let slot_back = |back: usize| {
            if self.newest_slot >= back {
                self.newest_slot - back
            } else {
                self.newest_slot + self.slots - back
            }
        };
        let back = (self.newest - j0) as usize;
        TimeStencil {
            slot0: slot_back(back),
            slot1: slot_back(back - 1),
            f,
        }
    }

    /// A stored channel value between two grid times, at fraction `f` from `g0`'s.
    #[inline(always)]
    fn lerp(f: f64, g0: f32, g1: f32) -> f64 {
        let (g0, g1) = (g0 as f64, g1 as f64);
        g0 + f * (g1 - g0)
    }

    /// Variance of the time interpolation of a process with lag-one correlation `a`.
    #[inline]
    fn time_variance(f: f64, a: f64) -> f64 {
        let g = 1.0 - f;
        g * g + f * f + 2.0 * f * g * a
    }

    /// The unit-variance wake gust (per component, dimensionless) at `p` (TA frame, m) now.
    /// Zero when wake turbulence is off. Allocates nothing.
    #[inline]
    pub fn wake_unit(&self, p: &Vector3<f64>) -> Vector3<f64> {
        if self.lanes == 0 {
            return Vector3::zeros();
        }
        self.wake_unit_at(&self.time_stencil(p.x), p)
    }

    /// [`Turbulence::wake_unit`] with the time stencil of `p.x` given (wake turbulence on).
    #[inline(always)]
    fn wake_unit_at(&self, ts: &TimeStencil, p: &Vector3<f64>) -> Vector3<f64> {
        let (iy0, iy1, fy) = self.lanes_y.locate(p.y);
        let (iz0, iz1, fz) = self.lanes_z.locate(p.z);
        let nz = self.lanes_z.count;
        let corners = [
            (iy0 * nz + iz0, (1.0 - fy) * (1.0 - fz)),
            (iy0 * nz + iz1, (1.0 - fy) * fz),
            (iy1 * nz + iz0, fy * (1.0 - fz)),
            (iy1 * nz + iz1, fy * fz),
        ];
        let mut sum = Vector3::zeros();
        let mut weights2 = 0.0;
        for (lane, w) in corners {
            if w == 0.0 {
                continue;
            }
            debug_assert!(
                self.active[lane],
                "wake lane {lane} sampled before it was generated"
            );
            weights2 += w * w;
            // The lane's values at the stencil's two grid times.
            let (g0, g1) = (
                &self.ring[self.at(lane, ts.slot0)..][..3],
                &self.ring[self.at(lane, ts.slot1)..][..3],
            );
            for c in 0..3 {
                sum[c] += w * Self::lerp(ts.f, g0[c], g1[c]);
            }
        }
        sum / (weights2 * Self::time_variance(ts.f, self.a_wake)).sqrt()
    }

    /// The unit-variance ambient gust (per component, dimensionless) at `p` (TA frame, m) now.
    /// Zero when ambient turbulence is off. Allocates nothing.
    #[inline]
    pub fn ambient_unit(&self, p: &Vector3<f64>) -> Vector3<f64> {
        if !self.ambient {
            return Vector3::zeros();
        }
        self.ambient_unit_at(&self.time_stencil(p.x))
    }

    /// [`Turbulence::ambient_unit`] with the time stencil given (ambient turbulence on).
    #[inline(always)]
    fn ambient_unit_at(&self, ts: &TimeStencil) -> Vector3<f64> {
        let g0 = &self.ring[self.at(self.lanes, ts.slot0)..][..3];
        let g1 = &self.ring[self.at(self.lanes, ts.slot1)..][..3];
        let scale = 1.0 / Self::time_variance(ts.f, self.a_ambient).sqrt();
        Vector3::new(
            Self::lerp(ts.f, g0[0], g1[0]),
            Self::lerp(ts.f, g0[1], g1[1]),
            Self::lerp(ts.f, g0[2], g1[2]),
        ) * scale
    }

    /// RMS wake fluctuation per component for turbulent kinetic energy `tke` (m^2/s^2):
    /// `u' = sqrt(2 k / 3)`, m/s (paper Eq. 1).
    #[inline]
    pub fn wake_rms(tke: f64) -> f64 {
        (2.0 * tke.max(0.0) / 3.0).sqrt()
    }

    /// RMS ambient fluctuation per component, m/s.
    pub fn ambient_sigma(&self) -> f64 {
        if self.ambient {
            self.sigma_ambient
        } else {
            0.0
        }
    }

    /// The turbulent velocity fluctuation at `p` (TA frame, m) now, m/s:
    /// `sqrt(2 tke / 3) * wake_unit(p) + sigma_ambient * ambient_unit(p)`, with `tke` (m^2/s^2)
    /// the wake's turbulent kinetic energy at `p`. Allocates nothing.
    #[inline(always)]
    pub fn sample(&self, p: &Vector3<f64>, tke: f64) -> Vector3<f64> {
        let mut v = Vector3::zeros();
        let wake = tke > 0.0 && self.lanes > 0;
        if !(wake || self.ambient) {
            return v;
        }
        // One time stencil for both parts: they are read at the same grid times.
        let ts = self.time_stencil(p.x);
        if wake {
            v += self.wake_unit_at(&ts, p) * Self::wake_rms(tke);
        }
        if self.ambient {
            v += self.ambient_unit_at(&ts) * self.sigma_ambient;
        }
        v
    }
}

/// Which wake lanes are generated, with [`crate::LaneStreams::PerLane`].
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LaneState {
    /// One stream per lane.
    pub streams: Vec<StreamState>,
    /// The generated lanes, in the order they were generated.
    pub generated: Vec<u64>,
    /// Lane rectangle `[iy0, iy1, iz0, iz1]` whose lanes are all generated.
    pub covered: Option<[u64; 4]>,
}

/// The turbulence ([`crate::Turbulence`]).
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TurbulenceState {
    /// The wake seed of the current history.
    pub seed: u64,
    /// Time since the last reset, s.
    pub time: f64,
    /// Grid index of the newest generated time.
    pub newest: i64,
    /// The frozen history (slot-major ring of every channel).
    pub ring: Vec<f32>,
    /// The current value of every channel.
    pub processes: Vec<f64>,
    /// The shared stream of the wake lanes.
    pub wake_stream: StreamState,
    /// The ambient turbulence's stream.
    pub ambient_stream: StreamState,
    /// Per-lane streams (`None` unless [`crate::LaneStreams::PerLane`] with wake turbulence).
    pub lanes: Option<LaneState>,
}
