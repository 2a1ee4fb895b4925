//! The RLV's capture boom: where its tip is relative to the towing aircraft, how it moves, and
//! when the ACCD has captured it.
//!
//! The RLV flies in formation behind and below the TA. Laterally and vertically its boom tip sits
//! at a formation offset (randomised at the start of an episode), drifts slowly (a sinusoid per
//! axis of period about a minute, random phases: formation-keeping wander) and is perturbed by
//! gusts on the RLV (a first-order Gauss-Markov process per axis).
//!
//! **Along track** the RLV approaches: its boom tip starts `approach_distance` behind the ACCD's
//! capture point and closes on it at no more than `approach_speed`, then keeps station with it
//! (the RLV's autopilot flies the along-track channel; the ACCD has almost no authority over its
//! own along-track position, which the tether's length fixes once its depth and lateral offset are
//! chosen). Each step the tip's along-track position moves towards the capture point's by at most
//! `approach_speed * dt`. With `approach_speed = 0` the tip holds `offset[0]` instead (a fixed
//! formation, which the tether can reach only for some offsets).
//!
//! **Placement.** The formation is set relative to the capture point's open-loop equilibrium of the
//! episode's own configuration ([`BoomPlacement::Equilibrium`], the default), so that every tether,
//! material, wake and aircraft setting gives the same, well-posed task: the boom tip's nominal
//! position is `equilibrium + boom.offset_from_equilibrium`. Left unset, that offset is the one the
//! default configuration's boom has from its own equilibrium, `boom.offset - equilibrium_default`
//! (about 3 m to starboard and 3.8 m above; [`BoomConfig::nominal`]), so the default task is the
//! one it always was, to the bit. [`BoomPlacement::Absolute`] puts it at `boom.offset` in the TA
//! frame whatever the configuration (the first versions' fixed formation).
//!
//! Defaults, all assumptions: offset (-, 3, 62) m laterally and vertically, i.e. 3 m to starboard of
//! and about 4 m above the ACCD's open-loop equilibrium in the 8 deg wake (65.8 m); initial spread
//! +-(2, 3, 3) m; drift amplitude (1, 2, 2) m over 50 s; perturbations 0.2 m RMS with a 1.5 s time
//! constant; approach from 10 m behind at 0.5 m/s (20 s to close). Capture: the ACCD's capture
//! point within 0.5 m of the boom tip at a relative speed under 2 m/s (a lock-in mechanism
//! tolerates a decimetre-scale miss; more closing speed would load the lock and the tether
//! abruptly).

use accd_spec::Fields;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::rng::{NormalSampler, Stream, StreamState, RLV_STREAM};

type V3 = Vector3<f64>;

accd_spec::config_struct! {
    /// Formation, motion and capture criteria of the boom. SI units.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct BoomConfig {
        pub offset: [f64; 3] = [-241.0, 3.0, 62.0], "m", "[-5000, 5000]",
            "nominal boom-tip position in the TA frame with placement \"absolute\"; with \"equilibrium\", its position in the default configuration (x only used with approach_speed = 0)";
        pub placement: BoomPlacement = BoomPlacement::Equilibrium, "", "",
            "where the formation is set: \"equilibrium\" (relative to the capture point's open-loop equilibrium of the episode's configuration) or \"absolute\" (at offset)";
        pub offset_from_equilibrium: Option<[f64; 3]> = None, "m", "[-5000, 5000]",
            "boom-tip position relative to the capture point's open-loop equilibrium, placement \"equilibrium\" (None: offset minus the default configuration's equilibrium)";
        pub initial_spread: [f64; 3] = [2.0, 3.0, 3.0], "m", "[0, 100]",
            "half-width of the uniform random initial offset per axis";
        pub drift_amplitude: [f64; 3] = [1.0, 2.0, 2.0], "m", "[0, 100]",
            "amplitude of the slow drift per axis";
        pub drift_period: f64 = 50.0, "s", "(0, 100000]", "period of the slow drift";
        pub perturbation_sigma: f64 = 0.2, "m", "[0, 100]", "RMS of the perturbation per axis";
        pub perturbation_time_constant: f64 = 1.5, "s", "(0, 10000]",
            "time constant of the perturbation";
        pub capture_radius: f64 = 0.5, "m", "(0, 100]", "capture radius around the boom tip";
        pub max_closing_speed: f64 = 2.0, "m/s", "(0, 1000]",
            "largest relative speed at which a capture holds";
        pub approach_distance: f64 = 10.0, "m", "[0, 1000]",
            "along-track distance of the boom tip behind the capture point at the start";
        pub approach_speed: f64 = 0.5, "m/s", "[0, 50]",
            "largest along-track closing speed of the boom tip on the capture point (0: a fixed formation at offset[0])";
    }
}

/// Where the RLV's formation is set (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BoomPlacement {
    /// Relative to the capture point's open-loop equilibrium of the episode's configuration.
    #[default]
    Equilibrium,
    /// At `boom.offset` in the TA frame.
    Absolute,
}

accd_spec::no_range!(BoomPlacement);

/// Each field's range is all there is to check.
impl accd_spec::Rules for BoomConfig {}

