//! The towing aircraft's (TA) wake: mean velocity perturbation and turbulent kinetic energy from
//! look-up tables over position behind the TA (paper section 2.2).
//!
//! # Tables
//!
//! A [`WakeTable`] holds, for one TA angle of attack, four fields on a rectilinear grid over
//! position in units of the TA length `L` (`length_scale_m`, 70 m by default):
//!
//! * `x_over_l` = x / L, measured from the TA's **nose**, forward positive, so behind the TA
//!   x / L < 0 (as in the paper's Fig. 7);
//! * `y_over_l` = y / L, starboard positive, from the fuselage plane;
//! * `z_over_l` = z / L, **down** positive, from the fuselage axis.
//!
//! The fields are dimensionless:
//!
//! * `u`, `v`, `w`: the mean perturbation of the air velocity **in the TA frame** (x forward,
//!   y starboard, z down) as fractions of the free-stream speed `U_inf`. The air velocity in the
//!   TA frame is `U_inf * (-1 + u, v, w)`. A streamwise velocity deficit (air dragged along with
//!   the TA) is therefore `u > 0`; downwash (air moving down) is `w > 0`. From a CFD solution that
//!   gives the air velocity `V` relative to the aircraft in the TA frame:
//!   `u = 1 + V_x / U_inf`, `v = V_y / U_inf`, `w = V_z / U_inf`.
//! * `k`: the turbulent kinetic energy as a fraction of `U_inf^2`. The RMS velocity fluctuation
//!   per component is `u' = sqrt(2 k / 3)` (paper Eq. 1, isotropic turbulence).
//!
//! Inside the grid the fields are interpolated trilinearly; outside it (on any axis) the air is
//! free stream: zero perturbation and `k = 0`. A table should therefore decay to zero at its
//! edges, or the field jumps there.
//!
//! # File format
//!
//! JSON ([`WakeTableData`], read by [`WakeTable::from_json_str`] / [`WakeTable::from_file`],
//! written by [`WakeTable::to_json_string`]):
//!
//! ```json
//! {
//!   "description": "free text: source of the data",
//!   "alpha_deg": 8.0,
//!   "length_scale_m": 70.0,
//!   "x_over_l": [-8.0, -7.875, ..., 0.0],
//!   "y_over_l": [-2.0, ..., 2.0],
//!   "z_over_l": [-2.0, ..., 2.0],
//!   "u": [...], "v": [...], "w": [...], "k": [...]
//! }
//! ```
//!
//! The axes must be strictly increasing with at least 2 points each. Each field is a **flat**
//! array of `nx * ny * nz` finite numbers in row-major order with `z` fastest: the value at
//! `(x_over_l[i], y_over_l[j], z_over_l[l])` is at index `(i * ny + j) * nz + l`. This is numpy's
//! C order: `field.ravel()` of an array of shape `(nx, ny, nz)`. `description` is optional.
//! Unknown keys are rejected.
//!
//! # The wake of one flight: [`Wake`]
//!
//! A [`Wake`] holds a table pair ([`WakeTables`], at 0 deg and 8 deg by default) and interpolates
//! linearly in the TA angle of attack between them; it converts a position in the TA frame
//! (origin at the tether attachment) into table coordinates with the attachment's position
//! relative to the nose ([`WakeConfig::attachment_from_nose_m`]; **assumption**: by default the
//! attachment is on the fuselage axis 60 m behind the nose, near the tail of a 70 m aircraft) and
//! scales the result by `U_inf`.
//!
//! # Default tables: an analytic model
//!
//! The paper's CFD tables are not public. [`AnalyticWake`] builds tables with the features the
//! paper states (section 2.2, Fig. 7). With `xi = -x / L` (distance behind the nose in TA
//! lengths), `eta = y / L`, `zeta = z / L`:
//!
//! * growth along the fuselage: `r(xi) = 1 - exp(-xi / 0.5)` (0 at the nose, 0.82 at the
//!   attachment, 0.98 one length behind the tail);
//! * cosine bump `c(s) = cos^2(pi s / 2)` for `|s| < 1`, else 0 (compact support);
//! * **streamwise deficit**, confined to `|zeta| <= 0.25` (and `|eta| <= 0.5`), decaying
//!   downstream: `u = a_u r(xi) / (1 + max(xi - 1, 0) / xi_u) * c(zeta / 0.25) * c(eta / 0.5)`,
//!   with `xi_u = 1`, `a_u = 0.15` at 8 deg and `0.12` at 0 deg: on the axis 13 % at the tail
//!   (one length behind the nose), falling to 3.3 % at 315 m and 1.9 % at 560 m (8 deg);
//! * **downwash**, wide (`|zeta| > 0.5`) and persistent:
//!   `w = W * g(xi) / g(4.5) * exp(-(zeta / 0.75)^2) * exp(-(eta / 0.6)^2)`,
//!   `g(xi) = r(xi) / (1 + xi / 20)`, so that `w = W` exactly at 315 m (xi = 4.5) on the axis,
//!   with `W = 0.08` at 8 deg (the paper: about 8 % of `U_inf` at 315 m) and `W = 0.015` at 0 deg
//!   (our choice: the paper shows a much weaker downwash at 0 deg; a cruise lift coefficient about
//!   a fifth of the 8 deg one). At `|zeta| = 0.5` the downwash is still 64 % of its axis value,
//!   at `|zeta| = 1` 17 %; at 560 m it has decayed only to 7.0 % (8 deg); at the settled ACCD
//!   (about 300 m behind the nose, 50 m below the axis) it is 3.3 % (6 m/s);
//! * **turbulent kinetic energy**, peaked in the wake and decaying downstream:
//!   `k = 1.5 I(xi)^2 * exp(-(zeta / h(xi))^2 - (eta / b(xi))^2)` with the turbulence intensity
//!   `I(xi) = I_0 r(xi) / sqrt(1 + max(xi - 1, 0) / 1.5)`, `h = 0.35 + 0.05 xi`,
//!   `b = 0.6 + 0.05 xi`, and `I_0 = 0.04` at 8 deg, `0.03` at 0 deg. On the axis this gives
//!   `u' / U_inf = I`: 3.5 % (6.4 m/s) one length behind the nose, 2.2 % (4.1 m/s) at 315 m,
//!   1.7 % (3.1 m/s) at 560 m (8 deg); at the settled ACCD (about 300 m behind the nose, 50 m
//!   below the axis) about 1 % (1.9 m/s).
//! * no mean sidewash: `v = 0` (the wake is symmetric about the fuselage plane; CFD tables can
//!   supply `v`).
//!
//! The default grid covers `x / L` in [-8, 0] (560 m behind the nose), `y / L` and `z / L` in
//! [-2, 2], all at a spacing of 0.125 (65 x 33 x 33 points). The default tables are built once
//! per process and shared ([`WakeTables::analytic`]).

