//! Aerodynamic coefficients of the ACCD as look-up tables over angle of attack, sideslip and the
//! four flap deflections, in a documented file format that users can fill from their own CFD (the
//! paper uses RANS tables), and a default set for a statically stable finned body.
//!
//! # Model
//! Body axes (x nose, y right, z down); moments about the centre of gravity. With the dynamic
//! pressure `qbar = rho V^2 / 2`, reference area `S` and reference length `d`:
//!
//! ```text
//! F_body = qbar S (C_X, C_Y, C_Z)
//! M_body = qbar S d (C_l + C_lp p d/(2V), C_m + C_mq q d/(2V), C_n + C_nr r d/(2V))
//! C_i = base_i(alpha, beta) + sum over flaps f of delta_i^f(alpha, beta, deflection_f)
//! ```
//!
//! the superposition of individual flap increments that the paper adopts for asymmetric
//! deflections (section 2.1). Angles follow flight mechanics: `alpha = atan2(w, u)`,
//! `beta = asin(v / V)` of the body's velocity relative to the air in body axes. Interpolation is
//! bilinear in (alpha, beta) and linear in the deflection; beyond a table's range the value at
//! its edge is used.
//!
//! # Flaps and sign conventions
//! Four flaps in a "+" layout at the tail: `right` (+y) and `left` (-y) are horizontal, `top`
//! (-z) and `bottom` (+z) vertical. A positive deflection of a horizontal flap moves its trailing
//! edge up (force +z at the tail: nose-up pitching moment); of a vertical flap, its trailing edge to
//! starboard (force -y at the tail: nose-right yawing moment). The paper's Fig. 5 mixing then reads
//! (see [`crate::physics::accd::mix`]): pitch (nose up) = right and left together; yaw (nose right) = top and
//! bottom together; roll (right side down) = right +, left -, top -, bottom +.
//!
//! # File format (JSON)
//! ```text
//! {
//!   "reference_area": 0.0707,          // S, m^2
//!   "reference_length": 0.3,           // d, m
//!   "alpha_deg": [...], "beta_deg": [...], "deflection_deg": [...],   // strictly increasing
//!   "base":  {"cx": [...], "cy": [...], "cz": [...], "cl": [...], "cm": [...], "cn": [...]},
//!   "flaps": {"right": {...}, "left": {...}, "top": {...}, "bottom": {...}},
//!   "damping": {"clp": -12.0, "cmq": -150.0, "cnr": -150.0}           // per radian
//! }
//! ```
//! Each `base` array is flat with `alpha` varying slowest: index `ia * n_beta + ib`. Each flap
//! array holds increments, index `(ia * n_beta + ib) * n_deflection + id`. `accd-gym` can write
//! the default set in this format as a starting point ([`AeroModel::to_json`]).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Result, SimError};
use crate::physics::interp::{check_axis, check_values, Axis};

/// Names of the six coefficients, in storage order.
pub const COEFFICIENTS: [&str; 6] = ["cx", "cy", "cz", "cl", "cm", "cn"];
/// Names of the four flaps, in storage (and action) order.
pub const FLAPS: [&str; 4] = ["right", "left", "top", "bottom"];

/// Six coefficient arrays (see the module docs for the index order).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoefficientArrays {
    /// Axial force coefficient (body x).
    pub cx: Vec<f64>,
    /// Side force coefficient (body y).
    pub cy: Vec<f64>,
    /// Normal force coefficient (body z, down).
    pub cz: Vec<f64>,
    /// Rolling moment coefficient.
    pub cl: Vec<f64>,
    /// Pitching moment coefficient.
    pub cm: Vec<f64>,
    /// Yawing moment coefficient.
    pub cn: Vec<f64>,
}

impl CoefficientArrays {
    fn arrays(&self) -> [&Vec<f64>; 6] {
        [&self.cx, &self.cy, &self.cz, &self.cl, &self.cm, &self.cn]
    }
    fn from_interleaved(values: &[[f64; 6]]) -> Self {
        let col = |c: usize| values.iter().map(|v| v[c]).collect();
        CoefficientArrays {
            cx: col(0),
            cy: col(1),
            cz: col(2),
            cl: col(3),
            cm: col(4),
            cn: col(5),
        }
    }
}

