//! Helpers shared by the integration tests: independent forward kinematics (written from the
//! paper's Eq. 3, not from the model's code) and small numerical tools.
#![allow(dead_code)]

use accd_tether::direction::direction;
use accd_tether::{TetherConfig, TetherState};
use nalgebra::{DMatrix, Vector3};

pub type V3 = Vector3<f64>;

/// Segment centres and tip of state `q`, straight from the geometry.
pub fn positions(config: &TetherConfig, q: &[f64]) -> (Vec<V3>, V3) {
    let n = config.segments;
    let l = config.segment_length();
    let e: Vec<V3> = (0..n)
        .map(|k| direction(q[1 + 2 * k], q[2 + 2 * k]))
        .collect();
    let mut base = e[0] * q[0];
    let mut centres = Vec::with_capacity(n);
    for ek in &e {
        centres.push(base + ek * (0.5 * l));
        base += ek * l;
    }
    (centres, base)
}

/// Segment directions of state `q`.
pub fn directions(config: &TetherConfig, q: &[f64]) -> Vec<V3> {
    (0..config.segments)
        .map(|k| direction(q[1 + 2 * k], q[2 + 2 * k]))
        .collect()
}

/// Kinetic energy T(q, v) from central differences of the positions along v (step h).
pub fn kinetic_energy_fd(config: &TetherConfig, q: &[f64], v: &[f64]) -> f64 {
    let h = 1e-6;
    let plus: Vec<f64> = q.iter().zip(v).map(|(a, b)| a + h * b).collect();
    let minus: Vec<f64> = q.iter().zip(v).map(|(a, b)| a - h * b).collect();
    let (cp, tp) = positions(config, &plus);
    let (cm, tm) = positions(config, &minus);
    let (ep, em) = (directions(config, &plus), directions(config, &minus));
    let m = config.segment_mass();
    let l = config.segment_length();
    let inertia = m * l * l / 12.0;
    let mut t = 0.5 * config.tip_mass * ((tp - tm) / (2.0 * h)).norm_squared();
    for k in 0..config.segments {
        t += 0.5 * m * ((cp[k] - cm[k]) / (2.0 * h)).norm_squared();
        t += 0.5 * inertia * ((ep[k] - em[k]) / (2.0 * h)).norm_squared();
    }
    t
}

/// Smallest and largest eigenvalue of a symmetric matrix.
pub fn eig_range(m: &DMatrix<f64>) -> (f64, f64) {
    let ev = m.clone().symmetric_eigenvalues();
    (ev.min(), ev.max())
}

/// Upward zero crossings of a sampled signal, linearly interpolated.
pub fn upward_crossings(times: &[f64], values: &[f64]) -> Vec<f64> {
    let mut out = Vec::new();
    for i in 1..values.len() {
        if values[i - 1] < 0.0 && values[i] >= 0.0 {
            let f = -values[i - 1] / (values[i] - values[i - 1]);
            out.push(times[i - 1] + f * (times[i] - times[i - 1]));
        }
    }
    out
}

/// Deterministic pseudo-random numbers in [0, 1) (SplitMix64), for reproducible test states.
pub struct SplitMix(pub u64);

impl SplitMix {
    pub fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// A bent, moving state of `config`'s tether (every drag term on): segment k at angles
/// (0.3 + 0.02 k, 0.1 - 0.01 k) rad, turning at (0, 0.2 sin k, -0.15 cos k) rad/s, elongation
/// 0.01 m at 0.05 m/s.
pub fn bent_moving_state(config: &TetherConfig) -> TetherState {
    let n = config.segments;
    let dirs: Vec<_> = (0..n)
        .map(|k| direction(0.3 + 0.02 * k as f64, 0.1 - 0.01 * k as f64))
        .collect();
    let rates: Vec<_> = (0..n)
        .map(|k| V3::new(0.0, 0.2 * (k as f64).sin(), -0.15 * (k as f64).cos()))
        .collect();
    TetherState::from_directions(&dirs, &rates, 0.01, 0.05).unwrap()
}