use std::path::Path;
use std::sync::{Arc, OnceLock};

use accd_spec::Fields;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Result, SimError};
use crate::physics::interp::{Axis, Edge, Grid};

/// Length of the towing aircraft L, m (paper section 2.2).
pub const TA_LENGTH_M: f64 = 70.0;

/// Default position of the tether attachment relative to the TA's nose in the TA frame, m:
/// on the fuselage axis, 60 m behind the nose (an assumption; the paper gives no value).
pub const DEFAULT_ATTACHMENT_FROM_NOSE_M: [f64; 3] = [-60.0, 0.0, 0.0];

/// Distance behind the nose at which the paper quotes the downwash, m.
pub const DOWNWASH_REFERENCE_DISTANCE_M: f64 = 315.0;

/// The file format of one wake table: what [`WakeTable::from_json_str`] reads and
/// [`WakeTable::to_json_string`] writes. See the [module docs](self) for the conventions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WakeTableData {
    /// Free text: where the data come from. Optional.
    #[serde(default)]
    pub description: String,
    /// TA angle of attack of this table, deg.
    pub alpha_deg: f64,
    /// The length L that scales the axes (the TA length), m.
    pub length_scale_m: f64,
    /// x / L from the nose, forward positive (negative behind the TA); strictly increasing.
    pub x_over_l: Vec<f64>,
    /// y / L, starboard positive; strictly increasing.
    pub y_over_l: Vec<f64>,
    /// z / L, down positive; strictly increasing.
    pub z_over_l: Vec<f64>,
    /// Streamwise perturbation (deficit > 0), fraction of U_inf; flat, index (i ny + j) nz + l.
    pub u: Vec<f64>,
    /// Lateral perturbation (to starboard > 0), fraction of U_inf; same layout.
    pub v: Vec<f64>,
    /// Vertical perturbation (downwash > 0), fraction of U_inf; same layout.
    pub w: Vec<f64>,
    /// Turbulent kinetic energy, fraction of U_inf^2, >= 0; same layout.
    pub k: Vec<f64>,
}

