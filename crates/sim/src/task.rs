//! The reinforcement-learning task (design.md §6): its configuration, the observation layout,
//! the reward and the episode-end conditions. The stepping itself is in [`crate::episode`].
//!
//! # Action
//! Four flap commands in [-1, 1] (right, left, top, bottom; the order of [`crate::accd::mix`]),
//! scaled by the flap limit (`accd.flap_limit_deg`, 15 degrees by default). Values outside
//! [-1, 1] are clipped; non-finite values are an error. Held for one agent step
//! ([`EnvConfig::agent_step`], 0.1 s = 10 physics steps by default).
//!
//! # Observation
//! `OBS_DIM` float32 values, each a physical quantity times a fixed scale, clipped to
//! [-`OBS_BOUND`, `OBS_BOUND`]. Vectors are in the TA frame (x forward, y starboard, z down)
//! unless stated. See [`OBSERVATION`] for the table (index, name, unit, scale).
//!
//! With `sensors.enabled` the observation is what the sensor model ([`crate::sensors`]) measures
//! of these quantities (same layout, names and scales); the reward and the episode end below
//! always use the true state.
//!
//! # Reward (per agent step)
//! With `d` the distance from the capture point to the boom tip at the end of the step (m),
//! `a` the action, `a'` the previous action (zero at the start):
//!
//! ```text
//! r = w_p exp(-d / lambda)                      proximity, in (0, w_p]
//!   - w_e sum(a^2) / 4                          control effort, in [0, w_e]
//!   - w_s sum(((a - a') / 2)^2) / 4             control rate, in [0, w_s]
//!   + [captured] (w_c + w_p * steps_left)       capture bonus
//!   - [overload or envelope exit or diverged] w_f
//! ```
//!
//! `steps_left` is the number of agent steps left in the capture window after this one: a
//! capture is always worth at least as much as hovering next to the boom for the rest of the
//! window, so an agent gains nothing by delaying it. Defaults: `w_p` 1, `lambda` 10 m,
//! `w_e` 0.05, `w_s` 0.05, `w_c` 100, `w_f` 50 ([`RewardConfig`]). Bounds: see
//! [`RewardConfig::bounds`].
//!
//! # Episode end
//! | condition | kind | checked |
//! |---|---|---|
//! | capture: capture point within `boom.capture_radius` of the boom tip at a relative speed under `boom.max_closing_speed` | terminated | every physics step |
//! | overload: attachment tension above `limits.overload_fraction` times the tether's breaking tension | terminated | every physics step |
//! | envelope exit: distance to the boom over `limits.max_distance`, the ACCD's nose more than `limits.max_tilt_deg` off the flight direction, a pitch/yaw rate over `limits.max_body_rate` (tumbling) or a roll rate over `limits.max_roll_rate` | terminated | every agent step |
//! | diverged: the simulation reported an error or a non-finite state (every physics step), or an implausible one: the ACCD faster than twice the airspeed relative to the aircraft or a body rate over 1000 rad/s (every agent step); the last good observation is kept | terminated | see left |
//! | capture window (`capture_window`, 70 s) elapsed | truncated | every agent step |

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::capture::Snapshot;
use crate::config::{parse_named, CaptureConfig};
use crate::error::Result;
use crate::randomization::RandomizationConfig;
use crate::sensors::{SensedLayout, Sensors, SensorsConfig};
use crate::valid::Valid;
use accd_spec::{join, out_of_range, Fields, OutOfRange, Rules};

/// Number of observation values.
pub const OBS_DIM: usize = 25;
/// Every observation value lies in [-OBS_BOUND, OBS_BOUND].
pub const OBS_BOUND: f32 = 10.0;
/// Number of action values (flap commands).
pub const ACT_DIM: usize = 4;

/// What the observation is computed from: the state's [`Snapshot`] and the episode's constants.
#[derive(Debug, Clone, Copy)]
pub struct ObservationInputs<'a> {
    /// Everything observable about the state.
    pub snapshot: &'a Snapshot,
    /// The ACCD's open-loop equilibrium position (TA frame), m.
    pub equilibrium: &'a Vector3<f64>,
    /// The flap limit, rad.
    pub flap_limit: f64,
    /// The capture window, s.
    pub capture_window: f64,
}