/// The four flaps' increment tables.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlapArrays {
    /// Right (+y, horizontal) flap.
    pub right: CoefficientArrays,
    /// Left (-y, horizontal) flap.
    pub left: CoefficientArrays,
    /// Top (-z, vertical) flap.
    pub top: CoefficientArrays,
    /// Bottom (+z, vertical) flap.
    pub bottom: CoefficientArrays,
}

/// Rate damping derivatives, per radian of `p d/(2V)`, `q d/(2V)`, `r d/(2V)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Damping {
    /// Roll damping C_lp.
    pub clp: f64,
    /// Pitch damping C_mq (including the alpha-dot contribution).
    pub cmq: f64,
    /// Yaw damping C_nr (including the beta-dot contribution).
    pub cnr: f64,
}

/// The serialized form of an aerodynamic model (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AeroTableFile {
    /// Reference area S, m^2.
    pub reference_area: f64,
    /// Reference length d, m.
    pub reference_length: f64,
    /// Angle-of-attack axis, degrees.
    pub alpha_deg: Vec<f64>,
    /// Sideslip axis, degrees.
    pub beta_deg: Vec<f64>,
    /// Flap deflection axis, degrees.
    pub deflection_deg: Vec<f64>,
    /// Coefficients of the body with all flaps neutral, over (alpha, beta).
    pub base: CoefficientArrays,
    /// Increments of each flap over (alpha, beta, deflection).
    pub flaps: FlapArrays,
    /// Rate damping derivatives.
    pub damping: Damping,
}

/// Aerodynamic coefficients ready for fast evaluation: axes in radians, values interleaved.
#[derive(Debug, Clone, PartialEq)]
pub struct AeroModel {
    reference_area: f64,
    reference_length: f64,
    alpha: Axis,
    beta: Axis,
    deflection: Axis,
    /// [ia][ib] -> 6 coefficients.
    base: Vec<[f64; 6]>,
    /// [flap][ia][ib][id] -> 6 increments.
    flaps: Vec<[f64; 6]>,
    damping: Damping,
}

/// Parameters of the analytic default set: a 1.5 m body of 0.3 m diameter with four tail fins
/// carrying the flaps. Every number is an assumption (the paper gives none), chosen to be
/// credible for a small finned body and documented here.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FinnedBody {
    /// Body diameter = reference length, m.
    pub diameter: f64,
    /// Zero-lift axial force coefficient (nose, base, fins), on the frontal area.
    pub axial_zero: f64,
    /// Growth of the axial force coefficient with sin^2 of the incidence.
    pub axial_incidence: f64,
    /// Normal-force slope, per radian.
    pub normal_slope: f64,
    /// Cross-flow (nonlinear) normal force coefficient, multiplies sin(a) |sin(a)|.
    pub normal_crossflow: f64,
    /// Static margin: centre of pressure behind the centre of gravity, in calibres.
    pub static_margin: f64,
    /// Flap force slope per flap, per radian of deflection.
    pub flap_slope: f64,
    /// Flap drag, multiplies sin^2 of the deflection.
    pub flap_drag: f64,
    /// Distance of the flaps' centre of pressure behind the centre of gravity, m.
    pub flap_arm: f64,
    /// Radial distance of each flap's centre of pressure from the body axis, m.
    pub flap_radius: f64,
    /// Local incidence (rad) at which a flap's effectiveness has halved.
    pub flap_stall: f64,
    /// Damping derivatives.
    pub damping: Damping,
}

impl FinnedBody {
    /// The default ACCD: C_A0 = 0.6 (the drag area of the stand-in body used to calibrate the
    /// tether), C_N_alpha = 10 /rad, static margin 0.8 calibre (C_m_alpha = -8 /rad), flaps of
    /// 1.2 /rad each, 0.75 m behind the centre of gravity at 0.22 m radius, C_lp = -12,
    /// C_mq = C_nr = -150 (pitch/yaw damping ratio about 0.1 at 185 m/s, 6000 m).
    pub fn accd() -> Self {
        FinnedBody {
            diameter: 0.3,
            axial_zero: 0.6,
            axial_incidence: 0.8,
            normal_slope: 10.0,
            normal_crossflow: 4.0,
            static_margin: 0.8,
            flap_slope: 1.2,
            flap_drag: 0.3,
            flap_arm: 0.75,
            flap_radius: 0.22,
            flap_stall: 20f64.to_radians(),
            damping: Damping {
                clp: -12.0,
                cmq: -150.0,
                cnr: -150.0,
            },
        }
    }