/// One validated wake table (one TA angle of attack). See the [module docs](self) for the
/// conventions and the file format.
#[derive(Debug, Clone, PartialEq)]
pub struct WakeTable {
    data: WakeTableData,
    grid: Grid,
}

fn check_axis(table: &str, name: &str, values: &[f64]) -> Result<()> {
    if values.len() < 2 {
        return Err(SimError::invalid_table(
            table,
            format!(
                "axis `{name}` has {} point(s), at least 2 are needed",
                values.len()
            ),
        ));
    }
    for (i, &v) in values.iter().enumerate() {
        if !v.is_finite() {
            return Err(SimError::invalid_table(
                table,
                format!("axis `{name}` has a non-finite value {v} at index {i}"),
            ));
        }
        if i > 0 && v <= values[i - 1] {
            return Err(SimError::invalid_table(
                table,
                format!(
                    "axis `{name}` is not strictly increasing at index {i}: {} then {v}",
                    values[i - 1]
                ),
            ));
        }
    }
    Ok(())
}

impl WakeTable {
    /// Validates `data` under the name `"wake table"` in error messages.
    pub fn new(data: WakeTableData) -> Result<WakeTable> {
        WakeTable::named(data, "wake table")
    }

    /// Validates `data`; `table` names it (e.g. the file) in error messages.
    ///
    /// Errors ([`SimError::InvalidTable`]): an axis with fewer than 2 points, a non-finite or
    /// non-increasing axis value (axis and index named), a field whose length is not
    /// `nx * ny * nz` (field, expected and found named), a non-finite field value or a negative
    /// `k` (field and index named), a non-finite angle or a non-positive length scale.
    pub fn named(data: WakeTableData, table: &str) -> Result<WakeTable> {
        if !data.alpha_deg.is_finite() || data.alpha_deg.abs() > 90.0 {
            return Err(SimError::invalid_table(
                table,
                format!("`alpha_deg` = {} is outside [-90, 90] deg", data.alpha_deg),
            ));
        }
        if !(data.length_scale_m.is_finite() && data.length_scale_m > 0.0) {
            return Err(SimError::invalid_table(
                table,
                format!(
                    "`length_scale_m` = {} must be finite and > 0 m",
                    data.length_scale_m
                ),
            ));
        }
        check_axis(table, "x_over_l", &data.x_over_l)?;
        check_axis(table, "y_over_l", &data.y_over_l)?;
        check_axis(table, "z_over_l", &data.z_over_l)?;
        let (nx, ny, nz) = (
            data.x_over_l.len(),
            data.y_over_l.len(),
            data.z_over_l.len(),
        );
        let expected = nx * ny * nz;
        for (name, field) in [
            ("u", &data.u),
            ("v", &data.v),
            ("w", &data.w),
            ("k", &data.k),
        ] {
            if field.len() != expected {
                return Err(SimError::invalid_table(
                    table,
                    format!(
                        "array `{name}` has {} values, expected nx * ny * nz = {nx} * {ny} * {nz} = {expected}",
                        field.len()
                    ),
                ));
            }
            if let Some(i) = field.iter().position(|v| !v.is_finite()) {
                return Err(SimError::invalid_table(
                    table,
                    format!(
                        "array `{name}` has a non-finite value {} at index {i} (ix {}, iy {}, iz {})",
                        field[i],
                        i / (ny * nz),
                        (i / nz) % ny,
                        i % nz
                    ),
                ));
            }
        }
        if let Some(i) = data.k.iter().position(|&v| v < 0.0) {
            return Err(SimError::invalid_table(
                table,
                format!("array `k` has a negative value {} at index {i}", data.k[i]),
            ));
        }
        let grid = Grid {
            x: Axis::new(data.x_over_l.clone()),
            y: Axis::new(data.y_over_l.clone()),
            z: Axis::new(data.z_over_l.clone()),
        };
        Ok(WakeTable { data, grid })
    }

    /// Parses and validates a JSON table (format in the [module docs](self)).
    pub fn from_json_str(text: &str) -> Result<WakeTable> {
        let data: WakeTableData = serde_json::from_str(text)
            .map_err(|e| SimError::invalid_table("wake table", format!("bad JSON: {e}")))?;
        WakeTable::new(data)
    }

