//! The task's configuration ([`EnvConfig`]): the physics, the initial conditions, the reward
//! weights, the limits of the episode end, randomization and sensors (see [`crate::task`]).

use serde::{Deserialize, Serialize};

use crate::config::{parse_named, CaptureConfig};
use crate::error::Result;
use crate::task::observation::OBS_DIM;
use crate::task::randomization::RandomizationConfig;
use crate::task::sensors::SensorsConfig;
use crate::valid::Valid;
use accd_spec::{join, out_of_range, Fields, OutOfRange, Rules};

accd_spec::config_struct! {
    /// Random initial conditions of an episode, around the open-loop equilibrium.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct InitialConfig {
        pub settle_time: f64 = 40.0, "s", "[0, 600]",
            "time the open-loop equilibrium is settled for (neutral flaps, mean wake, no turbulence)";
        /// The whole tether is rotated about the attachment to put the ACCD there.
        pub offset: [f64; 2] = [5.0, 5.0], "m", "[0, 50]",
            "half-width of the uniform random displacement of the ACCD from the equilibrium, [lateral y, vertical z]";
        pub attitude_deg: f64 = 3.0, "deg", "[0, 30]",
            "half-width of the uniform random roll, pitch and yaw of the ACCD";
    }
}

/// Each field's range is all there is to check.
impl Rules for InitialConfig {}

accd_spec::config_struct! {
    /// Reward weights (see the module docs for the formula).
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct RewardConfig {
        pub proximity: f64 = 1.0, "-", "[0, 1e6]", "w_p: weight of the proximity term";
        pub proximity_scale: f64 = 10.0, "m", "(0, 1e4]",
            "lambda: distance scale of the proximity term";
        pub effort: f64 = 0.05, "-", "[0, 1e6]", "w_e: weight of the control-effort cost";
        pub smoothness: f64 = 0.05, "-", "[0, 1e6]", "w_s: weight of the control-rate cost";
        pub capture: f64 = 100.0, "-", "[0, 1e6]", "w_c: bonus on capture (plus w_p per agent step left)";
        pub failure: f64 = 50.0, "-", "[0, 1e6]", "w_f: penalty on overload, envelope exit or divergence";
    }
}

/// Each field's range is all there is to check.
impl Rules for RewardConfig {}

impl RewardConfig {
    /// The lowest and highest reward of one agent step in an episode of `steps` agent steps.
    pub fn bounds(&self, steps: u64) -> (f64, f64) {
        (
            -self.effort - self.smoothness - self.failure,
            self.proximity * steps as f64 + self.capture,
        )
    }
}

accd_spec::config_struct! {
    /// Limits whose violation ends an episode (terminated).
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct LimitsConfig {
        pub overload_fraction: f64 = 0.5, "-", "(0, 1]",
            "largest attachment tension as a fraction of the tether's breaking tension (0.5: a safety factor of 2)";
        pub max_distance: f64 = 60.0, "m", "(0, 1e4]",
            "largest distance from the capture point to the boom tip";
        pub max_tilt_deg: f64 = 60.0, "deg", "(0, 180]",
            "largest angle between the ACCD's nose and the flight direction";
        pub max_body_rate: f64 = 10.0, "rad/s", "(0, 1000]",
            "largest pitch/yaw rate sqrt(q^2 + r^2) (tumbling)";
        /// The tether attaches through a swivel, so roll is free; a faster spin counts as loss
        /// of control.
        pub max_roll_rate: f64 = 50.0, "rad/s", "(0, 1000]", "largest roll rate |p|";
    }
}

/// Each field's range is all there is to check.
impl Rules for LimitsConfig {}

