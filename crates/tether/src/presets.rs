//! Named tethers: the paper's Table 1 and Table 3 cases, and a tether of any Table 2 material,
//! length and diameter ([`TetherConfig::preset`], [`TetherConfig::from_material`]).

use accd_spec::Fields;

use crate::config::TetherConfig;
use crate::error::{Result, TetherError};
use crate::material::Material;

impl TetherConfig {
    /// A tether of Table 2's `material` with the given `length` (m) and `diameter` (m), discretised
    /// into Table 3's 30 segments, with Table 3's damping and drag (see [`crate::material`] for
    /// how stiffness and mass follow from material and diameter).
    pub fn from_material(material: Material, length: f64, diameter: f64) -> Result<Self> {
        // Checked before the material's formulas use them (the message names these inputs).
        for (name, value) in [("length", length), ("diameter", diameter)] {
            if let Some(spec) = Self::field(name) {
                accd_spec::check_number(name, value, spec)?;
            }
        }
        let config = TetherConfig {
            length,
            diameter,
            mass_per_length: material.mass_per_length(diameter),
            axial_stiffness: material.axial_rigidity(diameter) / length,
            flexural_rigidity: material.flexural_rigidity(diameter),
            breaking_tension: material.max_tension(diameter),
            ..TetherConfig::table3()
        };
        config.validate()?;
        Ok(config)
    }

    /// Looks up a preset by name: `table1`, `table3`, or `<material>-<length m>m-<diameter mm>mm`
    /// such as `steel-250m-24mm`.
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "table1" => return Ok(Self::table1()),
            "table3" => return Ok(Self::table3()),
            _ => {}
        }
        let bad = || {
            TetherError::invalid_config(
                "preset",
                name,
                "table1, table3, or <uhmwpe|kevlar|steel>-<L>m-<d>mm (e.g. uhmwpe-300m-24mm)",
            )
        };
        let parts: Vec<&str> = name.split('-').collect();
        let [material, length, diameter] = parts.as_slice() else {
            return Err(bad());
        };
        let material = Material::from_name(material).map_err(|_| bad())?;
        let length: f64 = length
            .strip_suffix('m')
            .and_then(|v| v.parse().ok())
            .ok_or_else(bad)?;
        let diameter_mm: f64 = diameter
            .strip_suffix("mm")
            .and_then(|v| v.parse().ok())
            .ok_or_else(bad)?;
        Self::from_material(material, length, diameter_mm * 1e-3)
    }
}
