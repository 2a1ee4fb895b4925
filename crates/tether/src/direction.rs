//! The angle convention of a segment direction, chosen so that its coordinate singularity lies
//! outside the operating envelope.
//!
//! A segment's unit direction (pointing away from the aircraft along the chain) is, in the
//! towing-aircraft frame (x forward, y starboard, z down),
//!
//! ```text
//! e(phi, psi) = ( -cos(psi) cos(phi),  sin(psi),  cos(psi) sin(phi) )
//! ```
//!
//! * `phi` is the in-plane angle, measured in the aircraft's vertical plane of symmetry from
//!   "trailing straight back" (phi = 0, e = -x) towards "hanging straight down" (phi = pi/2, e = +z);
//!   phi = pi points forward.
//! * `psi` is the lateral angle out of that plane, positive towards starboard (+y).
//!
//! The parametrisation is singular only where cos(psi) = 0, i.e. for a segment pointing straight
//! sideways (e = +-y). Trailing, hanging, everything in between and lateral excursions up to
//! several tens of degrees are far from it. The paper's own convention (Eq. 2) puts the singular
//! axis along z, which its initial condition for a straight trailing tether (psi = pi/2) hits
//! exactly; see `tests/integration/singularity.rs` for the conditioning of ours.

use nalgebra::Vector3;

/// Unit direction and its first and second partial derivatives with respect to (phi, psi).
#[derive(Debug, Clone, Copy, Default)]
pub struct DirectionJet {
    /// Unit direction e.
    pub e: Vector3<f64>,
    /// de/dphi, of length cos(psi).
    pub e_phi: Vector3<f64>,
    /// de/dpsi, of unit length, orthogonal to e and de/dphi.
    pub e_psi: Vector3<f64>,
    /// d2e/dphi2.
    pub e_phiphi: Vector3<f64>,
    /// d2e/dphi dpsi.
    pub e_phipsi: Vector3<f64>,
    /// cos(psi): the distance from the singularity.
    pub cos_psi: f64,
}

impl DirectionJet {
    /// Evaluates the direction and its derivatives at (phi, psi).
    #[inline]
    pub fn new(phi: f64, psi: f64) -> Self {
        let (sf, cf) = libm::sincos(phi);
        let (sp, cp) = libm::sincos(psi);
        DirectionJet {
            e: Vector3::new(-cp * cf, sp, cp * sf),
            e_phi: Vector3::new(cp * sf, 0.0, cp * cf),
            e_psi: Vector3::new(sp * cf, cp, -sp * sf),
            e_phiphi: Vector3::new(cp * cf, 0.0, -cp * sf),
            e_phipsi: Vector3::new(-sp * sf, 0.0, -sp * cf),
            cos_psi: cp,
        }
    }

    /// Time derivative of e for angle rates (phi_dot, psi_dot).
    #[inline]
    pub fn rate(&self, phi_dot: f64, psi_dot: f64) -> Vector3<f64> {
        self.e_phi * phi_dot + self.e_psi * psi_dot
    }

    /// Second time derivative of e with zero angle accelerations (the convective part):
    /// e_phiphi phi_dot^2 + 2 e_phipsi phi_dot psi_dot + e_psipsi psi_dot^2, with e_psipsi = -e.
    #[inline]
    pub fn convective(&self, phi_dot: f64, psi_dot: f64) -> Vector3<f64> {
        self.e_phiphi * (phi_dot * phi_dot) + self.e_phipsi * (2.0 * phi_dot * psi_dot)
            - self.e * (psi_dot * psi_dot)
    }
}

/// Direction of a segment at angles (phi, psi).
#[inline]
pub fn direction(phi: f64, psi: f64) -> Vector3<f64> {
    DirectionJet::new(phi, psi).e
}

/// Angles (phi, psi) of a direction (normalised first); psi in [-pi/2, pi/2], phi in (-pi, pi].
pub fn angles(e: &Vector3<f64>) -> (f64, f64) {
    let u = e.normalize();
    let psi = libm::asin(u.y.clamp(-1.0, 1.0));
    let phi = libm::atan2(u.z, -u.x);
    (phi, psi)
}

/// Angle rates (phi_dot, psi_dot) that reproduce the direction rate `e_dot` at (phi, psi), after
/// removing any component of `e_dot` along e (which a unit vector cannot have).
pub fn angle_rates(phi: f64, psi: f64, e_dot: &Vector3<f64>) -> (f64, f64) {
    let j = DirectionJet::new(phi, psi);
    let phi_dot = e_dot.dot(&j.e_phi) / (j.cos_psi * j.cos_psi);
    let psi_dot = e_dot.dot(&j.e_psi);
    (phi_dot, psi_dot)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn reference_directions() {
        assert!((direction(0.0, 0.0) - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-15);
        assert!((direction(FRAC_PI_2, 0.0) - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-15);
        assert!((direction(0.0, FRAC_PI_2) - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-15);
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let h = 1e-6;
        for &(phi, psi) in &[(0.3, -0.4), (2.0, 0.9), (-1.0, 0.1)] {
            let j = DirectionJet::new(phi, psi);
            let dphi = (direction(phi + h, psi) - direction(phi - h, psi)) / (2.0 * h);
            let dpsi = (direction(phi, psi + h) - direction(phi, psi - h)) / (2.0 * h);
            assert!((dphi - j.e_phi).norm() < 1e-9);
            assert!((dpsi - j.e_psi).norm() < 1e-9);
            let jp = DirectionJet::new(phi + h, psi);
            let jm = DirectionJet::new(phi - h, psi);
            assert!(((jp.e_phi - jm.e_phi) / (2.0 * h) - j.e_phiphi).norm() < 1e-8);
            assert!(((jp.e_psi - jm.e_psi) / (2.0 * h) - j.e_phipsi).norm() < 1e-8);
            let (a, b) = angles(&j.e);
            assert!((a - phi).abs() < 1e-12 && (b - psi).abs() < 1e-12);
            let (pd, sd) = angle_rates(phi, psi, &j.rate(0.7, -1.3));
            assert!((pd - 0.7).abs() < 1e-12 && (sd + 1.3).abs() < 1e-12);
        }
    }
}