    /// Reads, parses and validates a JSON table file, named by the configuration field `field`
    /// (`wake.tables.low`) in the errors. Errors: [`SimError::InvalidConfig`] when the path is
    /// not a regular file of at most [`crate::table_file::MAX_TABLE_FILE_BYTES`],
    /// [`SimError::Io`] when the file cannot be read, [`SimError::InvalidTable`] (named by the
    /// path) when its content is bad.
    pub fn from_file(path: impl AsRef<Path>, field: &str) -> Result<WakeTable> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let text = crate::table_file::read_table_file(path, field)?;
        let data: WakeTableData = serde_json::from_str(&text)
            .map_err(|e| SimError::invalid_table(&name, format!("bad JSON: {e}")))?;
        WakeTable::named(data, &name)
    }

    /// The table as JSON (format in the [module docs](self)); reading it back gives an identical
    /// table.
    pub fn to_json_string(&self) -> String {
        serde_json::to_string(&self.data).expect("a validated table serializes")
    }

    /// The table's data (axes and fields).
    pub fn data(&self) -> &WakeTableData {
        &self.data
    }

    /// TA angle of attack of this table, deg.
    pub fn alpha_deg(&self) -> f64 {
        self.data.alpha_deg
    }

    /// The length scale L of the axes, m.
    pub fn length_scale_m(&self) -> f64 {
        self.data.length_scale_m
    }

    /// `[u, v, w, k]` (fractions of U_inf and U_inf^2) at table coordinates
    /// `(x / L, y / L, z / L)`, trilinearly interpolated; all zero outside the grid.
    pub fn sample(&self, x_over_l: f64, y_over_l: f64, z_over_l: f64) -> [f64; 4] {
        let mut out = [0.0; 4];
        if let Some(s) = self
            .grid
            .stencil([x_over_l, y_over_l, z_over_l], Edge::Zero)
        {
            let d = &self.data;
            for c in 0..8 {
                let idx = s.base + s.offsets[c];
                let wgt = s.weights[c];
                out[0] += wgt * d.u[idx];
                out[1] += wgt * d.v[idx];
                out[2] += wgt * d.w[idx];
                out[3] += wgt * d.k[idx];
            }
        }
        out
    }
}

/// The analytic wake model behind the default tables (formulas in the [module docs](self)).
/// All lengths in units of the TA length L; amplitudes as fractions of U_inf.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnalyticWake {
    /// TA angle of attack, deg.
    pub alpha_deg: f64,
    /// Length scale L, m.
    pub length_scale_m: f64,
    /// e-folding length of the growth r(xi) = 1 - exp(-xi / growth) along the fuselage, L.
    pub growth_l: f64,
    /// Streamwise deficit a_u on the axis before its decay starts (one L behind the nose).
    pub deficit_peak: f64,
    /// Decay length xi_u of the deficit behind the tail: a_u / (1 + (xi - 1) / xi_u), L.
    pub deficit_decay_l: f64,
    /// Vertical half-height of the deficit (zero beyond), L. 0.25 (paper Fig. 7).
    pub deficit_half_height_l: f64,
    /// Lateral half-width of the deficit (zero beyond), L.
    pub deficit_half_width_l: f64,
    /// Downwash W on the axis at 315 m behind the nose, fraction of U_inf.
    pub downwash_at_315m: f64,
    /// Decay length of the downwash, g(xi) = r(xi) / (1 + xi / decay), L.
    pub downwash_decay_l: f64,
    /// Vertical e-folding half-height of the downwash Gaussian, L.
    pub downwash_half_height_l: f64,
    /// Lateral e-folding half-width of the downwash Gaussian, L.
    pub downwash_half_width_l: f64,
    /// Peak turbulence intensity I_0 = u' / U_inf (before growth and decay).
    pub intensity_peak: f64,
    /// Decay length of the intensity behind the tail, I_0 / sqrt(1 + (xi - 1) / decay), L.
    pub intensity_decay_l: f64,
    /// Vertical e-folding half-height of k at the nose, L; grows by `tke_spread` per L.
    pub tke_half_height_l: f64,
    /// Lateral e-folding half-width of k at the nose, L; grows by `tke_spread` per L.
    pub tke_half_width_l: f64,
    /// Growth of the half-height and half-width of k per unit distance behind the nose.
    pub tke_spread: f64,
}

/// `x^2`.
fn square(x: f64) -> f64 {
    x * x
}

/// `cos^2(pi s / 2)` on |s| < 1, else 0.
fn bump(s: f64) -> f64 {
    if s.abs() < 1.0 {
        let c = libm::cos(0.5 * std::f64::consts::PI * s);
        c * c
    } else {
        0.0
    }
}

