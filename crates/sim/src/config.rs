//! The physics configuration ([`CaptureConfig`]: tether, ACCD, aircraft, boom, wake,
//! turbulence), the rules between its fields, and the reading of configuration documents (JSON
//! with unknown keys refused and a bad value named by its dotted path). The task's configuration
//! ([`crate::EnvConfig`]) builds on it.

use accd_spec::{join, out_of_range, Fields, OutOfRange, Rules};
use accd_tether::TetherConfig;
use serde::{Deserialize, Serialize};

use crate::error::{Result, SimError};
use crate::physics::accd::AccdConfig;
use crate::physics::aircraft::AircraftConfig;
use crate::physics::boom::BoomConfig;
use crate::physics::turbulence::TurbulenceConfig;
use crate::physics::wake::WakeConfig;
use crate::valid::Valid;

accd_spec::config_struct! {
    /// Everything that defines an episode's physics: one section a physics part. Missing keys
    /// take their defaults. A new part is one more line here: the range checks, the rules
    /// ([`Section::validate`]), the flat keys of [`crate::EnvConfig`] and the documentation
    /// follow from it.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct CaptureConfig {
        /// Its `tip_mass` must stay 0: the ACCD's mass is at the tip.
        pub tether: TetherConfig = TetherConfig::table3(), "", "",
            "the tether (Table 3 by default; a dict, or a preset name in Python)";
        pub accd: AccdConfig = AccdConfig::default(), "", "", "the capturing device";
        pub aircraft: AircraftConfig = AircraftConfig::default(), "", "",
            "the towing aircraft (185 m/s at 6000 m by default)";
        pub boom: BoomConfig = BoomConfig::default(), "", "", "the RLV's boom";
        pub wake: WakeConfig = WakeConfig::default(), "", "",
            "the towing aircraft's mean wake (on by default, at 8 degrees angle of attack)";
        pub turbulence: TurbulenceConfig = TurbulenceConfig::default(), "", "",
            "wake and ambient turbulence (wake turbulence on by default, ambient off)";
    }
}

/// Between the sections: the tether's tip mass is the ACCD's ([`check_cross_fields`] has the
/// rest).
impl Rules for CaptureConfig {
    fn check_rules(&self, prefix: &str) -> std::result::Result<(), OutOfRange> {
        if self.tether.tip_mass != 0.0 {
            return Err(out_of_range(
                &join(prefix, "tether.tip_mass"),
                self.tether.tip_mass,
                "0 kg (the ACCD's mass, accd.mass, is the tip mass)",
            ));
        }
        check_cross_fields(self)
    }
}

impl CaptureConfig {
    /// Checks every field against its declared range and every section's rules, then the rules
    /// between the sections ([`Rules`]); counted by [`crate::valid::validation_passes`].
    pub fn validate(&self) -> Result<()> {
        crate::valid::count_validation_pass();
        Ok(self.check_fields("")?)
    }

    /// The paper's open-loop setting (section 4): no wake, no turbulence ("no wake unless stated").
    pub fn calm() -> Self {
        let mut config = CaptureConfig::default();
        config.wake.enabled = false;
        config.turbulence.wake_turbulence = false;
        config
    }

    /// Parses JSON (unknown keys are errors) and validates.
    pub fn from_json(text: &str) -> Result<Valid<Self>> {
        let config: CaptureConfig = parse_json(text, "(document)")?;
        config.validated()
    }

    /// The configuration, validated ([`CaptureConfig::validate`]): what the simulation takes.
    pub fn validated(self) -> Result<Valid<Self>> {
        self.validate()?;
        Ok(Valid::trusted(self))
    }

    /// The tether with the ACCD's mass at its tip.
    pub fn tether_with_tip(&self) -> TetherConfig {
        TetherConfig {
            tip_mass: self.accd.mass,
            ..self.tether.clone()
        }
    }
}

/// Parses a JSON config document; serde's message (unknown field, wrong type, with the line and
/// column) becomes an [`SimError::InvalidConfig`] for `what`.
pub(crate) fn parse_json<T: serde::de::DeserializeOwned>(text: &str, _what: &str) -> Result<T> {
    parse_named(text)
}

/// Rules between the fields of a physics configuration (each field's own range is checked by
/// its part): the flap limit within the default aerodynamic table's deflection range (a user
/// table is checked when loaded, [`crate::physics::accd::AccdConfig::aero_model`]), and a tether step
/// that substepping can keep stable at the tension the tow is estimated to reach
/// ([`accd_tether::TetherConfig::check_stability`]).
pub fn check_cross_fields(config: &CaptureConfig) -> std::result::Result<(), OutOfRange> {
    if config.accd.aero_table.is_none() {
        let range = crate::physics::aero::DEFAULT_DEFLECTION_LIMIT_DEG;
        if config.accd.flap_limit_deg > range {
            return Err(out_of_range(
                "accd.flap_limit_deg",
                config.accd.flap_limit_deg,
                format!("(0, {range}] deg: the default aerodynamic table covers deflections up to {range} deg (give accd.aero_table for more)"),
            ));
        }
    }
    config
        .turbulence
        .check_history(config.aircraft.airspeed, "aircraft.airspeed")?;
    let (tension, density, airspeed) = estimated_peak_load(config);
    config
        .tether
        .check_stability(tension, density, airspeed, config.accd.mass)
        .map_err(|e| match e {
            accd_tether::TetherError::InvalidConfig {
                field,
                value,
                allowed,
            } => OutOfRange {
                field: format!("tether.{field}"),
                value,
                allowed: format!(
                    "{} (the tension estimated from the weight of tether and accd.mass = {} kg \
                     at tether.gravity = {} m/s^2 and the drag of tether.diameter = {} m \
                     (tether.normal_drag_coefficient = {}, tether.tangential_drag_coefficient = \
                     {}) at aircraft.airspeed = {} m/s)",
                    qualify(&allowed, "tether."),
                    config.accd.mass,
                    config.tether.gravity,
                    config.tether.diameter,
                    config.tether.normal_drag_coefficient,
                    config.tether.tangential_drag_coefficient,
                    config.aircraft.airspeed
                ),
            },
            other => out_of_range(
                "tether.time_step",
                config.tether.time_step,
                other.to_string(),
            ),
        })
}