    /// Base coefficients at (alpha, beta), rad.
    pub fn base(&self, alpha: f64, beta: f64) -> [f64; 6] {
        let (sa, ca) = libm::sincos(alpha);
        let (sb, cb) = libm::sincos(beta);
        let cx = -(self.axial_zero + self.axial_incidence * (sa * sa + sb * sb));
        let cz = -(self.normal_slope * sa * ca + self.normal_crossflow * sa * sa.abs());
        let cy = -(self.normal_slope * sb * cb + self.normal_crossflow * sb * sb.abs());
        // Centre of pressure `static_margin` calibres behind the centre of gravity.
        let h = self.static_margin;
        [cx, cy, cz, 0.0, h * cz, -h * cy]
    }

    /// Increments of flap `flap` (0 right, 1 left, 2 top, 3 bottom) at (alpha, beta, deflection).
    pub fn flap(&self, flap: usize, alpha: f64, beta: f64, deflection: f64) -> [f64; 6] {
        let horizontal = flap < 2;
        let incidence = if horizontal { alpha } else { beta };
        let ratio = incidence / self.flap_stall;
        let effectiveness = 1.0 / (1.0 + ratio * ratio);
        let sin_deflection = libm::sin(deflection);
        let force = self.flap_slope * sin_deflection * effectiveness;
        let drag = -self.flap_drag * (sin_deflection * sin_deflection);
        let arm = self.flap_arm / self.diameter;
        let radius = self.flap_radius / self.diameter;
        match flap {
            // Horizontal flaps push along +z; at y = +-r they roll, behind the CG they pitch.
            0 => [drag, 0.0, force, radius * force, arm * force, 0.0],
            1 => [drag, 0.0, force, -radius * force, arm * force, 0.0],
            // Vertical flaps push along -y; at z = -+r they roll, behind the CG they yaw.
            2 => [drag, -force, 0.0, -radius * force, 0.0, arm * force],
            _ => [drag, -force, 0.0, radius * force, 0.0, arm * force],
        }
    }
}

/// The largest flap deflection of the default tables ([`AeroModel::from_finned_body`]), deg.
pub const DEFAULT_DEFLECTION_LIMIT_DEG: f64 = 15.0;

impl AeroModel {
    /// The deflection axis's range, deg: beyond it the tables hold their edge values.
    pub fn deflection_range_deg(&self) -> (f64, f64) {
        let first = self.deflection.values().first().copied().unwrap_or(0.0);
        let last = self.deflection.values().last().copied().unwrap_or(0.0);
        (first.to_degrees(), last.to_degrees())
    }

    /// Tabulates `body` on alpha, beta in [-30, 30] degrees every 2.5 degrees and deflections in
    /// [-15, 15] degrees every 2.5 degrees.
    pub fn from_finned_body(body: &FinnedBody) -> Self {
        let axis = |lo: f64, hi: f64, step: f64| -> Vec<f64> {
            let n = ((hi - lo) / step).round() as usize;
            (0..=n)
                .map(|i| (lo + step * i as f64).to_radians())
                .collect()
        };
        let alpha = axis(-30.0, 30.0, 2.5);
        let beta = alpha.clone();
        let deflection = axis(
            -DEFAULT_DEFLECTION_LIMIT_DEG,
            DEFAULT_DEFLECTION_LIMIT_DEG,
            2.5,
        );
        let mut base = Vec::with_capacity(alpha.len() * beta.len());
        for &a in &alpha {
            for &b in &beta {
                base.push(body.base(a, b));
            }
        }
        let mut flaps = Vec::with_capacity(4 * base.len() * deflection.len());
        for f in 0..4 {
            for &a in &alpha {
                for &b in &beta {
                    for &d in &deflection {
                        flaps.push(body.flap(f, a, b, d));
                    }
                }
            }
        }
        AeroModel {
            reference_area: std::f64::consts::PI * body.diameter * body.diameter / 4.0,
            reference_length: body.diameter,
            alpha: Axis::new(alpha),
            beta: Axis::new(beta),
            deflection: Axis::new(deflection),
            base,
            flaps,
            damping: body.damping,
        }
    }