/// Default table axis: `min, min + step, ..., max`.
fn uniform_axis(min: f64, max: f64, step: f64) -> Vec<f64> {
    let n = ((max - min) / step).round() as usize + 1;
    (0..n).map(|i| min + i as f64 * step).collect()
}

impl AnalyticWake {
    /// The 0 deg (cruise) model: deficit 12 %, downwash 1.5 % at 315 m, peak intensity 3 %.
    pub fn alpha_0() -> AnalyticWake {
        AnalyticWake {
            alpha_deg: 0.0,
            deficit_peak: 0.12,
            downwash_at_315m: 0.015,
            intensity_peak: 0.03,
            ..AnalyticWake::alpha_8()
        }
    }

    /// The 8 deg model: deficit 15 %, downwash 8 % at 315 m (paper), peak intensity 4 %.
    pub fn alpha_8() -> AnalyticWake {
        AnalyticWake {
            alpha_deg: 8.0,
            length_scale_m: TA_LENGTH_M,
            growth_l: 0.5,
            deficit_peak: 0.15,
            deficit_decay_l: 1.0,
            deficit_half_height_l: 0.25,
            deficit_half_width_l: 0.5,
            downwash_at_315m: 0.08,
            downwash_decay_l: 20.0,
            downwash_half_height_l: 0.75,
            downwash_half_width_l: 0.6,
            intensity_peak: 0.04,
            intensity_decay_l: 1.5,
            tke_half_height_l: 0.35,
            tke_half_width_l: 0.6,
            tke_spread: 0.05,
        }
    }

    /// `[u, v, w, k]` at `(x / L, y / L, z / L)` (x from the nose, negative behind), exactly
    /// (no table). Zero ahead of the nose.
    pub fn value(&self, x_over_l: f64, y_over_l: f64, z_over_l: f64) -> [f64; 4] {
        let xi = -x_over_l;
        if xi <= 0.0 {
            return [0.0; 4];
        }
        let (eta, zeta) = (y_over_l, z_over_l);
        let growth = |xi: f64| 1.0 - libm::exp(-xi / self.growth_l);
        let r = growth(xi);
        let behind_tail = (xi - 1.0).max(0.0);
        let u = self.deficit_peak * r / (1.0 + behind_tail / self.deficit_decay_l)
            * bump(zeta / self.deficit_half_height_l)
            * bump(eta / self.deficit_half_width_l);
        let xi_ref = DOWNWASH_REFERENCE_DISTANCE_M / self.length_scale_m;
        let g = |xi: f64| growth(xi) / (1.0 + xi / self.downwash_decay_l);
        let w = self.downwash_at_315m * g(xi) / g(xi_ref)
            * libm::exp(-square(zeta / self.downwash_half_height_l))
            * libm::exp(-square(eta / self.downwash_half_width_l));
        let intensity =
            self.intensity_peak * r / (1.0 + behind_tail / self.intensity_decay_l).sqrt();
        let h = self.tke_half_height_l + self.tke_spread * xi;
        let b = self.tke_half_width_l + self.tke_spread * xi;
        let k = 1.5 * intensity * intensity * libm::exp(-square(zeta / h) - square(eta / b));
        [u, 0.0, w, k]
    }

    /// The model tabulated on the given axes (in units of L; validated as a file would be).
    pub fn table_on(
        &self,
        x_over_l: &[f64],
        y_over_l: &[f64],
        z_over_l: &[f64],
    ) -> Result<WakeTable> {
        let n = x_over_l.len() * y_over_l.len() * z_over_l.len();
        let mut fields = [
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        ];
        for &x in x_over_l {
            for &y in y_over_l {
                for &z in z_over_l {
                    let value = self.value(x, y, z);
                    for (field, v) in fields.iter_mut().zip(value) {
                        field.push(v);
                    }
                }
            }
        }
        let [u, v, w, k] = fields;
        WakeTable::named(
            WakeTableData {
                description: format!(
                    "accd-sim analytic wake model (AnalyticWake), TA angle of attack {} deg",
                    self.alpha_deg
                ),
                alpha_deg: self.alpha_deg,
                length_scale_m: self.length_scale_m,
                x_over_l: x_over_l.to_vec(),
                y_over_l: y_over_l.to_vec(),
                z_over_l: z_over_l.to_vec(),
                u,
                v,
                w,
                k,
            },
            "analytic wake",
        )
    }

