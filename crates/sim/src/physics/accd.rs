//! The Aerodynamically Controlled Capturing Device (ACCD): a 6-DoF rigid body at the tether's tip,
//! joined at its centre of gravity by a spherical joint (paper section 3): the tether carries its
//! translation, its attitude and rates follow its own aerodynamic moments.
//!
//! Rotational dynamics in body axes (x nose, y right, z down), attitude as the unit quaternion
//! `q` rotating body vectors into the towing-aircraft frame:
//!
//! ```text
//! I w' = M_aero - w x (I w)        q' = q (0, w) / 2
//! ```
//!
//! Four flaps (right, left, top, bottom; see [`crate::physics::aero`] for their signs) follow their
//! commands through a first-order lag with a rate limit and hard stops at +-`flap_limit_deg`.

use accd_spec::{join, out_of_range, Fields, OutOfRange, Rules};
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Result, SimError};
use crate::physics::aero::AeroModel;

type V3 = Vector3<f64>;

/// Below this airspeed (m/s) the ACCD feels no aerodynamic load (angles are undefined).
const MIN_AIRSPEED: f64 = 1.0;

accd_spec::config_struct! {
    /// Mass, geometry, actuators and aerodynamic data of the ACCD. SI units unless the name says.
    ///
    /// The paper gives the length (1.5 m with fins) and the flap limit (+-15 deg); the rest are
    /// documented assumptions. The mass (50 kg) is calibrated with the tether's normal drag
    /// coefficient so that the open-loop settled depths of the paper hold (see README).
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct AccdConfig {
        pub mass: f64 = 50.0, "kg", "(0, 1000]", "mass";
        pub length: f64 = 1.5, "m", "(0, 10]", "length including the fins (paper section 2.1)";
        pub diameter: f64 = 0.3, "m", "(0, 2]", "body diameter";
        pub cg_from_nose: f64 = 0.6, "m", "(0, 10]",
            "centre of gravity behind the nose, at most accd.length";
        /// `None`: a solid cylinder of the mass, length and diameter (0.56, 9.66, 9.66).
        pub inertia: Option<[f64; 3]> = None, "kg m^2", "(0, 1e4]",
            "principal moments of inertia (roll, pitch, yaw) about the centre of gravity (None: a solid cylinder's)";
        pub flap_limit_deg: f64 = 15.0, "deg", "(0, 45]", "flap deflection limit (paper section 2.1)";
        pub actuator_time_constant: f64 = 0.05, "s", "(0, 1]",
            "time constant of the flap actuators' first-order lag";
        pub actuator_rate_limit_deg_s: f64 = 300.0, "deg/s", "(0, 5000]",
            "rate limit of the flap actuators";
        /// See [`crate::physics::aero`] for the file format; an inline table (text starting with `{`) is a
        /// configuration that carries its table, for pickles and saved envs.
        pub aero_table: Option<String> = None, "", "",
            "aerodynamic table: a file path (a regular file of at most 64 MiB) or the table as JSON text (None: the default finned body)";
        /// The table's uncertainty, for robustness studies and randomized physics: every force
        /// coefficient (base and flap increments) is multiplied by it.
        pub force_coefficient_scale: f64 = 1.0, "-", "(0, 10]",
            "factor on the table's force coefficients C_X, C_Y, C_Z";
        /// Static moments, flap increments (the control effectiveness) and damping derivatives.
        pub moment_coefficient_scale: f64 = 1.0, "-", "(0, 10]",
            "factor on the table's moment coefficients C_l, C_m, C_n and damping derivatives";
    }
}

/// The centre of gravity within the body; principal moments satisfying the triangle inequality.
impl Rules for AccdConfig {
    fn check_rules(&self, prefix: &str) -> std::result::Result<(), OutOfRange> {
        if self.cg_from_nose > self.length {
            return Err(out_of_range(
                &join(prefix, "cg_from_nose"),
                self.cg_from_nose,
                format!("(0, {}] m", join(prefix, "length")),
            ));
        }
        if let Some(inertia) = self.inertia {
            let [a, b, c] = inertia;
            if a + b < c || b + c < a || a + c < b {
                return Err(out_of_range(
                    &join(prefix, "inertia"),
                    format!("{inertia:?}"),
                    "principal moments satisfying the triangle inequality",
                ));
            }
        }
        Ok(())
    }
}

impl AccdConfig {
    /// Checks every field against its declared range and the [`Rules`]; errors name the field
    /// as `accd.<field>`.
    pub fn validate(&self) -> Result<()> {
        Ok(self.check_fields("accd")?)
    }

    /// Principal moments of inertia, kg m^2 (the configured ones, or a solid cylinder's).
    pub fn principal_inertia(&self) -> V3 {
        match self.inertia {
            Some([a, b, c]) => V3::new(a, b, c),
            None => {
                let r = 0.5 * self.diameter;
                let axial = 0.5 * self.mass * r * r;
                let transverse = self.mass * (3.0 * r * r + self.length * self.length) / 12.0;
                V3::new(axial, transverse, transverse)
            }
        }
    }