impl ObservationInputs<'_> {
    /// +1 or -1: the sign that puts the attitude quaternion in the hemisphere w >= 0 (q and -q
    /// are the same attitude; the observation shows one of them).
    #[inline]
    pub fn hemisphere(&self) -> f64 {
        if self.snapshot.attitude.w < 0.0 {
            -1.0
        } else {
            1.0
        }
    }
}

/// One row of the observation table: what the value is and how it is computed.
#[derive(Debug, Clone, Copy)]
pub struct ObservationField {
    /// Name (also the key users see).
    pub name: &'static str,
    /// Unit of the physical quantity.
    pub unit: &'static str,
    /// The observation value is the quantity times this scale (then clipped).
    pub scale: f64,
    /// What it is.
    pub description: &'static str,
    /// The physical quantity (in `unit`) at a state.
    pub value: fn(&ObservationInputs<'_>) -> f64,
}

/// The observation table, in index order: the one declaration the observation values
/// ([`observe`]), the names, the docs and Python's index constants come from.
pub const OBSERVATION: [ObservationField; OBS_DIM] = [
    ObservationField {
        name: "boom_rel_x",
        unit: "m",
        scale: 0.05,
        description: "boom tip minus capture point, x (forward)",
        value: |o| o.snapshot.boom_tip.x - o.snapshot.capture_point.x,
    },
    ObservationField {
        name: "boom_rel_y",
        unit: "m",
        scale: 0.05,
        description: "boom tip minus capture point, y (starboard)",
        value: |o| o.snapshot.boom_tip.y - o.snapshot.capture_point.y,
    },
    ObservationField {
        name: "boom_rel_z",
        unit: "m",
        scale: 0.05,
        description: "boom tip minus capture point, z (down)",
        value: |o| o.snapshot.boom_tip.z - o.snapshot.capture_point.z,
    },
    ObservationField {
        name: "boom_rel_vx",
        unit: "m/s",
        scale: 0.1,
        description: "boom-tip velocity minus capture-point velocity, x",
        value: |o| o.snapshot.boom_velocity.x - o.snapshot.capture_point_velocity.x,
    },
    ObservationField {
        name: "boom_rel_vy",
        unit: "m/s",
        scale: 0.1,
        description: "boom-tip velocity minus capture-point velocity, y",
        value: |o| o.snapshot.boom_velocity.y - o.snapshot.capture_point_velocity.y,
    },
    ObservationField {
        name: "boom_rel_vz",
        unit: "m/s",
        scale: 0.1,
        description: "boom-tip velocity minus capture-point velocity, z",
        value: |o| o.snapshot.boom_velocity.z - o.snapshot.capture_point_velocity.z,
    },
    ObservationField {
        name: "accd_dx",
        unit: "m",
        scale: 0.05,
        description: "ACCD position minus its open-loop equilibrium, x",
        value: |o| o.snapshot.position.x - o.equilibrium.x,
    },
    ObservationField {
        name: "accd_dy",
        unit: "m",
        scale: 0.05,
        description: "ACCD position minus its open-loop equilibrium, y",
        value: |o| o.snapshot.position.y - o.equilibrium.y,
    },
    ObservationField {
        name: "accd_dz",
        unit: "m",
        scale: 0.05,
        description: "ACCD position minus its open-loop equilibrium, z",
        value: |o| o.snapshot.position.z - o.equilibrium.z,
    },
    ObservationField {
        name: "accd_vx",
        unit: "m/s",
        scale: 0.1,
        description: "ACCD velocity relative to the aircraft, x",
        value: |o| o.snapshot.velocity.x,
    },
    ObservationField {
        name: "accd_vy",
        unit: "m/s",
        scale: 0.1,
        description: "ACCD velocity relative to the aircraft, y",
        value: |o| o.snapshot.velocity.y,
    },
    ObservationField {
        name: "accd_vz",
        unit: "m/s",
        scale: 0.1,
        description: "ACCD velocity relative to the aircraft, z",
        value: |o| o.snapshot.velocity.z,
    },
    ObservationField {
        name: "quat_w",
        unit: "-",
        scale: 1.0,
        description: "attitude quaternion body -> TA frame, scalar part (>= 0)",
        value: |o| o.hemisphere() * o.snapshot.attitude.w,
    },
    ObservationField {
        name: "quat_x",
        unit: "-",
        scale: 1.0,
        description: "attitude quaternion, x part",
        value: |o| o.hemisphere() * o.snapshot.attitude.i,
    },
    ObservationField {
        name: "quat_y",
        unit: "-",
        scale: 1.0,
        description: "attitude quaternion, y part",
        value: |o| o.hemisphere() * o.snapshot.attitude.j,
    },
    ObservationField {
        name: "quat_z",
        unit: "-",
        scale: 1.0,
        description: "attitude quaternion, z part",
        value: |o| o.hemisphere() * o.snapshot.attitude.k,
    },
    ObservationField {
        name: "rate_p",
        unit: "rad/s",
        scale: 0.5,
        description: "body roll rate",
        value: |o| o.snapshot.omega.x,
    },
    ObservationField {
        name: "rate_q",
        unit: "rad/s",
        scale: 0.5,
        description: "body pitch rate",
        value: |o| o.snapshot.omega.y,
    },
    ObservationField {
        name: "rate_r",
        unit: "rad/s",
        scale: 0.5,
        description: "body yaw rate",
        value: |o| o.snapshot.omega.z,
    },
    ObservationField {
        name: "flap_right",
        unit: "-",
        scale: 1.0,
        description: "right flap deflection / accd.flap_limit_deg",
        value: |o| o.snapshot.deflection[0] / o.flap_limit,
    },
    ObservationField {
        name: "flap_left",
        unit: "-",
        scale: 1.0,
        description: "left flap deflection / accd.flap_limit_deg",
        value: |o| o.snapshot.deflection[1] / o.flap_limit,
    },
    ObservationField {
        name: "flap_top",
        unit: "-",
        scale: 1.0,
        description: "top flap deflection / accd.flap_limit_deg",
        value: |o| o.snapshot.deflection[2] / o.flap_limit,
    },
    ObservationField {
        name: "flap_bottom",
        unit: "-",
        scale: 1.0,
        description: "bottom flap deflection / accd.flap_limit_deg",
        value: |o| o.snapshot.deflection[3] / o.flap_limit,
    },
    ObservationField {
        name: "tension",
        unit: "N",
        scale: 0.0001,
        description: "tension at the attachment",
        value: |o| o.snapshot.attachment_tension,
    },
    ObservationField {
        name: "time_left",
        unit: "-",
        scale: 1.0,
        description: "time left in the capture window / capture_window",
        value: |o| (o.capture_window - o.snapshot.time) / o.capture_window,
    },
];

/// The index of the observation entry `name`, if there is one.
pub fn observation_index(name: &str) -> Option<usize> {
    OBSERVATION.iter().position(|f| f.name == name)
}

/// The index of the observation entry `name`, at compile time (a name not in the table is a
/// compile error).
const fn index_of(name: &str) -> usize {
    let mut i = 0;
    while i < OBS_DIM {
        let a = OBSERVATION[i].name.as_bytes();
        let b = name.as_bytes();
        if a.len() == b.len() {
            let mut k = 0;
            while k < a.len() && a[k] == b[k] {
                k += 1;
            }
            if k == a.len() {
                return i;
            }
        }
        i += 1;
    }
    panic!("not an observation entry")
}

/// Where the sensor model ([`crate::sensors`]) finds the quantities it senses in the
/// observation; each group is contiguous in the table (`sensed_layout_matches_the_table`).
pub const SENSED_LAYOUT: SensedLayout = SensedLayout {
    dim: OBS_DIM,
    boom_rel: index_of("boom_rel_x"),
    boom_rel_rate: index_of("boom_rel_vx"),
    position: index_of("accd_dx"),
    velocity: index_of("accd_vx"),
    attitude: index_of("quat_w"),
    body_rates: index_of("rate_p"),
    tension: index_of("tension"),
};

/// The physical quantities of the observation of `inputs` (in their units, before scaling)
/// into `raw`; false if one is not finite.
pub fn raw_observation(inputs: &ObservationInputs<'_>, raw: &mut [f64; OBS_DIM]) -> bool {
    for (v, field) in raw.iter_mut().zip(&OBSERVATION) {
        *v = (field.value)(inputs);
    }
    raw.iter().all(|v| v.is_finite())
}

/// Each quantity of `raw` times its scale, clipped to [-[`OBS_BOUND`], [`OBS_BOUND`]], into `out`.
pub fn scale_observation(raw: &[f64; OBS_DIM], out: &mut [f32; OBS_DIM]) {
    for (o, (v, field)) in out.iter_mut().zip(raw.iter().zip(&OBSERVATION)) {
        *o = ((v * field.scale) as f32).clamp(-OBS_BOUND, OBS_BOUND);
    }
}

/// The observation of `inputs` into `out` (each quantity times its scale, clipped to
/// [-[`OBS_BOUND`], [`OBS_BOUND`]]) if every quantity is finite; false (and `out` unchanged)
/// otherwise.
pub fn observe(inputs: &ObservationInputs<'_>, out: &mut [f32; OBS_DIM]) -> bool {
    let mut raw = [0.0; OBS_DIM];
    if !raw_observation(inputs, &mut raw) {
        return false;
    }
    scale_observation(&raw, out);
    true
}

/// [`observe`] through `sensors`: the true quantities checked finite (false and `out` unchanged
/// otherwise), then measured ([`Sensors::sense`]), scaled and clipped, then delayed
/// ([`Sensors::delay`]).
pub fn observe_sensed(
    inputs: &ObservationInputs<'_>,
    sensors: &mut Sensors,
    out: &mut [f32; OBS_DIM],
) -> bool {
    let mut raw = [0.0; OBS_DIM];
    if !raw_observation(inputs, &mut raw) {
        return false;
    }
    sensors.sense(&mut raw);
    scale_observation(&raw, out);
    sensors.delay(out);
    true
}

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

/// The agent step a whole multiple of the physics step, the capture window a whole multiple of
/// the agent step, a wake-seed list not empty.
impl Rules for EnvConfig {
    fn check_rules(&self, prefix: &str) -> std::result::Result<(), OutOfRange> {
        let dt = self.physics.tether.time_step;
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
        }
        Ok(())
    }
}