    /// The model on the default grid: x / L in [-8, 0], y / L and z / L in [-2, 2], step 0.125.
    pub fn table(&self) -> WakeTable {
        let x = uniform_axis(-8.0, 0.0, 0.125);
        let yz = uniform_axis(-2.0, 2.0, 0.125);
        self.table_on(&x, &yz, &yz)
            .expect("the analytic model gives a valid table")
    }
}

/// Two wake tables on the same grid at two TA angles of attack (0 and 8 deg by default), stored
/// interleaved for one-pass interpolation and shared (cheap to clone) between wakes.
#[derive(Debug, Clone)]
pub struct WakeTables {
    inner: Arc<TablePair>,
}

#[derive(Debug)]
struct TablePair {
    low: WakeTable,
    high: WakeTable,
    /// Per node: low u, v, w, k, high u, v, w, k.
    nodes: Vec<[f64; 8]>,
}

impl WakeTables {
    /// Pairs two tables. Errors ([`SimError::InvalidTable`]): `low.alpha_deg >= high.alpha_deg`,
    /// different length scales, or different axes (the axis and index named).
    pub fn new(low: WakeTable, high: WakeTable) -> Result<WakeTables> {
        let name = "wake table pair";
        if low.alpha_deg() >= high.alpha_deg() {
            return Err(SimError::invalid_table(
                name,
                format!(
                    "the low table's alpha_deg {} must be below the high table's {}",
                    low.alpha_deg(),
                    high.alpha_deg()
                ),
            ));
        }
        if low.length_scale_m() != high.length_scale_m() {
            return Err(SimError::invalid_table(
                name,
                format!(
                    "the tables' length_scale_m differ: {} and {}",
                    low.length_scale_m(),
                    high.length_scale_m()
                ),
            ));
        }
        for (axis, a, b) in [
            ("x_over_l", &low.data.x_over_l, &high.data.x_over_l),
            ("y_over_l", &low.data.y_over_l, &high.data.y_over_l),
            ("z_over_l", &low.data.z_over_l, &high.data.z_over_l),
        ] {
            if a.len() != b.len() {
                return Err(SimError::invalid_table(
                    name,
                    format!(
                        "the tables must share their axes: `{axis}` has {} and {} points",
                        a.len(),
                        b.len()
                    ),
                ));
            }
            if let Some(i) = a.iter().zip(b.iter()).position(|(x, y)| x != y) {
                return Err(SimError::invalid_table(
                    name,
                    format!(
                        "the tables must share their axes: `{axis}` differs at index {i}: {} and {}",
                        a[i], b[i]
                    ),
                ));
            }
        }
        let nodes = (0..low.grid.len())
            .map(|i| {
                let (l, h) = (&low.data, &high.data);
                [
                    l.u[i], l.v[i], l.w[i], l.k[i], h.u[i], h.v[i], h.w[i], h.k[i],
                ]
            })
            .collect();
        Ok(WakeTables {
            inner: Arc::new(TablePair { low, high, nodes }),
        })
    }

    /// The analytic default pair ([`AnalyticWake::alpha_0`], [`AnalyticWake::alpha_8`] on the
    /// default grid), built once per process and shared.
    pub fn analytic() -> WakeTables {
        static TABLES: OnceLock<WakeTables> = OnceLock::new();
        TABLES
            .get_or_init(|| {
                WakeTables::new(
                    AnalyticWake::alpha_0().table(),
                    AnalyticWake::alpha_8().table(),
                )
                .expect("the analytic tables pair")
            })
            .clone()
    }

    /// Loads a pair from two JSON files (low angle first), named `wake.tables.low` and
    /// `wake.tables.high` in the errors ([`WakeTable::from_file`]).
    pub fn from_files(low: impl AsRef<Path>, high: impl AsRef<Path>) -> Result<WakeTables> {
        WakeTables::new(
            WakeTable::from_file(low, "wake.tables.low")?,
            WakeTable::from_file(high, "wake.tables.high")?,
        )
    }

    /// The table at the lower angle of attack.
    pub fn low(&self) -> &WakeTable {
        &self.inner.low
    }

    /// The table at the higher angle of attack.
    pub fn high(&self) -> &WakeTable {
        &self.inner.high
    }
}

/// Paths of a user-supplied table pair (JSON files, format in the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WakeTableFiles {
    /// The table at the lower angle of attack (0 deg for the default pair).
    pub low: String,
    /// The table at the higher angle of attack (8 deg for the default pair).
    pub high: String,
}

