//! Test support: a standalone [`WakeField`] from a small configuration of flight condition,
//! wake and turbulence (the capture simulation builds its field from its own configuration with
//! [`WakeField::from_parts`]; this is not production API).

use accd_sim::physics::turbulence::{Turbulence, TurbulenceConfig};
use accd_sim::physics::wake::{Wake, WakeConfig, WakeTables};
use accd_sim::{SimError, WakeField};
use accd_tether::Atmosphere;

/// Configuration of the air: flight condition, wake, turbulence.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WakeFieldConfig {
    /// Airspeed of the TA, U_inf, m/s, (0, 400]. Default 185 (paper).
    pub airspeed_mps: f64,
    /// Altitude for the ISA density, m, [-500, 20000]. Default 6000 (paper).
    pub altitude_m: f64,
    /// The mean wake.
    pub wake: WakeConfig,
    /// The turbulence.
    pub turbulence: TurbulenceConfig,
}

impl Default for WakeFieldConfig {
    fn default() -> Self {
        WakeFieldConfig {
            airspeed_mps: accd_tether::reference::TOWING_AIRSPEED,
            altitude_m: accd_tether::reference::TOWING_ALTITUDE,
            wake: WakeConfig::default(),
            turbulence: TurbulenceConfig::default(),
        }
    }
}

/// The field a config asks for (tables from files or the shared analytic default), with its
/// turbulence drawn from `wake_seed`.
pub fn wake_field(config: &WakeFieldConfig, wake_seed: u64) -> Result<WakeField, SimError> {
    let tables = if config.wake.enabled {
        config.wake.load_tables()?
    } else {
        WakeTables::analytic()
    };
    let air = Atmosphere::isa(config.altitude_m).map_err(|_| {
        SimError::invalid_config("altitude_m", config.altitude_m, "[-500, 20000] m")
    })?;
    let wake = Wake::new(&config.wake, config.airspeed_mps, tables)?;
    let mut turbulence_config = config.turbulence.clone();
    if !config.wake.enabled {
        turbulence_config.wake_turbulence = false;
    }
    let turbulence = Turbulence::new(&turbulence_config, config.airspeed_mps, wake_seed)?;
    Ok(WakeField::from_parts(wake, turbulence, air.density))
}