accd_spec::config_struct! {
    /// Everything that defines the RL environment: the physics ([`CaptureConfig`], composed flat:
    /// its sections' keys stand beside the task's in one document), the task, and the wake seeds.
    /// Missing keys take their defaults; unknown keys are errors.
    #[derive(Debug, Clone, PartialEq)]
    pub struct EnvConfig {
        ..physics: CaptureConfig;
        pub agent_step: f64 = 0.1, "s", "(0, 10]",
            "how long one action is held; a whole multiple of tether.time_step, at least one";
        pub capture_window: f64 = 70.0, "s", "(0, 3600]",
            "the episode is truncated after this time; a whole multiple of agent_step, at least one";
        pub initial: InitialConfig = InitialConfig::default(), "", "", "random initial conditions";
        pub reward: RewardConfig = RewardConfig::default(), "", "", "reward weights";
        pub limits: LimitsConfig = LimitsConfig::default(), "", "", "episode-ending limits";
        pub wake_seed: Option<u64> = None, "", "",
            "fixes the wake seed of every episode (None: drawn from the training range)";
        /// Env `i`'s episode `e` uses entry `(i + e * num_envs) mod len`.
        pub wake_seeds: Option<Vec<u64>> = None, "", "",
            "wake seeds to cycle through (evaluation); overrides wake_seed";
        pub randomization: RandomizationConfig = RandomizationConfig::default(), "", "",
            "physical parameters drawn per episode from its wake seed (off by default)";
        /// Last, and left out of written documents while off, so that documents and config
        /// hashes of configurations without sensors are as they were.
        pub sensors: SensorsConfig = SensorsConfig::default(), "", "",
            "sensor model of the observation (noise, rates, latency, dropouts, delay); off by default";
    }
}

/// The most physics steps the set-up of an env may take: settling the open-loop equilibrium
/// ([`crate::Equilibrium::settle`]) runs `initial.settle_time / tether.time_step` of them before
/// the first episode. A physics step of the default tether takes 10 to 40 us (an idle or a busy
/// processor), so the bound keeps the set-up within seconds (the default settles in 4,000 steps,
/// the longest `initial.settle_time` at the default step in 60,000); a configuration above it is
/// refused rather than left to run for minutes or hours.
pub const MAX_SETTLE_STEPS: f64 = 2e5;

/// The agent step a whole multiple of the physics step, the capture window a whole multiple of
/// the agent step, the set-up within [`MAX_SETTLE_STEPS`], a wake-seed list not empty and every
/// wake seed in the seed range.
impl Rules for EnvConfig {
    fn check_rules(&self, prefix: &str) -> std::result::Result<(), OutOfRange> {
        let dt = self.physics.tether.time_step;
        let settle_steps = self.initial.settle_time / dt;
        if settle_steps > MAX_SETTLE_STEPS {
            return Err(out_of_range(
                &join(prefix, "tether.time_step"),
                dt,
                format!(
                    "[initial.settle_time / {MAX_SETTLE_STEPS:e}, 1] s = [{:e}, 1] s: settling the \
                     open-loop equilibrium takes initial.settle_time / tether.time_step = {:.3e} \
                     physics steps before the first episode, at most {MAX_SETTLE_STEPS:e} (seconds \
                     of set-up); use a longer tether.time_step or a shorter initial.settle_time = {} s",
                    self.initial.settle_time / MAX_SETTLE_STEPS,
                    settle_steps,
                    self.initial.settle_time
                ),
            ));
        }
        if self.agent_step < dt {
            return Err(out_of_range(
                &join(prefix, "agent_step"),
                self.agent_step,
                format!("[tether.time_step = {dt}, 10] s"),
            ));
        }
        let k = self.substeps() as f64;
        if (k * dt - self.agent_step).abs() > 1e-9 * self.agent_step {
            return Err(out_of_range(
                &join(prefix, "agent_step"),
                self.agent_step,
                format!("a whole multiple of tether.time_step = {dt} s"),
            ));
        }
        if self.capture_window < self.agent_step {
            return Err(out_of_range(
                &join(prefix, "capture_window"),
                self.capture_window,
                "[agent_step, 3600] s",
            ));
        }
        let steps = self.capture_window / self.agent_step;
        if (steps - steps.round()).abs() > 1e-9 * steps {
            return Err(out_of_range(
                &join(prefix, "capture_window"),
                self.capture_window,
                "a whole multiple of agent_step",
            ));
        }
        let rate = self.sensors.vision.update_rate;
        if self.sensors.enabled && rate * dt > 1.0 + 1e-9 {
            return Err(out_of_range(
                &join(prefix, "sensors.vision.update_rate"),
                rate,
                format!("(0, 1 / tether.time_step = {}] Hz", 1.0 / dt),
            ));
        }
        if let Some(list) = &self.wake_seeds {
            if list.is_empty() {
                return Err(out_of_range(
                    &join(prefix, "wake_seeds"),
                    "[]",
                    "a non-empty list of wake seeds",
                ));
            }
            if let Some(seed) = list.iter().find(|s| **s >= crate::rng::SEED_END) {
                return Err(out_of_range(
                    &join(prefix, "wake_seeds"),
                    seed,
                    format!("{} for every entry", crate::rng::SEED_RANGE),
                ));
            }
        }
        if let Some(seed) = self.wake_seed.filter(|s| *s >= crate::rng::SEED_END) {
            return Err(out_of_range(
                &join(prefix, "wake_seed"),
                seed,
                crate::rng::SEED_RANGE,
            ));
        }
        Ok(())
    }
}