/// Where the tether's segments sample the air disturbance (mean wake and turbulence) during a
/// physics step. The capturing device samples it at every RK4 stage in both schemes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AirSampling {
    /// At every RK4 stage, at the stage's segment centres (4 samples per segment and step): the
    /// exact scheme for a field that is frozen over the step.
    PerStage,
    /// Once per step, at the segment centres of the step's initial state, held over its four
    /// stages (a first-order error in the forcing: the segments move by millimetres in a step).
    #[default]
    PerStep,
}

accd_spec::config_struct! {
    /// Configuration of the mean wake.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct WakeConfig {
        /// When false the air is free stream (and there is no wake turbulence, k = 0).
        pub enabled: bool = true, "", "", "whether there is a wake at all";
        /// 8 is the paper's high-angle-of-attack case, the hardest. Checked against the tables'
        /// angles by [`Wake::new`].
        pub alpha_deg: f64 = 8.0, "deg", "",
            "TA angle of attack, within the angles of the table pair ([0, 8] for the default tables)";
        /// In the TA frame (x forward, y starboard, z down); the default, on the fuselage axis
        /// 60 m behind the nose, is an assumption.
        pub attachment_from_nose_m: [f64; 3] = DEFAULT_ATTACHMENT_FROM_NOSE_M, "m", "[-1000, 1000]",
            "position of the tether attachment (the TA frame's origin) relative to the TA's nose";
        pub tables: Option<WakeTableFiles> = None, "", "",
            "user wake tables, {\"low\": path, \"high\": path}, regular files of at most 64 MiB each (None: the analytic model)";
        /// `"per_step"` is the default since the fast scheme's measurement (BENCHMARKS.md);
        /// `"per_stage"` is the exact scheme of the first releases.
        /// Scales the mean wake's velocity perturbation by the factor and its turbulent kinetic
        /// energy by its square (the wake turbulence's RMS velocities by the factor): a weaker or
        /// stronger wake of the same shape, for robustness studies and randomized physics.
        pub strength: f64 = 1.0, "-", "[0, 5]",
            "factor on the mean wake's velocity perturbation (its turbulent kinetic energy scales with the square)";
        pub sampling: AirSampling = AirSampling::PerStep, "", "",
            "where the tether's segments sample the wake and its turbulence: \"per_step\" or \"per_stage\" (the exact scheme)";
    }
}

accd_spec::no_range!(WakeTableFiles, AirSampling);

/// Each field's range is all there is to check here (the angle is checked against the tables
/// when they are loaded).
impl accd_spec::Rules for WakeConfig {}

impl WakeConfig {
    /// Checks the values against their declared ranges (the angle is checked against the tables
    /// by [`Wake::new`]). Errors name the field as `wake.<field>`.
    pub fn validate(&self) -> Result<()> {
        Ok(self.check_fields("wake")?)
    }

    /// The table pair this config asks for: the files, or the shared analytic default.
    pub fn load_tables(&self) -> Result<WakeTables> {
        match &self.tables {
            Some(files) => WakeTables::from_files(&files.low, &files.high),
            None => Ok(WakeTables::analytic()),
        }
    }
}

/// The wake at one point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WakeSample {
    /// Mean perturbation of the air velocity in the TA frame, m/s (the air velocity is
    /// `(-U_inf, 0, 0) + velocity`; deficit +x, downwash +z).
    pub velocity: Vector3<f64>,
    /// Turbulent kinetic energy, m^2/s^2.
    pub tke: f64,
}

/// The mean wake of one flight: a table pair, the TA angle of attack, the airspeed and the
/// attachment's position relative to the nose. Cheap to clone (the tables are shared).
#[derive(Debug, Clone)]
pub struct Wake {
    tables: Option<WakeTables>,
    alpha_deg: f64,
    /// Interpolation weight of the high table, (alpha - alpha_low) / (alpha_high - alpha_low).
    high_weight: f64,
    airspeed: f64,
    /// The speed the tables' dimensionless values are scaled by: airspeed times `wake.strength`.
    perturbation_speed: f64,
    length: f64,
    inv_length: f64,
    attachment_from_nose: Vector3<f64>,
}

