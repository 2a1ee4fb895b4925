//! Rotations between unit quaternions, rotation vectors and Euler angles, with the sines,
//! cosines and arc tangents of the `libm` crate: the same bits on every processor and system
//! (nalgebra's own constructors call the platform's C library). The formulas are nalgebra's.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// The rotation by `|v|` radians about `v` (nalgebra's `UnitQuaternion::from_scaled_axis`):
/// `(cos(|v|/2), v/|v| sin(|v|/2))`; the identity where `|v|/2` is at most machine epsilon.
pub fn from_scaled_axis(v: Vector3<f64>) -> UnitQuaternion<f64> {
    let half = v / 2.0;
    let nn = half.norm_squared();
    if nn <= f64::EPSILON * f64::EPSILON {
        return UnitQuaternion::identity();
    }
    let n = nn.sqrt();
    let (sin, cos) = libm::sincos(n);
    UnitQuaternion::new_unchecked(Quaternion::from_parts(cos, half * (sin / n)))
}

/// The rotation vector of `q`, axis times angle in [0, pi] (nalgebra's
/// `UnitQuaternion::scaled_axis`); zero for the identity.
pub fn scaled_axis(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (w, imag) = (q.scalar(), q.imag());
    let v = if w >= 0.0 { imag } else { -imag };
    let norm = v.norm();
    if norm <= 0.0 {
        return Vector3::zeros();
    }
    let angle = libm::atan2(norm, w.abs()) * 2.0;
    (v / norm) * angle
}

/// The rotation by `roll` about x, then `pitch` about y, then `yaw` about z, rad (nalgebra's
/// `UnitQuaternion::from_euler_angles`).
pub fn from_euler_angles(roll: f64, pitch: f64, yaw: f64) -> UnitQuaternion<f64> {
    let (sr, cr) = libm::sincos(roll * 0.5);
    let (sp, cp) = libm::sincos(pitch * 0.5);
    let (sy, cy) = libm::sincos(yaw * 0.5);
    UnitQuaternion::new_unchecked(Quaternion::new(
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agree_with_nalgebra() {
        for v in [
            Vector3::new(0.3, -0.2, 1.0),
            Vector3::new(-2.5, 0.1, 0.4),
            Vector3::new(1e-9, 0.0, 0.0),
            Vector3::zeros(),
        ] {
            let ours = from_scaled_axis(v);
            let theirs = UnitQuaternion::from_scaled_axis(v);
            assert!((ours.coords - theirs.coords).norm() < 1e-15, "{v}");
            assert!(
                (scaled_axis(&ours) - theirs.scaled_axis()).norm() < 1e-14,
                "{v}"
            );
            let e = from_euler_angles(v.x, v.y, v.z);
            let n = UnitQuaternion::from_euler_angles(v.x, v.y, v.z);
            assert!((e.coords - n.coords).norm() < 1e-15, "{v}");
        }
    }
}
