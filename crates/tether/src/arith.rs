//! Multiply-add, fused or not, for the right-hand side's hot loops.
//!
//! Rust never contracts `a * b + c` into one fused multiply-add, and `f64::mul_add` is a slow
//! library call on a processor without FMA. The hot loops are therefore written against [`Madd`]
//! and compiled twice: with [`Fused`] inside a function built for AVX2 and FMA (chosen at run time
//! when the processor has them) and with [`Plain`] otherwise. The two differ only in rounding.

use nalgebra::Vector3;

type V3 = Vector3<f64>;

/// `a * b + c`, fused or not.
pub(crate) trait Madd: 'static {
    fn madd(a: f64, b: f64, c: f64) -> f64;
}

/// Separate multiply and add.
pub(crate) struct Plain;

/// One fused multiply-add (use only where the processor has FMA).
pub(crate) struct Fused;

impl Madd for Plain {
    #[inline(always)]
    fn madd(a: f64, b: f64, c: f64) -> f64 {
        a * b + c
    }
}

impl Madd for Fused {
    #[inline(always)]
    fn madd(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
}

/// `a . b`.
#[inline(always)]
pub(crate) fn dot<M: Madd>(a: &V3, b: &V3) -> f64 {
    M::madd(a.x, b.x, M::madd(a.y, b.y, a.z * b.z))
}

/// `a s + y`.
#[inline(always)]
pub(crate) fn axpy<M: Madd>(a: &V3, s: f64, y: &V3) -> V3 {
    V3::new(
        M::madd(a.x, s, y.x),
        M::madd(a.y, s, y.y),
        M::madd(a.z, s, y.z),
    )
}

/// `a x b`.
#[inline(always)]
pub(crate) fn cross<M: Madd>(a: &V3, b: &V3) -> V3 {
    V3::new(
        M::madd(a.y, b.z, -(a.z * b.y)),
        M::madd(a.z, b.x, -(a.x * b.z)),
        M::madd(a.x, b.y, -(a.y * b.x)),
    )
}

/// Whether the processor has AVX2 and FMA: where [`Fused`] and the vectorized loops may run
/// (cached by the standard library after the first call).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn has_avx2_fma() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fused_and_plain_agree() {
        let a = V3::new(0.3, -1.7, 2.9);
        let b = V3::new(-4.1, 0.6, 1.25);
        let y = V3::new(1.0, 2.0, -3.0);
        assert!((dot::<Plain>(&a, &b) - a.dot(&b)).abs() < 1e-15);
        assert!((dot::<Fused>(&a, &b) - a.dot(&b)).abs() < 1e-14);
        assert!((axpy::<Fused>(&a, 0.7, &y) - (a * 0.7 + y)).norm() < 1e-15);
        assert!((cross::<Fused>(&a, &b) - a.cross(&b)).norm() < 1e-14);
        assert!((cross::<Plain>(&a, &b) - a.cross(&b)).norm() == 0.0);
    }
}
