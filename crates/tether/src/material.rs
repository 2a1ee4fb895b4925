//! Tether materials of the paper's Table 2, and the rope model that turns a material, a length
//! and a diameter into tether properties.
//!
//! Table 2 gives mass per unit length and breaking tension at a few diameters. For any diameter we
//! interpolate the *areal* quantities `mu / d^2` and `T_max / d^2` linearly in `d` between the
//! table's diameters and hold them constant beyond the ends (both scale with the rope's
//! cross-section, so this is exact for geometrically similar ropes).
//!
//! Stiffness is not in Table 2. We use:
//! * **Axial**: `EA = E_spec * mu`, with the material's specific modulus `E_spec` (m^2/s^2). For
//!   UHMWPE it is derived from Table 3 (k = 157431.5 N/m at L = 250 m, mu = 0.329 kg/m, which gives
//!   1.196e8 m^2/s^2, within 7 % of Dyneema SK75 fibre, 109 GPa / 975 kg/m^3). For Kevlar 29 we take
//!   the fibre value 70.5 GPa / 1440 kg/m^3; for steel wire rope a rope modulus of 100 GPa over the
//!   metallic area, i.e. 100 GPa / 7850 kg/m^3. The last two are assumptions, not paper data.
//! * **Bending**: `EI = beta * EA * d^2 / 16`, a solid rod's `EI` scaled by a rope construction
//!   factor `beta` that is derived from Table 3 (k_t = 170 N m^2 at 24 mm), the same for all
//!   materials (an assumption: real wire ropes differ).
//! * **Damping**: Table 3's per-unit-mass coefficients for every material.

use serde::{Deserialize, Serialize};

use crate::config::TetherConfig;
use crate::error::{Result, TetherError};

/// A tether material of the paper's Table 2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Material {
    /// Ultra-high-molecular-weight polyethylene (Dyneema).
    Uhmwpe,
    /// Aramid (Kevlar 29).
    Kevlar,
    /// Steel wire rope.
    Steel,
}

/// One row of Table 2: diameter (m), mass per length (kg/m), maximum tension (N).
#[derive(Debug, Clone, Copy)]
struct Row {
    diameter: f64,
    mass_per_length: f64,
    max_tension: f64,
}

const fn row(diameter_mm: f64, mass_per_length: f64, max_tension_kn: f64) -> Row {
    Row {
        diameter: diameter_mm * 1e-3,
        mass_per_length,
        max_tension: max_tension_kn * 1e3,
    }
}

/// Table 2 of the paper.
const UHMWPE: [Row; 3] = [
    row(16.0, 0.156, 280.0),
    row(24.0, 0.329, 550.0),
    row(32.0, 0.555, 900.0),
];
const KEVLAR: [Row; 2] = [row(16.0, 0.156, 175.0), row(32.0, 0.555, 578.0)];
const STEEL: [Row; 2] = [row(24.0, 2.34, 375.0), row(32.0, 4.1, 645.0)];

/// Kevlar 29 fibre: Young's modulus (Pa) over density (kg/m^3).
const KEVLAR_SPECIFIC_MODULUS: f64 = 70.5e9 / 1440.0;
/// Steel wire rope: rope modulus over the metallic area (Pa) over steel density (kg/m^3).
const STEEL_SPECIFIC_MODULUS: f64 = 100.0e9 / 7850.0;

impl Material {
    /// All materials, in Table 2's order.
    pub const ALL: [Material; 3] = [Material::Uhmwpe, Material::Kevlar, Material::Steel];