    /// Position of the capture mechanism (the tail) relative to the centre of gravity, body axes, m.
    pub fn capture_point(&self) -> V3 {
        V3::new(-(self.length - self.cg_from_nose), 0.0, 0.0)
    }

    /// The aerodynamic model this config names; a flap limit beyond the table's deflection
    /// range (where the table would hold its edge values) is an error.
    pub fn aero_model(&self) -> Result<AeroModel> {
        let model = match &self.aero_table {
            None => AeroModel::accd(),
            Some(text) if text.trim_start().starts_with('{') => {
                AeroModel::from_json(text, "accd.aero_table (inline)")?
            }
            Some(path) => AeroModel::from_path(std::path::Path::new(path), "accd.aero_table")?,
        };
        let model = if self.force_coefficient_scale == 1.0 && self.moment_coefficient_scale == 1.0 {
            model
        } else {
            model.scaled(self.force_coefficient_scale, self.moment_coefficient_scale)
        };
        let (lo, hi) = model.deflection_range_deg();
        let reach = (-lo).min(hi);
        // Degrees and radians round trip within a few ulps.
        if self.flap_limit_deg > reach + 1e-9 {
            return Err(SimError::invalid_config(
                "accd.flap_limit_deg",
                self.flap_limit_deg,
                &format!(
                    "(0, {reach}] deg: the aerodynamic table covers deflections [{lo}, {hi}] deg"
                ),
            ));
        }
        Ok(model)
    }
}

/// Flap deflections from pitch, yaw and roll commands (any angle unit), paper Fig. 5: pitch moves
/// both horizontal flaps, yaw both vertical flaps, roll all four differentially. Positive pitch
/// is nose up, positive yaw nose right, positive roll right side down. Order: right, left, top,
/// bottom. The sum may exceed the flap limit; the actuators clip it.
pub fn mix(pitch: f64, yaw: f64, roll: f64) -> [f64; 4] {
    [pitch + roll, pitch - roll, yaw - roll, yaw + roll]
}

/// The four flap actuators: commanded and actual deflections, rad.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Actuators {
    /// Commanded deflections (right, left, top, bottom), rad, clipped to the limit.
    pub command: [f64; 4],
    /// Actual deflections, rad.
    pub deflection: [f64; 4],
}

impl Actuators {
    /// Sets the commands (rad), clipped to +-limit. Non-finite commands are rejected.
    pub fn set_command(&mut self, config: &AccdConfig, command: [f64; 4]) -> Result<()> {
        let limit = config.flap_limit_deg.to_radians();
        for (i, c) in command.iter().enumerate() {
            if !c.is_finite() {
                return Err(SimError::invalid_config(
                    &format!("flap_command[{i}]"),
                    c,
                    "a finite angle",
                ));
            }
            self.command[i] = c.clamp(-limit, limit);
        }
        Ok(())
    }

    /// Advances the actuators by `dt`: exact first-order lag towards the command, then the rate
    /// limit, then the hard stops.
    pub fn advance(&mut self, config: &AccdConfig, dt: f64) {
        let lag = 1.0 - libm::exp(-dt / config.actuator_time_constant);
        let max_change = config.actuator_rate_limit_deg_s.to_radians() * dt;
        let limit = config.flap_limit_deg.to_radians();
        for i in 0..4 {
            let change =
                ((self.command[i] - self.deflection[i]) * lag).clamp(-max_change, max_change);
            self.deflection[i] = (self.deflection[i] + change).clamp(-limit, limit);
        }
    }
}

/// Attitude and body rates of the ACCD.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccdState {
    /// Rotation from body axes to the TA frame.
    pub attitude: UnitQuaternion<f64>,
    /// Angular velocity in body axes (p, q, r), rad/s.
    pub omega: V3,
}

impl Default for AccdState {
    /// Nose forward along the flight path, level, at rest: body axes aligned with the TA frame.
    fn default() -> Self {
        AccdState {
            attitude: UnitQuaternion::identity(),
            omega: V3::zeros(),
        }
    }
}

/// Aerodynamic loads on the ACCD and the flow angles they came from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AeroLoads {
    /// Force in the TA frame, N.
    pub force: V3,
    /// Moment about the centre of gravity in body axes, N m.
    pub moment: V3,
    /// Angle of attack, rad.
    pub alpha: f64,
    /// Sideslip, rad.
    pub beta: f64,
    /// Airspeed, m/s.
    pub airspeed: f64,
}