impl EnvConfig {
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

/// Angle between the body's nose (body x) and the flight direction (TA x), rad.
pub fn tilt(attitude: &nalgebra::UnitQuaternion<f64>) -> f64 {
    let nose = attitude.transform_vector(&Vector3::x());
    nose.x.clamp(-1.0, 1.0).acos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accd::AccdConfig;

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

    /// The sensors' groups are contiguous runs of the table, in the order the layout says.
    #[test]
    fn sensed_layout_matches_the_table() {
        let l = SENSED_LAYOUT;
        let runs: [(usize, &[&str]); 7] = [
            (l.boom_rel, &["boom_rel_x", "boom_rel_y", "boom_rel_z"]),
            (
                l.boom_rel_rate,
                &["boom_rel_vx", "boom_rel_vy", "boom_rel_vz"],
            ),
            (l.position, &["accd_dx", "accd_dy", "accd_dz"]),
            (l.velocity, &["accd_vx", "accd_vy", "accd_vz"]),
            (l.attitude, &["quat_w", "quat_x", "quat_y", "quat_z"]),
            (l.body_rates, &["rate_p", "rate_q", "rate_r"]),
            (l.tension, &["tension"]),
        ];
        for (start, names) in runs {
            for (k, name) in names.iter().enumerate() {
                assert_eq!(OBSERVATION[start + k].name, *name);
            }
        }
        assert_eq!(l.dim, OBS_DIM);
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

    #[test]
    fn observation_table_is_complete() {
        let mut names: Vec<_> = OBSERVATION.iter().map(|f| f.name).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), OBS_DIM);
        assert!(OBSERVATION.iter().all(|f| f.scale > 0.0));
    }
}