impl Wake {
    /// A wake with the given table pair at `airspeed_mps` (U_inf, m/s, (0, 400]).
    ///
    /// Errors ([`SimError::InvalidConfig`]): `wake.alpha_deg` outside the pair's angles,
    /// an attachment offset outside [-1000, 1000] m, `airspeed_mps` outside (0, 400].
    pub fn new(config: &WakeConfig, airspeed_mps: f64, tables: WakeTables) -> Result<Wake> {
        config.validate()?;
        crate::physics::aircraft::check_airspeed("airspeed_mps", airspeed_mps)?;
        let (lo, hi) = (tables.low().alpha_deg(), tables.high().alpha_deg());
        if !(config.alpha_deg >= lo && config.alpha_deg <= hi) {
            return Err(SimError::invalid_config(
                "wake.alpha_deg",
                config.alpha_deg,
                &format!("[{lo}, {hi}] deg (the angles of the wake tables)"),
            ));
        }
        let length = tables.low().length_scale_m();
        let a = config.attachment_from_nose_m;
        Ok(Wake {
            high_weight: (config.alpha_deg - lo) / (hi - lo),
            alpha_deg: config.alpha_deg,
            tables: config.enabled.then_some(tables),
            airspeed: airspeed_mps,
            perturbation_speed: airspeed_mps * config.strength,
            length,
            inv_length: 1.0 / length,
            attachment_from_nose: Vector3::new(a[0], a[1], a[2]),
        })
    }

    /// The wake a config asks for (its tables loaded, or the shared analytic default).
    pub fn from_config(config: &WakeConfig, airspeed_mps: f64) -> Result<Wake> {
        let tables = if config.enabled {
            config.load_tables()?
        } else {
            WakeTables::analytic()
        };
        Wake::new(config, airspeed_mps, tables)
    }

    /// Free stream everywhere (no perturbation, k = 0).
    pub fn none(airspeed_mps: f64) -> Result<Wake> {
        let config = WakeConfig {
            enabled: false,
            ..WakeConfig::default()
        };
        Wake::new(&config, airspeed_mps, WakeTables::analytic())
    }

    /// Whether the wake is on.
    pub fn enabled(&self) -> bool {
        self.tables.is_some()
    }

    /// TA angle of attack, deg.
    pub fn alpha_deg(&self) -> f64 {
        self.alpha_deg
    }

    /// Free-stream speed U_inf, m/s.
    pub fn airspeed(&self) -> f64 {
        self.airspeed
    }

    /// The tables' length scale L, m.
    pub fn length(&self) -> f64 {
        self.length
    }

    /// Attachment position relative to the nose, TA frame, m.
    pub fn attachment_from_nose(&self) -> Vector3<f64> {
        self.attachment_from_nose
    }

    /// The table pair (`None` when the wake is off).
    pub fn tables(&self) -> Option<&WakeTables> {
        self.tables.as_ref()
    }

    /// Table coordinates `(x / L, y / L, z / L)` from the nose of a point `p` in the TA frame, m.
    pub fn table_coordinates(&self, p: &Vector3<f64>) -> [f64; 3] {
        let q = (p + self.attachment_from_nose) * self.inv_length;
        [q.x, q.y, q.z]
    }

    /// The mean perturbation (m/s) and turbulent kinetic energy (m^2/s^2) at `p` (TA frame, m):
    /// one trilinear look-up in the shared interleaved pair, blended linearly in the angle of
    /// attack. Free stream outside the tables. Allocates nothing.
    #[inline(always)]
    pub fn sample(&self, p: &Vector3<f64>) -> WakeSample {
        let Some(tables) = &self.tables else {
            return WakeSample::default();
        };
        let pair = &*tables.inner;
        let Some(s) = pair.low.grid.stencil(self.table_coordinates(p), Edge::Zero) else {
            return WakeSample::default();
        };
        // The corners come in pairs adjacent along z (offsets 2k and 2k + 1 differ by one).
        let mut acc = [0.0; 8];
        for k in 0..4 {
            let pair_nodes = &pair.nodes[s.base + s.offsets[2 * k]..][..2];
            for (node, wgt) in pair_nodes.iter().zip(&s.weights[2 * k..2 * k + 2]) {
                for (a, v) in acc.iter_mut().zip(node) {
                    *a += wgt * v;
                }
            }
        }
        let h = self.high_weight;
        let mix = |i: usize| acc[i] + h * (acc[i + 4] - acc[i]);
        let u = self.perturbation_speed;
        WakeSample {
            velocity: Vector3::new(mix(0), mix(1), mix(2)) * u,
            tke: mix(3).max(0.0) * u * u,
        }
    }
}