    /// The default model ([`FinnedBody::accd`]).
    pub fn accd() -> Self {
        AeroModel::from_finned_body(&FinnedBody::accd())
    }

    /// The model with every force coefficient (base and flap increments of C_X, C_Y, C_Z) times
    /// `force` and every moment coefficient (C_l, C_m, C_n, their flap increments and the
    /// damping derivatives) times `moment`: loads scale by the same factors
    /// (`tests` check it against [`crate::physics::accd::aero_loads`]).
    pub fn scaled(mut self, force: f64, moment: f64) -> Self {
        for c in self.base.iter_mut().chain(self.flaps.iter_mut()) {
            for (i, v) in c.iter_mut().enumerate() {
                *v *= if i < 3 { force } else { moment };
            }
        }
        self.damping.clp *= moment;
        self.damping.cmq *= moment;
        self.damping.cnr *= moment;
        self
    }

    /// Builds a model from the file format, validating every axis and array.
    pub fn from_file_data(data: &AeroTableFile, name: &str) -> Result<Self> {
        for (field, v) in [
            ("reference_area", data.reference_area),
            ("reference_length", data.reference_length),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 100.0) {
                return Err(SimError::invalid_table(
                    name,
                    format!("`{field}` = {v} must be in (0, 100]"),
                ));
            }
        }
        let d = data.damping;
        for (field, v) in [
            ("damping.clp", d.clp),
            ("damping.cmq", d.cmq),
            ("damping.cnr", d.cnr),
        ] {
            if !v.is_finite() {
                return Err(SimError::invalid_table(
                    name,
                    format!("`{field}` = {v} is not finite"),
                ));
            }
        }
        check_axis(name, "alpha_deg", &data.alpha_deg)?;
        check_axis(name, "beta_deg", &data.beta_deg)?;
        check_axis(name, "deflection_deg", &data.deflection_deg)?;
        let (na, nb, nd) = (
            data.alpha_deg.len(),
            data.beta_deg.len(),
            data.deflection_deg.len(),
        );
        let shape2 = format!("({na} alpha x {nb} beta)");
        for (c, arr) in COEFFICIENTS.iter().zip(data.base.arrays()) {
            check_values(name, &format!("base.{c}"), arr, na * nb, &shape2)?;
        }
        let shape3 = format!("({na} alpha x {nb} beta x {nd} deflection)");
        let flap_sets = [
            &data.flaps.right,
            &data.flaps.left,
            &data.flaps.top,
            &data.flaps.bottom,
        ];
        for (flap, set) in FLAPS.iter().zip(flap_sets) {
            for (c, arr) in COEFFICIENTS.iter().zip(set.arrays()) {
                check_values(
                    name,
                    &format!("flaps.{flap}.{c}"),
                    arr,
                    na * nb * nd,
                    &shape3,
                )?;
            }
        }
        let interleave = |set: &CoefficientArrays, len: usize| -> Vec<[f64; 6]> {
            let arrays = set.arrays();
            (0..len)
                .map(|i| std::array::from_fn(|c| arrays[c][i]))
                .collect()
        };
        let base = interleave(&data.base, na * nb);
        let mut flaps = Vec::with_capacity(4 * na * nb * nd);
        for set in flap_sets {
            flaps.extend(interleave(set, na * nb * nd));
        }
        let rad = |v: &Vec<f64>| Axis::new(v.iter().map(|x| x.to_radians()).collect());
        Ok(AeroModel {
            reference_area: data.reference_area,
            reference_length: data.reference_length,
            alpha: rad(&data.alpha_deg),
            beta: rad(&data.beta_deg),
            deflection: rad(&data.deflection_deg),
            base,
            flaps,
            damping: data.damping,
        })
    }

    /// Parses the JSON file format.
    pub fn from_json(text: &str, name: &str) -> Result<Self> {
        let data: AeroTableFile =
            serde_json::from_str(text).map_err(|e| SimError::invalid_table(name, e.to_string()))?;
        AeroModel::from_file_data(&data, name)
    }

    /// Reads a JSON file in the documented format, named by the configuration field `field`
    /// (`accd.aero_table`) in the errors: a regular file of at most
    /// [`crate::table_file::MAX_TABLE_FILE_BYTES`] ([`crate::table_file::read_table_file`]).
    pub fn from_path(path: &Path, field: &str) -> Result<Self> {
        let text = crate::table_file::read_table_file(path, field)?;
        AeroModel::from_json(&text, &path.display().to_string())
    }

    /// The model in the file format.
    pub fn to_file_data(&self) -> AeroTableFile {
        // Degrees rounded to 1e-9 so that the file shows the grid as written (-30, not -29.999...).
        let deg = |v: &Axis| {
            v.values()
                .iter()
                .map(|x| (x.to_degrees() * 1e9).round() / 1e9)
                .collect()
        };
        let per_flap = self.flaps.len() / 4;
        let flap = |f: usize| {
            CoefficientArrays::from_interleaved(&self.flaps[f * per_flap..(f + 1) * per_flap])
        };
        AeroTableFile {
            reference_area: self.reference_area,
            reference_length: self.reference_length,
            alpha_deg: deg(&self.alpha),
            beta_deg: deg(&self.beta),
            deflection_deg: deg(&self.deflection),
            base: CoefficientArrays::from_interleaved(&self.base),
            flaps: FlapArrays {
                right: flap(0),
                left: flap(1),
                top: flap(2),
                bottom: flap(3),
            },
            damping: self.damping,
        }
    }

    /// The model as JSON in the file format.
    pub fn to_json(&self) -> String {
        serde_json::to_string(&self.to_file_data()).expect("plain numbers serialize")
    }

    /// Reference area S, m^2.
    pub fn reference_area(&self) -> f64 {
        self.reference_area
    }

    /// Reference length d, m.
    pub fn reference_length(&self) -> f64 {
        self.reference_length
    }

    /// Damping derivatives.
    pub fn damping(&self) -> Damping {
        self.damping
    }

    /// Static coefficients `[C_X, C_Y, C_Z, C_l, C_m, C_n]` at (alpha, beta) with the four flap
    /// deflections (all rad), by superposition of the base table and the flap increments.
    pub fn coefficients(&self, alpha: f64, beta: f64, deflections: &[f64; 4]) -> [f64; 6] {
        let nb = self.beta.values().len();
        let nd = self.deflection.values().len();
        let (ia, fa) = self.alpha.locate_held(alpha);
        let (ib, fb) = self.beta.locate_held(beta);
        let w = [
            (1.0 - fa) * (1.0 - fb),
            (1.0 - fa) * fb,
            fa * (1.0 - fb),
            fa * fb,
        ];
        let cells = [
            ia * nb + ib,
            ia * nb + ib + 1,
            (ia + 1) * nb + ib,
            (ia + 1) * nb + ib + 1,
        ];
        let mut out = [0.0; 6];
        for (cell, wk) in cells.iter().zip(w) {
            let v = &self.base[*cell];
            for c in 0..6 {
                out[c] += wk * v[c];
            }
        }
        let per_flap = self.base.len() * nd;
        for (f, &delta) in deflections.iter().enumerate() {
            let (id, fd) = self.deflection.locate_held(delta);
            for (cell, wk) in cells.iter().zip(w) {
                let at = f * per_flap + cell * nd + id;
                let (lo, hi) = (&self.flaps[at], &self.flaps[at + 1]);
                for c in 0..6 {
                    out[c] += wk * (lo[c] + fd * (hi[c] - lo[c]));
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaled_models_scale_forces_and_moments_by_their_factors() {
        let model = AeroModel::accd();
        let (f, m) = (1.15, 0.8);
        let scaled = model.clone().scaled(f, m);
        let d = [0.1, -0.05, 0.2, -0.2];
        for (a, b) in [(0.0, 0.0), (0.12, -0.07), (-0.3, 0.2)] {
            let (c, s) = (model.coefficients(a, b, &d), scaled.coefficients(a, b, &d));
            for i in 0..6 {
                let k = if i < 3 { f } else { m };
                assert!((s[i] - k * c[i]).abs() <= 1e-14 * (1.0 + c[i].abs()), "{i}");
            }
        }
        let (dc, ds) = (model.damping(), scaled.damping());
        assert_eq!(
            [ds.clp, ds.cmq, ds.cnr],
            [dc.clp * m, dc.cmq * m, dc.cnr * m]
        );
        assert_eq!(model.clone().scaled(1.0, 1.0), model);
    }

    #[test]
    fn table_reproduces_the_analytic_body_at_grid_points_and_between() {
        let body = FinnedBody::accd();
        let model = AeroModel::from_finned_body(&body);
        let d = [
            5f64.to_radians(),
            -2.5f64.to_radians(),
            10f64.to_radians(),
            0.0,
        ];
        let (a, b) = (7.5f64.to_radians(), -5f64.to_radians());
        let table = model.coefficients(a, b, &d);
        let mut exact = body.base(a, b);
        for (f, &df) in d.iter().enumerate() {
            let inc = body.flap(f, a, b, df);
            for c in 0..6 {
                exact[c] += inc[c];
            }
        }
        for c in 0..6 {
            assert!(
                (table[c] - exact[c]).abs() < 1e-12,
                "{}: {} vs {}",
                COEFFICIENTS[c],
                table[c],
                exact[c]
            );
        }
        // Between grid points the error is that of linear interpolation of smooth functions.
        let (a, b) = (8.3f64.to_radians(), -1.1f64.to_radians());
        let table = model.coefficients(a, b, &[0.0; 4]);
        let exact = body.base(a, b);
        for c in 0..6 {
            assert!((table[c] - exact[c]).abs() < 0.01, "{}", COEFFICIENTS[c]);
        }
    }

    #[test]
    fn json_round_trip_keeps_values() {
        // The file stores angles in degrees: the round trip through degrees costs an ulp or two.
        let model = AeroModel::accd();
        let back = AeroModel::from_json(&model.to_json(), "round trip").unwrap();
        let (a, b) = (0.1, -0.05);
        let d = [0.1, -0.2, 0.05, 0.0];
        let (x, y) = (model.coefficients(a, b, &d), back.coefficients(a, b, &d));
        for c in 0..6 {
            assert!((x[c] - y[c]).abs() < 1e-13);
        }
    }

    #[test]
    fn loader_names_bad_shapes_values_and_axes() {
        let good = AeroModel::accd().to_file_data();
        let mut bad = good.clone();
        bad.base.cm.pop();
        let e = AeroModel::from_file_data(&bad, "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("base.cm") && e.contains("expected 625"), "{e}");
        let mut bad = good.clone();
        bad.flaps.top.cn[17] = f64::NAN;
        let e = AeroModel::from_file_data(&bad, "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("flaps.top.cn") && e.contains("index 17"), "{e}");
        let mut bad = good.clone();
        bad.alpha_deg.swap(3, 4);
        let e = AeroModel::from_file_data(&bad, "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("alpha_deg") && e.contains("index 4"), "{e}");
        let e = AeroModel::from_json(r#"{"reference_area": 1}"#, "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing field"), "{e}");
    }

    #[test]
    fn default_body_is_statically_stable_with_effective_flaps() {
        let m = AeroModel::accd();
        let small = 2f64.to_radians();
        let up = m.coefficients(small, 0.0, &[0.0; 4]);
        let side = m.coefficients(0.0, small, &[0.0; 4]);
        assert!(up[4] < 0.0, "C_m_alpha < 0 (nose-down restoring moment)");
        assert!(up[2] < 0.0, "positive alpha gives lift (-z)");
        assert!(side[5] > 0.0, "C_n_beta > 0 (weathercock stability)");
        assert!(side[1] < 0.0);
        let pitch = 10f64.to_radians();
        let c = m.coefficients(0.0, 0.0, &[pitch, pitch, 0.0, 0.0]);
        assert!(
            c[4] > 0.0 && c[3].abs() < 1e-12,
            "pitch flaps: nose-up moment, no roll"
        );
        let c = m.coefficients(0.0, 0.0, &[0.0, 0.0, pitch, pitch]);
        assert!(
            c[5] > 0.0 && c[3].abs() < 1e-12,
            "yaw flaps: nose-right moment, no roll"
        );
        let c = m.coefficients(0.0, 0.0, &[pitch, -pitch, -pitch, pitch]);
        assert!(
            c[3] > 0.0 && c[4].abs() < 1e-12 && c[5].abs() < 1e-12,
            "roll mixing: pure roll"
        );
        assert!(c[0] < -0.6, "deflected flaps add drag");
    }
}