impl EnvConfig {
    /// The fields set away from their defaults, as `dotted.name = value` (values cut to 40
    /// characters), in document order: what an error names when a combination of values fails
    /// and no single range says which ([`crate::SimError::Unsettled`]).
    pub fn changed_fields(&self) -> Vec<String> {
        fn diff(
            path: &str,
            now: &serde_json::Value,
            default: &serde_json::Value,
            out: &mut Vec<String>,
        ) {
            match (now, default) {
                (serde_json::Value::Object(a), serde_json::Value::Object(b)) => {
                    for (key, value) in a {
                        let name = join(path, key);
                        match b.get(key) {
                            Some(d) => diff(&name, value, d, out),
                            None => diff(&name, value, &serde_json::Value::Null, out),
                        }
                    }
                }
                _ if now != default => {
                    let text = now.to_string();
                    let shown = if text.chars().count() > 40 {
                        format!("{}...", text.chars().take(37).collect::<String>())
                    } else {
                        text
                    };
                    out.push(format!("{path} = {shown}"));
                }
                _ => {}
            }
        }
        let mut out = Vec::new();
        if let (Ok(now), Ok(default)) = (
            serde_json::to_value(self),
            serde_json::to_value(EnvConfig::default()),
        ) {
            diff("", &now, &default, &mut out);
        }
        out
    }

    /// Parses JSON (unknown keys are errors) and validates. A value of the wrong type is named
    /// by its dotted field (see [`crate::config::locate_parse_error`]).
    pub fn from_json(text: &str) -> Result<Valid<Self>> {
        let config: EnvConfig = parse_named(text)?;
        config.validated()
    }

    /// The configuration, validated ([`EnvConfig::validate`]): what the episode and the batch
    /// env take.
    pub fn validated(self) -> Result<Valid<Self>> {
        self.validate()?;
        Ok(Valid::trusted(self))
    }

    /// Estimated heap bytes of one env (episode) of this configuration: the turbulence's gust
    /// history (the dominant part at low airspeed or a long history), the tether's state, model
    /// and integrator buffers, the sensors' history and delay line, and a fixed allowance for
    /// the rest. Shared parts (the wake and
    /// aerodynamic tables) are not counted.
    pub fn bytes_per_env(&self) -> usize {
        let dofs = self.physics.tether.dofs();
        // State, start state, RK4 stages and spares (about 20 vectors), and the model's
        // per-segment workspace (about 60 values a segment).
        let tether = (20 * dofs + 60 * self.physics.tether.segments) * std::mem::size_of::<f64>();
        let turbulence = self
            .physics
            .turbulence
            .history_bytes(self.physics.aircraft.airspeed);
        let sensors = self.sensors.bytes(self.physics.tether.time_step, OBS_DIM);
        const FIXED: usize = 16 << 10;
        turbulence
            .saturating_add(tether)
            .saturating_add(sensors)
            .saturating_add(FIXED)
    }