/// Aerodynamic force and moment on the ACCD moving at `velocity` (TA frame, m/s) through air of
/// velocity `wind` (TA frame, m/s) and density `density`, with attitude, body rates and flap
/// deflections (rad).
pub fn aero_loads(
    model: &AeroModel,
    state: &AccdState,
    velocity: &V3,
    wind: &V3,
    density: f64,
    deflections: &[f64; 4],
) -> AeroLoads {
    let air_relative_body = state.attitude.inverse_transform_vector(&(velocity - wind));
    let airspeed = air_relative_body.norm();
    if airspeed < MIN_AIRSPEED || density <= 0.0 {
        return AeroLoads {
            airspeed,
            ..AeroLoads::default()
        };
    }
    let (u, v, w) = (
        air_relative_body.x,
        air_relative_body.y,
        air_relative_body.z,
    );
    let alpha = libm::atan2(w, u);
    let beta = libm::asin((v / airspeed).clamp(-1.0, 1.0));
    let c = model.coefficients(alpha, beta, deflections);
    let qbar_s = 0.5 * density * airspeed * airspeed * model.reference_area();
    let d = model.reference_length();
    let rate = d / (2.0 * airspeed);
    let damping = model.damping();
    let force_body = V3::new(c[0], c[1], c[2]) * qbar_s;
    let moment = V3::new(
        c[3] + damping.clp * state.omega.x * rate,
        c[4] + damping.cmq * state.omega.y * rate,
        c[5] + damping.cnr * state.omega.z * rate,
    ) * (qbar_s * d);
    AeroLoads {
        force: state.attitude.transform_vector(&force_body),
        moment,
        alpha,
        beta,
        airspeed,
    }
}

/// Angular acceleration in body axes from Euler's equations, for principal inertia `inertia`.
pub fn angular_acceleration(inertia: &V3, omega: &V3, moment: &V3) -> V3 {
    let h = inertia.component_mul(omega);
    (moment - omega.cross(&h)).component_div(inertia)
}

/// Rotational kinetic energy (J) and angular momentum in the TA frame (N m s) of a state.
pub fn rotational_invariants(inertia: &V3, state: &AccdState) -> (f64, V3) {
    let h_body = inertia.component_mul(&state.omega);
    (
        0.5 * state.omega.dot(&h_body),
        state.attitude.transform_vector(&h_body),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_inertia_is_a_solid_cylinder() {
        let c = AccdConfig::default();
        let i = c.principal_inertia();
        assert!((i.x - 0.5625).abs() < 1e-12);
        assert!((i.y - 50.0 * (3.0 * 0.0225 + 2.25) / 12.0).abs() < 1e-12);
        assert_eq!(c.capture_point(), V3::new(-0.9, 0.0, 0.0));
        c.validate().unwrap();
    }

    #[test]
    fn bad_config_is_named() {
        let c = AccdConfig {
            mass: -1.0,
            ..AccdConfig::default()
        };
        assert!(c.validate().unwrap_err().to_string().contains("accd.mass"));
        let c = AccdConfig {
            inertia: Some([1.0, 1.0, 5.0]),
            ..AccdConfig::default()
        };
        assert!(c.validate().unwrap_err().to_string().contains("triangle"));
    }

    #[test]
    fn actuators_lag_rate_limit_and_clip() {
        let cfg = AccdConfig::default();
        let mut act = Actuators::default();
        act.set_command(&cfg, [1.0, -1.0, 0.1, 0.0]).unwrap();
        let limit = 15f64.to_radians();
        assert_eq!(act.command[0], limit);
        assert_eq!(act.command[1], -limit);
        act.advance(&cfg, 0.01);
        // First-order lag: 1 - exp(-0.01 / 0.05) of the way, under the 3 deg rate limit.
        let lag = 1.0 - (-0.2f64).exp();
        assert!((act.deflection[0] - lag * limit).abs() < 1e-12);
        // A fast actuator hits the rate limit: 300 deg/s * 0.01 s = 3 deg.
        let fast = AccdConfig {
            actuator_time_constant: 0.001,
            ..cfg.clone()
        };
        let mut quick = Actuators::default();
        quick.set_command(&fast, [1.0, 0.0, 0.0, 0.0]).unwrap();
        quick.advance(&fast, 0.01);
        assert!((quick.deflection[0] - 3f64.to_radians()).abs() < 1e-12);
        for _ in 0..200 {
            act.advance(&cfg, 0.01);
        }
        assert!((act.deflection[0] - limit).abs() < 1e-9);
        assert!((act.deflection[2] - 0.1).abs() < 1e-9);
        assert!(act.set_command(&cfg, [f64::NAN, 0.0, 0.0, 0.0]).is_err());
    }

    #[test]
    fn mixing_follows_fig5() {
        assert_eq!(mix(1.0, 0.0, 0.0), [1.0, 1.0, 0.0, 0.0]);
        assert_eq!(mix(0.0, 1.0, 0.0), [0.0, 0.0, 1.0, 1.0]);
        assert_eq!(mix(0.0, 0.0, 1.0), [1.0, -1.0, -1.0, 1.0]);
    }

    #[test]
    fn aligned_body_feels_pure_drag() {
        let model = AeroModel::accd();
        let st = AccdState::default();
        let loads = aero_loads(
            &model,
            &st,
            &V3::zeros(),
            &V3::new(-185.0, 0.0, 0.0),
            0.66,
            &[0.0; 4],
        );
        assert!(loads.alpha.abs() < 1e-15 && loads.beta.abs() < 1e-15);
        assert!(loads.force.x < 0.0 && loads.force.y.abs() < 1e-9 && loads.force.z.abs() < 1e-9);
        let expected = 0.5 * 0.66 * 185.0f64.powi(2) * model.reference_area() * 0.6;
        assert!((loads.force.x + expected).abs() < 1e-9 * expected);
        assert!(loads.moment.norm() < 1e-9);
    }
}