    /// Lower-case name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Material::Uhmwpe => "uhmwpe",
            Material::Kevlar => "kevlar",
            Material::Steel => "steel",
        }
    }

    /// Parse a name as written by [`Material::name`] (case-insensitive).
    pub fn from_name(name: &str) -> Result<Material> {
        Material::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(name))
            .ok_or_else(|| {
                TetherError::invalid_config("material", name, "one of uhmwpe, kevlar, steel")
            })
    }

    fn rows(self) -> &'static [Row] {
        match self {
            Material::Uhmwpe => &UHMWPE,
            Material::Kevlar => &KEVLAR,
            Material::Steel => &STEEL,
        }
    }

    /// Specific axial modulus EA / mu, m^2/s^2 (see the module docs for the sources).
    pub fn specific_modulus(self) -> f64 {
        match self {
            Material::Uhmwpe => {
                let t3 = TetherConfig::table3();
                t3.axial_stiffness * t3.length / t3.mass_per_length
            }
            Material::Kevlar => KEVLAR_SPECIFIC_MODULUS,
            Material::Steel => STEEL_SPECIFIC_MODULUS,
        }
    }

    /// Interpolates `value(row) / d^2` linearly in d, constant beyond the table, times d^2.
    fn areal(self, diameter: f64, value: impl Fn(&Row) -> f64) -> f64 {
        let rows = self.rows();
        let per_area = |r: &Row| value(r) / (r.diameter * r.diameter);
        let first = &rows[0];
        let last = &rows[rows.len() - 1];
        let areal = if diameter <= first.diameter {
            per_area(first)
        } else if diameter >= last.diameter {
            per_area(last)
        } else {
            let i = rows
                .windows(2)
                .position(|w| diameter <= w[1].diameter)
                .unwrap_or(0);
            let (a, b) = (&rows[i], &rows[i + 1]);
            let f = (diameter - a.diameter) / (b.diameter - a.diameter);
            per_area(a) + f * (per_area(b) - per_area(a))
        };
        areal * diameter * diameter
    }

    /// Mass per unit length of a rope of this material and diameter (m), kg/m.
    pub fn mass_per_length(self, diameter: f64) -> f64 {
        self.areal(diameter, |r| r.mass_per_length)
    }

    /// Breaking (maximum allowable) tension of a rope of this material and diameter (m), N.
    pub fn max_tension(self, diameter: f64) -> f64 {
        self.areal(diameter, |r| r.max_tension)
    }

    /// Axial rigidity EA of a rope of this material and diameter (m), N.
    pub fn axial_rigidity(self, diameter: f64) -> f64 {
        self.specific_modulus() * self.mass_per_length(diameter)
    }

    /// Flexural rigidity EI of a rope of this material and diameter (m), N m^2.
    pub fn flexural_rigidity(self, diameter: f64) -> f64 {
        rope_bending_factor() * self.axial_rigidity(diameter) * diameter * diameter / 16.0
    }
}

/// Ratio of a rope's flexural rigidity to that of a solid rod with the same EA and diameter,
/// derived from Table 3 (k_t = 170 N m^2 for the 24 mm UHMWPE tether): about 0.12.
pub fn rope_bending_factor() -> f64 {
    let t3 = TetherConfig::table3();
    let ea = t3.axial_stiffness * t3.length;
    t3.flexural_rigidity / (ea * t3.diameter * t3.diameter / 16.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table2_points_are_reproduced() {
        for m in Material::ALL {
            for r in m.rows() {
                assert!((m.mass_per_length(r.diameter) - r.mass_per_length).abs() < 1e-12);
                assert!((m.max_tension(r.diameter) - r.max_tension).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn uhmwpe_24mm_gives_table3_stiffnesses() {
        let t3 = TetherConfig::table3();
        let k = Material::Uhmwpe.axial_rigidity(0.024) / t3.length;
        assert!((k / t3.axial_stiffness - 1.0).abs() < 1e-12);
        let ei = Material::Uhmwpe.flexural_rigidity(0.024);
        assert!((ei / t3.flexural_rigidity - 1.0).abs() < 1e-12);
    }

    #[test]
    fn interpolation_is_monotonic_in_diameter() {
        for m in Material::ALL {
            let mut last = 0.0;
            for i in 1..100 {
                let d = i as f64 * 0.5e-3;
                let mu = m.mass_per_length(d);
                assert!(mu > last, "{m:?} at {d}");
                last = mu;
            }
        }
    }

    #[test]
    fn names_round_trip() {
        for m in Material::ALL {
            assert_eq!(Material::from_name(m.name()).unwrap(), m);
        }
        assert!(Material::from_name("rubber").is_err());
    }
}