impl BoomConfig {
    /// Checks every field against its declared range.
    pub fn validate(&self) -> Result<()> {
        Ok(self.check_fields("boom")?)
    }

    /// The boom tip's nominal position (TA frame, m) for a configuration whose capture point
    /// settles at `equilibrium`: `offset` with [`BoomPlacement::Absolute`]; otherwise
    /// `equilibrium + offset_from_equilibrium`, the latter, when unset, `offset - reference()`
    /// with `reference()` the default configuration's equilibrium (asked only then). For the
    /// default configuration `equilibrium == reference()`, and `e + (offset - e)` is `offset`
    /// exactly: the difference of two doubles within a factor of two of each other is exact
    /// (Sterbenz), and so is then the sum, whose true value is the double `offset`.
    pub fn nominal(&self, equilibrium: &V3, reference: impl FnOnce() -> Result<V3>) -> Result<V3> {
        let offset = V3::from(self.offset);
        Ok(match (self.placement, self.offset_from_equilibrium) {
            (BoomPlacement::Absolute, _) => offset,
            (BoomPlacement::Equilibrium, Some(relative)) => equilibrium + V3::from(relative),
            (BoomPlacement::Equilibrium, None) => equilibrium + (offset - reference()?),
        })
    }
}

/// The boom tip's motion over one episode.
#[derive(Debug, Clone)]
pub struct Boom {
    config: BoomConfig,
    base: V3,
    phase: V3,
    perturbation: V3,
    /// Along-track position of the tip before the perturbation (approach mode), m.
    along: f64,
    previous_tip: V3,
    velocity: V3,
    stream: Stream,
}

impl Boom {
    /// The boom of an episode whose RLV stream is drawn from `seed`, at t = 0, with the capture
    /// point at along-track position `capture_x` (m) and the formation's nominal tip position
    /// `nominal` (TA frame, m; [`BoomConfig::nominal`]).
    pub fn new(config: &BoomConfig, seed: u64, capture_x: f64, nominal: &V3) -> Self {
        let mut stream = Stream::new(seed, RLV_STREAM);
        let base =
            V3::from_fn(|i, _| nominal[i] + stream.range(-1.0, 1.0) * config.initial_spread[i]);
        let phase = V3::from_fn(|_, _| stream.range(0.0, 2.0 * std::f64::consts::PI));
        let perturbation = V3::from_fn(|_, _| config.perturbation_sigma * stream.gaussian());
        let mut boom = Boom {
            config: config.clone(),
            base,
            phase,
            perturbation,
            along: capture_x - config.approach_distance,
            previous_tip: V3::zeros(),
            velocity: V3::zeros(),
            stream,
        };
        boom.previous_tip = boom.tip(0.0);
        boom.velocity = boom.drift_rate(0.0);
        if boom.approaching() && config.approach_distance > 0.0 {
            boom.velocity.x = config.approach_speed;
        }
        boom
    }

    fn drift(&self, t: f64) -> V3 {
        let w = 2.0 * std::f64::consts::PI / self.config.drift_period;
        V3::from_fn(|i, _| self.config.drift_amplitude[i] * libm::sin(w * t + self.phase[i]))
    }

    fn drift_rate(&self, t: f64) -> V3 {
        let w = 2.0 * std::f64::consts::PI / self.config.drift_period;
        V3::from_fn(|i, _| self.config.drift_amplitude[i] * w * libm::cos(w * t + self.phase[i]))
    }

    /// True when the RLV approaches along track (`approach_speed > 0`), false for a fixed
    /// formation.
    pub fn approaching(&self) -> bool {
        self.config.approach_speed > 0.0
    }

    /// Boom-tip position in the TA frame at time `t` (with the perturbation and the along-track
    /// position of the last step), m.
    pub fn tip(&self, t: f64) -> V3 {
        let mut tip = self.base + self.drift(t) + self.perturbation;
        if self.approaching() {
            tip.x = self.along + self.perturbation.x;
        }
        tip
    }

    /// Boom-tip velocity over the last step, m/s.
    pub fn velocity(&self) -> V3 {
        self.velocity
    }

    /// Advances the perturbation from `t` to `t + dt` (exact Gauss-Markov update), moves an
    /// approaching tip along track towards the capture point at `capture_x` (m; `None` for a fixed
    /// formation) by at most `approach_speed * dt`, and updates the velocity estimate.
    pub fn advance(&mut self, t: f64, dt: f64, capture_x: Option<f64>) {
        if let Some(x) = capture_x {
            let step = self.config.approach_speed * dt;
            self.along += (x - self.along).clamp(-step, step);
        }
        let a = libm::exp(-dt / self.config.perturbation_time_constant);
        let kick = self.config.perturbation_sigma * (1.0 - a * a).sqrt();
        for i in 0..3 {
            self.perturbation[i] = a * self.perturbation[i] + kick * self.stream.gaussian();
        }
        let tip = self.tip(t + dt);
        self.velocity = (tip - self.previous_tip) / dt;
        self.previous_tip = tip;
    }