/// `text` (the tether crate's message, which names the tether's fields bare: `length = 250 m`)
/// with every tether field written before ` = ` given its dotted name (`tether.length = 250 m`),
/// so that the message names the fields as the configuration does.
fn qualify(text: &str, prefix: &str) -> String {
    let words: Vec<&str> = text.split(' ').collect();
    let is_field = |w: &str| {
        TetherConfig::FIELDS
            .iter()
            .any(|f| !f.name.is_empty() && f.name == w)
    };
    words
        .iter()
        .enumerate()
        .map(|(i, w)| {
            if is_field(w) && words.get(i + 1) == Some(&"=") {
                format!("{prefix}{w}")
            } else {
                (*w).to_string()
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// A rough peak tension of the tow (N) with the air it flies in (sea-level density, an upper
/// bound, and the airspeed): the weight of tether and ACCD plus the skin friction and cross-flow
/// drag of the whole tether, for the stability check at validation. The step itself substeps
/// from the actual tension ([`crate::CaptureSim::substeps`]).
pub fn estimated_peak_load(config: &CaptureConfig) -> (f64, f64, f64) {
    const DENSITY: f64 = 1.225;
    let t = &config.tether;
    let v = config.aircraft.airspeed;
    let q = 0.5 * DENSITY * v * v;
    let drag = q
        * t.diameter
        * t.length
        * (std::f64::consts::PI * t.tangential_drag_coefficient + t.normal_drag_coefficient);
    let weight = (t.total_mass() + config.accd.mass) * t.gravity;
    (weight + drag, DENSITY, v)
}

/// Deserializes a config document; on failure the error names the dotted field whose value
/// could not be read (see [`locate_parse_error`]), the value and the expected type.
pub fn parse_named<T: serde::de::DeserializeOwned>(text: &str) -> Result<T> {
    match serde_json::from_str::<T>(text) {
        Ok(v) => Ok(v),
        Err(e) => {
            let message = strip_position(&e.to_string());
            let Ok(value) = serde_json::from_str::<serde_json::Value>(text) else {
                return Err(SimError::InvalidConfig {
                    field: "(document)".into(),
                    value: "not JSON".into(),
                    allowed: format!("a JSON object ({message})"),
                });
            };
            if !value.is_object() {
                return Err(SimError::invalid_config(
                    "(document)",
                    short(&value),
                    "a JSON object of configuration keys",
                ));
            }
            Err(match locate_parse_error::<T>(&value) {
                Some((field, v)) => SimError::InvalidConfig {
                    field,
                    value: short(&v),
                    allowed: format!("of its type: {message}"),
                },
                None => SimError::InvalidConfig {
                    field: "(document)".into(),
                    value: String::new(),
                    allowed: message,
                },
            })
        }
    }
}

/// A JSON value printed, cut to 60 characters.
fn short(v: &serde_json::Value) -> String {
    let s = v.to_string();
    if s.chars().count() > 60 {
        format!("{}...", s.chars().take(57).collect::<String>())
    } else {
        s
    }
}

/// serde_json's message without " at line L column C" (positions in a merged document mean
/// nothing to the user).
fn strip_position(message: &str) -> String {
    message
        .split(" at line ")
        .next()
        .unwrap_or(message)
        .to_string()
}

/// The dotted path and value of the first field of `document` that `T` cannot read: every
/// struct of the configuration fills missing keys with defaults, so a document with one key
/// alone (nested objects narrowed the same way) fails exactly when that key's value is bad.
pub fn locate_parse_error<T: serde::de::DeserializeOwned>(
    document: &serde_json::Value,
) -> Option<(String, serde_json::Value)> {
    fn wrap(path: &[String], leaf: serde_json::Value) -> serde_json::Value {
        path.iter().rev().fold(leaf, |inner, key| {
            let mut m = serde_json::Map::new();
            m.insert(key.clone(), inner);
            serde_json::Value::Object(m)
        })
    }
    fn walk<T: serde::de::DeserializeOwned>(
        path: &mut Vec<String>,
        value: &serde_json::Map<String, serde_json::Value>,
    ) -> Option<(String, serde_json::Value)> {
        for (k, v) in value {
            path.push(k.clone());
            let alone = wrap(path, v.clone());
            if serde_json::from_value::<T>(alone).is_err() {
                // Narrow into an object only where the field takes one (`{}` reads as defaults).
                let takes_object = serde_json::from_value::<T>(wrap(
                    path,
                    serde_json::Value::Object(serde_json::Map::new()),
                ))
                .is_ok();
                if let (Some(inner), true) = (v.as_object(), takes_object) {
                    if let Some(found) = walk::<T>(path, inner) {
                        return Some(found);
                    }
                }
                return Some((path.join("."), v.clone()));
            }
            path.pop();
        }
        None
    }
    walk::<T>(&mut Vec::new(), document.as_object()?)
}
