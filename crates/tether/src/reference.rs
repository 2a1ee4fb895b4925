//! Reference problems shared by the tests, the benchmarks and the command-line demos, so that
//! what is benchmarked is what is validated.

use nalgebra::Vector3;

use crate::atmosphere::Atmosphere;
use crate::config::TetherConfig;
use crate::error::Result;
use crate::surroundings::UniformFlow;

/// Airspeed of the towing aircraft during capture (paper section 2), m/s.
pub const TOWING_AIRSPEED: f64 = 185.0;
/// Altitude of the capture (paper section 2), m.
pub const TOWING_ALTITUDE: f64 = 6000.0;

/// The stand-in for the capturing device at the tip, used until the 6-DoF ACCD model exists:
/// a point mass with quadratic drag along its velocity relative to the air.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StandInBody {
    /// Mass, kg.
    pub mass: f64,
    /// Drag area C_D A, m^2.
    pub drag_area: f64,
}

impl StandInBody {
    /// A 1.5 m finned body of 0.3 m diameter (frontal area pi 0.15^2 = 0.0707 m^2) with a
    /// zero-lift drag coefficient of 0.6 on that area (nose, base and four fins), and 50 kg:
    /// assumptions within the 30-100 kg range that the paper's settled depths allow.
    pub fn accd() -> Self {
        let diameter: f64 = 0.3;
        let frontal_area = std::f64::consts::PI * diameter * diameter / 4.0;
        StandInBody {
            mass: 50.0,
            drag_area: 0.6 * frontal_area,
        }
    }
}

/// Table 3's tether carrying `body`, towed at 185 m/s through ISA air at 6000 m: the config (with
/// the body's mass at the tip) and the surroundings (uniform flow, the body's drag).
pub fn towed(config: &TetherConfig, body: StandInBody) -> Result<(TetherConfig, UniformFlow)> {
    let air = Atmosphere::isa(TOWING_ALTITUDE)?;
    let config = TetherConfig {
        tip_mass: body.mass,
        ..config.clone()
    };
    config.validate()?;
    let flow = UniformFlow {
        tip_drag_area: body.drag_area,
        ..UniformFlow::towing(TOWING_AIRSPEED, air.density)
    };
    Ok((config, flow))
}

/// Table 3's tether with the stand-in ACCD, towed at the paper's flight condition.
pub fn towed_table3() -> (TetherConfig, UniformFlow) {
    towed(&TetherConfig::table3(), StandInBody::accd()).expect("the reference case is valid")
}

/// A chain hanging straight down (all segments along +z), as used by the hanging-chain tests.
pub fn hanging_direction() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, 1.0)
}

/// A chain trailing straight back (all segments along -x): the paper's initial condition.
pub fn trailing_direction() -> Vector3<f64> {
    Vector3::new(-1.0, 0.0, 0.0)
}