    /// The dynamic state (formation offset, drift phases, perturbation, stream).
    pub fn state(&self) -> BoomState {
        BoomState {
            base: self.base.into(),
            phase: self.phase.into(),
            perturbation: self.perturbation.into(),
            previous_tip: self.previous_tip.into(),
            velocity: self.velocity.into(),
            along: self.along,
            stream: self.stream.state(),
        }
    }

    /// Restores a state from [`Boom::state`] (of a boom with any config: the state has no
    /// lengths to check).
    pub fn set_state(&mut self, state: &BoomState) {
        self.base = state.base.into();
        self.phase = state.phase.into();
        self.perturbation = state.perturbation.into();
        self.previous_tip = state.previous_tip.into();
        self.velocity = state.velocity.into();
        self.along = state.along;
        self.stream = Stream::from_state(&state.stream, NormalSampler::BoxMuller);
    }

    /// The configuration.
    pub fn config(&self) -> &BoomConfig {
        &self.config
    }
}

/// How close the capture point is to the boom tip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureStatus {
    /// Distance between the capture point and the boom tip, m.
    pub distance: f64,
    /// Relative speed of the capture point with respect to the boom tip, m/s.
    pub relative_speed: f64,
    /// Within the capture radius at an acceptable relative speed.
    pub captured: bool,
}

impl CaptureStatus {
    /// Evaluates the capture criteria of `config` for the given positions and velocities.
    pub fn evaluate(
        config: &BoomConfig,
        point: &V3,
        point_velocity: &V3,
        tip: &V3,
        tip_velocity: &V3,
    ) -> Self {
        let distance = (point - tip).norm();
        let relative_speed = (point_velocity - tip_velocity).norm();
        CaptureStatus {
            distance,
            relative_speed,
            captured: distance <= config.capture_radius
                && relative_speed <= config.max_closing_speed,
        }
    }
}

/// The RLV's boom ([`crate::physics::boom::Boom`]), TA frame, SI.
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BoomState {
    /// Formation offset of the tip, m.
    pub base: [f64; 3],
    /// Drift phases, rad.
    pub phase: [f64; 3],
    /// Gauss-Markov perturbation, m.
    pub perturbation: [f64; 3],
    /// Tip at the last step, m.
    pub previous_tip: [f64; 3],
    /// Tip velocity estimate, m/s.
    pub velocity: [f64; 3],
    /// Along-track position of the approaching tip, m.
    pub along: f64,
    /// The RLV stream.
    pub stream: StreamState,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeded_boom_is_reproducible_and_stays_near_its_offset() {
        let cfg = BoomConfig {
            approach_speed: 0.0,
            ..BoomConfig::default()
        };
        let run = |seed| {
            let mut b = Boom::new(&cfg, seed, -240.0, &cfg.offset.into());
            let mut out = vec![];
            for k in 0..7000 {
                b.advance(k as f64 * 0.01, 0.01, None);
                out.push(b.tip((k + 1) as f64 * 0.01));
            }
            out
        };
        let a = run(5);
        assert_eq!(a, run(5));
        assert_ne!(a, run(6));
        for p in &a {
            for i in 0..3 {
                let bound =
                    cfg.initial_spread[i] + cfg.drift_amplitude[i] + 6.0 * cfg.perturbation_sigma;
                assert!((p[i] - cfg.offset[i]).abs() < bound);
            }
        }
    }

    #[test]
    fn the_boom_approaches_at_its_speed_then_keeps_station() {
        let cfg = BoomConfig {
            perturbation_sigma: 0.0,
            ..BoomConfig::default()
        };
        let mut b = Boom::new(&cfg, 1, -242.0, &cfg.offset.into());
        assert!((b.tip(0.0).x - (-252.0)).abs() < 1e-12);
        let dt = 0.01;
        for k in 0..2100 {
            b.advance(k as f64 * dt, dt, Some(-242.0));
            let x = b.tip((k + 1) as f64 * dt).x;
            let expected = (-252.0 + 0.5 * (k + 1) as f64 * dt).min(-242.0);
            assert!((x - expected).abs() < 1e-9, "step {k}: {x} vs {expected}");
            if k < 1990 && x < -242.0 {
                assert!((b.velocity().x - 0.5).abs() < 1e-6);
            }
        }
        // Station-keeping: it follows the capture point back and forth at up to 0.5 m/s.
        for k in 2100..2200 {
            b.advance(k as f64 * dt, dt, Some(-241.8));
        }
        assert!((b.tip(22.0).x - (-241.8)).abs() < 1e-9);
    }

    #[test]
    fn capture_needs_both_proximity_and_low_speed() {
        let cfg = BoomConfig::default();
        let tip = V3::new(1.0, 2.0, 3.0);
        let z = V3::zeros();
        assert!(
            CaptureStatus::evaluate(&cfg, &(tip + V3::new(0.3, 0.0, 0.0)), &z, &tip, &z).captured
        );
        assert!(
            !CaptureStatus::evaluate(&cfg, &(tip + V3::new(0.6, 0.0, 0.0)), &z, &tip, &z).captured
        );
        assert!(!CaptureStatus::evaluate(&cfg, &tip, &V3::new(2.5, 0.0, 0.0), &tip, &z).captured);
    }
}