    /// Physics steps per agent step.
    pub fn substeps(&self) -> usize {
        (self.agent_step / self.physics.tether.time_step).round() as usize
    }

    /// Agent steps in the capture window.
    pub fn episode_steps(&self) -> u64 {
        (self.capture_window / self.agent_step).round() as u64
    }

    /// Checks every field against its declared range and every rule ([`Rules`]), the physics
    /// part's included; counted by [`crate::valid::validation_passes`] as one pass.
    pub fn validate(&self) -> Result<()> {
        crate::valid::count_validation_pass();
        Ok(self.check_fields("")?)
    }
}

impl Valid<EnvConfig> {
    /// The physics part, valid with it ([`EnvConfig::validate`] checks it whole).
    pub fn capture(&self) -> Valid<CaptureConfig> {
        Valid::trusted(self.physics.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::accd::AccdConfig;

    #[test]
    fn wake_seeds_beyond_the_seed_range_are_refused_quoting_the_value() {
        for seed in [crate::rng::SEED_END, u64::MAX] {
            for doc in [
                format!(r#"{{"wake_seed": {seed}}}"#),
                format!(r#"{{"wake_seeds": [1, {seed}]}}"#),
            ] {
                let e = EnvConfig::from_json(&doc).unwrap_err().to_string();
                assert!(
                    e.contains(&format!("= {seed} ")) && e.contains("[0, 2^63)"),
                    "{e}"
                );
            }
        }
        let top = crate::rng::SEED_END - 1;
        EnvConfig::from_json(&format!(r#"{{"wake_seed": {top}, "wake_seeds": [{top}]}}"#)).unwrap();
    }

    #[test]
    fn a_set_up_beyond_the_settle_step_bound_is_refused_naming_both_fields() {
        let e = EnvConfig::from_json(r#"{"tether": {"time_step": 1e-7}}"#)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`tether.time_step`")
                && e.contains("initial.settle_time")
                && e.contains("at most 2e5"),
            "{e}"
        );
        // A step of 1e-4 s is within the bound with a settle short enough.
        let e = EnvConfig::from_json(r#"{"tether": {"time_step": 1e-4}}"#).unwrap_err();
        assert!(e.to_string().contains("[2e-4, 1] s"), "{e}");
        EnvConfig::from_json(r#"{"tether": {"time_step": 1e-4}, "initial": {"settle_time": 20}}"#)
            .unwrap();
    }

    #[test]
    fn a_gust_history_too_long_for_the_airspeed_names_the_airspeed() {
        let e = EnvConfig::from_json(r#"{"aircraft": {"airspeed": 0.3}}"#)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("turbulence.history_distance_m")
                && e.contains("aircraft.airspeed = 0.3 m/s"),
            "{e}"
        );
    }

    #[test]
    fn changed_fields_name_every_value_set_away_from_its_default() {
        assert!(EnvConfig::default().changed_fields().is_empty());
        let c = EnvConfig::from_json(r#"{"accd": {"mass": 0.01}, "wake_seed": 7}"#).unwrap();
        assert_eq!(
            c.changed_fields(),
            vec!["accd.mass = 0.01".to_string(), "wake_seed = 7".to_string()]
        );
    }

    #[test]
    fn defaults_validate_and_derive_the_step_counts() {
        let c = EnvConfig::default();
        c.validate().unwrap();
        assert_eq!(c.substeps(), 10);
        assert_eq!(c.episode_steps(), 700);
    }

    #[test]
    fn bad_values_name_the_field() {
        let mut c = EnvConfig {
            agent_step: 0.105,
            ..EnvConfig::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("agent_step") && e.contains("0.105"), "{e}");
        c.agent_step = 0.1;
        c.limits.max_tilt_deg = 0.0;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("limits.max_tilt_deg"), "{e}");
        let e = EnvConfig::from_json(r#"{"capture_windw": 3}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("capture_windw"), "{e}");
    }

    /// The keys of today's documents, in the order they are written (the state header hashes
    /// this JSON: the order must not change). `sensors` follows them, written only when it is
    /// not at its default (`the_sensors_section_is_written_last_and_only_when_set`).
    const KEYS: [&str; 14] = [
        "tether",
        "accd",
        "aircraft",
        "boom",
        "wake",
        "turbulence",
        "agent_step",
        "capture_window",
        "initial",
        "reward",
        "limits",
        "wake_seed",
        "wake_seeds",
        "randomization",
    ];

    #[test]
    fn env_config_reads_and_writes_flat_keys() {
        let text = serde_json::to_string(&EnvConfig::default()).unwrap();
        let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
        let keys: Vec<&str> = doc
            .as_object()
            .unwrap()
            .keys()
            .map(|k| k.as_str())
            .collect();
        let mut sorted = KEYS.to_vec();
        sorted.sort();
        assert_eq!(keys, sorted, "serde_json's map is sorted");
        assert!(text.starts_with(r#"{"tether":{"segments":30,"#), "{text}");
        let order: Vec<usize> = KEYS
            .iter()
            .map(|k| text.find(&format!("\"{k}\":")).unwrap())
            .collect();
        assert!(order.windows(2).all(|w| w[0] < w[1]), "{text}");
        let back: EnvConfig = serde_json::from_str(&text).unwrap();
        assert_eq!(back, EnvConfig::default());
        let c = EnvConfig::from_json(
            r#"{"tether": {"segments": 20}, "reward": {"effort": 0.1}, "capture_window": 30}"#,
        )
        .unwrap();
        assert_eq!(c.physics.tether.segments, 20);
        assert_eq!(c.reward.effort, 0.1);
        assert_eq!(c.capture_window, 30.0);
        assert_eq!(c.physics.accd, AccdConfig::default());
    }

    #[test]
    fn env_config_refuses_unknown_and_repeated_keys_by_dotted_path() {
        for (doc, path) in [
            (r#"{"capture_windw": 3}"#, "capture_windw"),
            (r#"{"tether": {"lenght": 3}}"#, "tether.lenght"),
            (r#"{"reward": {"effort": 0.1, "efort": 1}}"#, "reward.efort"),
            (r#"{"wake": {"enabled": 3}}"#, "wake.enabled"),
            (r#"{"boom": {"offset": [0, 1]}}"#, "boom.offset"),
        ] {
            let e = EnvConfig::from_json(doc).unwrap_err().to_string();
            assert!(e.contains(&format!("`{path}`")), "{doc}: {e}");
        }
        let e = EnvConfig::from_json(r#"{"capture_window": 30, "capture_window": 40}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("duplicate field `capture_window`"), "{e}");
        let e = EnvConfig::from_json(r#"{"nope": 1}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("`tether`") && e.contains("`wake_seeds`"), "{e}");
    }

    /// Every declared range reads, only numbers have one, sections have neither unit nor range.
    #[test]
    fn declarations_are_well_formed() {
        let rows = accd_spec::walk(EnvConfig::FIELDS);
        assert!(rows.len() > 70, "{}", rows.len());
        let mut keys: Vec<&str> = rows.iter().map(|(k, _)| k.as_str()).collect();
        keys.sort();
        keys.dedup();
        assert_eq!(keys.len(), rows.len());
        for (key, f) in &rows {
            assert!(
                !f.description.is_empty() && !f.description.ends_with('.'),
                "{key}"
            );
            if !f.range.is_empty() {
                accd_spec::Range::parse(f.range).unwrap_or_else(|e| panic!("{key}: {e}"));
                assert!(
                    !f.unit.is_empty(),
                    "{key}: a number has a unit (\"-\" for none)"
                );
            }
            if !f.nested.is_empty() {
                assert!(f.unit.is_empty() && f.range.is_empty(), "{key}");
            }
        }
    }

    /// Each declared range is what validation enforces: a value just outside it (each number of
    /// the configuration in turn) is refused, naming the dotted field.
    #[test]
    fn every_declared_range_is_enforced() {
        let mut default = serde_json::to_value(EnvConfig::default()).unwrap();
        // The sensors section is left out at its default: write it in.
        default["sensors"] = serde_json::to_value(SensorsConfig::default()).unwrap();
        let mut checked = 0;
        for (key, f) in accd_spec::walk(EnvConfig::FIELDS) {
            if f.range.is_empty() {
                continue;
            }
            let r = accd_spec::Range::parse(f.range).unwrap();
            let (lo, hi) = match (r.lo, r.hi) {
                (
                    accd_spec::Bound::Open(lo) | accd_spec::Bound::Closed(lo),
                    accd_spec::Bound::Open(hi) | accd_spec::Bound::Closed(hi),
                ) => (lo, hi),
            };
            for outside in [hi + hi.abs() + 1.0, lo - lo.abs() - 1.0] {
                if !outside.is_finite() {
                    continue;
                }
                let mut doc = default.clone();
                let mut slot = &mut doc;
                for part in key.split('.') {
                    slot = slot.get_mut(part).unwrap_or_else(|| panic!("{key}"));
                }
                let field = match slot {
                    serde_json::Value::Array(a) => {
                        a[0] = outside.into();
                        format!("{key}[0]")
                    }
                    serde_json::Value::Null => {
                        *slot = serde_json::json!([outside, outside, outside]);
                        format!("{key}[0]")
                    }
                    other => {
                        *other = if other.is_u64() {
                            (outside.max(0.0) as u64).into()
                        } else {
                            outside.into()
                        };
                        key.clone()
                    }
                };
                if slot_is_unsigned_below_zero(&default, &key, outside) {
                    continue;
                }
                let e = EnvConfig::from_json(&doc.to_string())
                    .unwrap_err()
                    .to_string();
                assert!(
                    e.contains(&format!("`{field}`")) && e.contains(f.range),
                    "{key} = {outside}: {e}"
                );
                checked += 1;
            }
        }
        assert!(checked > 60, "{checked}");
    }

    /// A count (unsigned in JSON) cannot be negative: nothing to check below its range.
    fn slot_is_unsigned_below_zero(default: &serde_json::Value, key: &str, v: f64) -> bool {
        let mut slot = default;
        for part in key.split('.') {
            slot = &slot[part];
        }
        slot.is_u64() && v < 0.0
    }

    /// The sensors section is written only when it differs from its default (so the default
    /// document, and its hash, are as before), last, and reads back.
    #[test]
    fn the_sensors_section_is_written_last_and_only_when_set() {
        let text = serde_json::to_string(&EnvConfig::default()).unwrap();
        assert!(!text.contains("sensors"), "{text}");
        let mut c = EnvConfig::default();
        c.sensors.enabled = true;
        c.sensors.vision.latency = 0.1;
        let text = serde_json::to_string(&c).unwrap();
        let at = text.find("\"sensors\":").unwrap();
        assert!(text.find("\"wake_seeds\":").unwrap() < at, "{text}");
        let back = EnvConfig::from_json(&text).unwrap();
        assert_eq!(*back, c);
        let e = EnvConfig::from_json(
            r#"{"tether": {"time_step": 0.1}, "agent_step": 0.1, "sensors": {"enabled": true}}"#,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("`sensors.vision.update_rate`") && e.contains("20"),
            "{e}"
        );
        // Off, the rule does not apply.
        EnvConfig::from_json(r#"{"tether": {"time_step": 0.1}, "agent_step": 0.1}"#).unwrap();
        let e = EnvConfig::from_json(r#"{"sensors": {"vision": {"dropout": 0.7}}}"#)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`sensors.vision.dropout`") && e.contains("[0, 0.5]"),
            "{e}"
        );
    }
}
