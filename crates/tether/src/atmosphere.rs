//! International Standard Atmosphere (ISO 2533) up to 20 km: the troposphere (lapse rate
//! -6.5 K/km) and the isothermal lower stratosphere.

use crate::config::STANDARD_GRAVITY;
use crate::error::{Result, TetherError};

/// Sea-level temperature, K.
pub const SEA_LEVEL_TEMPERATURE: f64 = 288.15;
/// Sea-level pressure, Pa.
pub const SEA_LEVEL_PRESSURE: f64 = 101_325.0;
/// Specific gas constant of dry air, J/(kg K).
pub const GAS_CONSTANT: f64 = 287.052_87;
/// Ratio of specific heats of air.
pub const HEAT_CAPACITY_RATIO: f64 = 1.4;
/// Tropospheric temperature lapse rate, K/m.
pub const LAPSE_RATE: f64 = 0.0065;
/// Geopotential altitude of the tropopause, m.
pub const TROPOPAUSE: f64 = 11_000.0;
/// Highest altitude modelled (geometric), m.
pub const CEILING: f64 = 20_000.0;
/// Earth radius used to convert geometric to geopotential altitude, m.
pub const EARTH_RADIUS: f64 = 6_356_766.0;

/// Air properties at one altitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Atmosphere {
    /// Geometric altitude above mean sea level, m.
    pub altitude: f64,
    /// Temperature, K.
    pub temperature: f64,
    /// Static pressure, Pa.
    pub pressure: f64,
    /// Density, kg/m^3.
    pub density: f64,
    /// Speed of sound, m/s.
    pub speed_of_sound: f64,
}

impl Atmosphere {
    /// ISA at geometric `altitude` (m above mean sea level) in [-500, 20000]. At 6000 m this gives
    /// the paper's flight condition: density 0.6601 kg/m^3, speed of sound 316.5 m/s.
    pub fn isa(altitude: f64) -> Result<Atmosphere> {
        if !(altitude.is_finite() && (-500.0..=CEILING).contains(&altitude)) {
            return Err(TetherError::invalid_config(
                "altitude",
                altitude,
                "[-500, 20000] m",
            ));
        }
        let geometric = altitude;
        let altitude = EARTH_RADIUS * geometric / (EARTH_RADIUS + geometric);
        let exponent = STANDARD_GRAVITY / (GAS_CONSTANT * LAPSE_RATE);
        let tropopause_temperature = SEA_LEVEL_TEMPERATURE - LAPSE_RATE * TROPOPAUSE;
        let (temperature, pressure) = if altitude <= TROPOPAUSE {
            let t = SEA_LEVEL_TEMPERATURE - LAPSE_RATE * altitude;
            (
                t,
                SEA_LEVEL_PRESSURE * libm::pow(t / SEA_LEVEL_TEMPERATURE, exponent),
            )
        } else {
            let p11 = SEA_LEVEL_PRESSURE
                * libm::pow(tropopause_temperature / SEA_LEVEL_TEMPERATURE, exponent);
            let decay = libm::exp(
                -STANDARD_GRAVITY * (altitude - TROPOPAUSE)
                    / (GAS_CONSTANT * tropopause_temperature),
            );
            (tropopause_temperature, p11 * decay)
        };
        Ok(Atmosphere {
            altitude: geometric,
            temperature,
            pressure,
            density: pressure / (GAS_CONSTANT * temperature),
            speed_of_sound: (HEAT_CAPACITY_RATIO * GAS_CONSTANT * temperature).sqrt(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference values from the ISA tables by geometric altitude (ICAO Doc 7488).
    #[test]
    fn matches_isa_tables() {
        let cases = [
            (0.0, 1.2250, 340.29),
            (6000.0, 0.66011, 316.45),
            (11_000.0, 0.36480, 295.15),
            (15_000.0, 0.19475, 295.07),
        ];
        for (h, rho, a) in cases {
            let atm = Atmosphere::isa(h).unwrap();
            assert!(
                (atm.density / rho - 1.0).abs() < 2e-4,
                "rho at {h}: {}",
                atm.density
            );
            assert!(
                (atm.speed_of_sound / a - 1.0).abs() < 1e-4,
                "a at {h}: {}",
                atm.speed_of_sound
            );
        }
        assert!(Atmosphere::isa(30_000.0)
            .unwrap_err()
            .to_string()
            .contains("altitude"));
    }
}
