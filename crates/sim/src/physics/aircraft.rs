//! The towing aircraft (TA): straight flight at constant airspeed by default, or a scripted
//! acceleration profile, which enters the tether as the rheonomous constraint (paper section
//! 2.3.5) and changes the free stream the tether and the ACCD see.
//!
//! The TA frame translates with the aircraft without rotating. With the aircraft's velocity
//! `V(t) = V0 + integral of a` (relative to the air mass), the free stream in the TA frame is
//! `-V(t)`, and every mass feels the apparent force `-m a(t)`.

use accd_spec::{join, out_of_range, Fields, OutOfRange, Rules};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::Result;

type V3 = Vector3<f64>;

/// One segment of a piecewise-constant acceleration profile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccelerationSegment {
    /// Start time, s.
    pub start: f64,
    /// End time, s (> start).
    pub end: f64,
    /// Acceleration of the TA in its frame (x forward, y right, z down), m/s^2.
    pub acceleration: [f64; 3],
}

accd_spec::config_struct! {
    /// Flight condition and manoeuvre of the towing aircraft.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct AircraftConfig {
        pub airspeed: f64 = 185.0, "m/s", "(0, 400]", "true airspeed at t = 0 (paper section 2)";
        pub altitude: f64 = 6000.0, "m", "[0, 15000]", "altitude at t = 0, ISA (paper section 2)";
        /// Each segment `{"start": s, "end": s, "acceleration": [x, y, z] m/s^2}`; segments must
        /// not overlap.
        pub acceleration_profile: Vec<AccelerationSegment> = vec![], "", "",
            "scripted piecewise-constant accelerations (empty: constant speed)";
    }
}

accd_spec::no_range!(AccelerationSegment);

/// Checks an airspeed (m/s) against the range every part of the simulation accepts: that of
/// `aircraft.airspeed`.
pub fn check_airspeed(field: &str, value: f64) -> Result<()> {
    Ok(accd_spec::check_number(field, value, AIRSPEED)?)
}

/// The declaration of `aircraft.airspeed` (the first field; a test checks the name).
const AIRSPEED: &accd_spec::FieldSpec = &AircraftConfig::FIELDS[0];

/// Acceleration segments in order, not overlapping, with bounded accelerations.
impl Rules for AircraftConfig {
    fn check_rules(&self, prefix: &str) -> std::result::Result<(), OutOfRange> {
        let mut last_end = f64::NEG_INFINITY;
        for (i, seg) in self.acceleration_profile.iter().enumerate() {
            let field = format!("{}[{i}]", join(prefix, "acceleration_profile"));
            if !(seg.start.is_finite()
                && seg.end.is_finite()
                && seg.start >= 0.0
                && seg.end > seg.start)
            {
                return Err(out_of_range(
                    &field,
                    format!("start {} end {}", seg.start, seg.end),
                    "0 <= start < end, finite",
                ));
            }
            if seg.start < last_end {
                return Err(out_of_range(
                    &field,
                    seg.start,
                    "start at or after the previous segment's end",
                ));
            }
            if seg
                .acceleration
                .iter()
                .any(|a| !a.is_finite() || a.abs() > 30.0)
            {
                return Err(out_of_range(
                    &format!("{field}.acceleration"),
                    format!("{:?}", seg.acceleration),
                    "components in [-30, 30] m/s^2",
                ));
            }
            last_end = seg.end;
        }
        Ok(())
    }
}

impl AircraftConfig {
    /// Checks every field against its declared range and the [`Rules`]; errors name the field
    /// as `aircraft.<field>`.
    pub fn validate(&self) -> Result<()> {
        Ok(self.check_fields("aircraft")?)
    }

    /// Acceleration of the TA at time `t`, m/s^2.
    pub fn acceleration(&self, t: f64) -> V3 {
        self.acceleration_profile
            .iter()
            .find(|s| t >= s.start && t < s.end)
            .map_or(V3::zeros(), |s| V3::from(s.acceleration))
    }

    /// Velocity of the TA relative to the air mass at time `t` (exact integral of the profile), m/s.
    pub fn velocity(&self, t: f64) -> V3 {
        let mut v = V3::new(self.airspeed, 0.0, 0.0);
        for s in &self.acceleration_profile {
            let dt = (t.min(s.end) - s.start).max(0.0);
            v += V3::from(s.acceleration) * dt;
        }
        v
    }

    /// Altitude of the TA at time `t` (ISA), m: the initial altitude minus the integral of the
    /// vertical (z-down) velocity.
    pub fn altitude_at(&self, t: f64) -> f64 {
        // Each segment adds a z-velocity ramp: its integral is u^2/2 while inside (u the time
        // spent in it so far) and grows linearly at the final velocity afterwards.
        let descent: f64 = self
            .acceleration_profile
            .iter()
            .map(|s| {
                let duration = s.end - s.start;
                let inside = (t - s.start).clamp(0.0, duration);
                s.acceleration[2] * (0.5 * inside * inside + duration * (t - s.end).max(0.0))
            })
            .sum();
        self.altitude - descent
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn airspeed_check_is_the_declared_one() {
        assert_eq!(AIRSPEED.name, "airspeed");
        let e = check_airspeed("airspeed_mps", 401.0)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("airspeed_mps") && e.contains("(0, 400] m/s"),
            "{e}"
        );
    }

    #[test]
    fn profile_integrates_exactly() {
        let cfg = AircraftConfig {
            acceleration_profile: vec![
                AccelerationSegment {
                    start: 1.0,
                    end: 3.0,
                    acceleration: [2.0, 0.0, 1.0],
                },
                AccelerationSegment {
                    start: 5.0,
                    end: 6.0,
                    acceleration: [-4.0, 0.0, -2.0],
                },
            ],
            ..AircraftConfig::default()
        };
        cfg.validate().unwrap();
        assert_eq!(cfg.acceleration(0.5), V3::zeros());
        assert_eq!(cfg.acceleration(2.0), V3::new(2.0, 0.0, 1.0));
        assert_eq!(cfg.velocity(2.0), V3::new(187.0, 0.0, 1.0));
        assert_eq!(cfg.velocity(4.0), V3::new(189.0, 0.0, 2.0));
        assert_eq!(cfg.velocity(10.0), V3::new(185.0, 0.0, 0.0));
        // Vertical: 1 m/s^2 for 2 s -> 2 m down by t = 3, then 2 m/s down until t = 5 (4 m),
        // then -2 m/s^2 for 1 s -> 1 m more; then at rest: 7 m down in all.
        assert!((cfg.altitude_at(3.0) - 5998.0).abs() < 1e-12);
        assert!(
            (cfg.altitude_at(10.0) - 5993.0).abs() < 1e-12,
            "{}",
            cfg.altitude_at(10.0)
        );
    }

    #[test]
    fn overlapping_segments_are_refused() {
        let cfg = AircraftConfig {
            acceleration_profile: vec![
                AccelerationSegment {
                    start: 0.0,
                    end: 3.0,
                    acceleration: [1.0, 0.0, 0.0],
                },
                AccelerationSegment {
                    start: 2.0,
                    end: 4.0,
                    acceleration: [1.0, 0.0, 0.0],
                },
            ],
            ..AircraftConfig::default()
        };
        assert!(cfg
            .validate()
            .unwrap_err()
            .to_string()
            .contains("acceleration_profile[1]"));
    }
}
