//! Multiply-adds for the right-hand side's hot loops, and the choice of its build.
//!
//! One arithmetic on every processor: every multiply-add of the hot loops is one fused
//! multiply-add (`f64::mul_add`, rounded once), which IEEE 754 defines to the bit. Rust never
//! contracts `a * b + c` by itself, so everything else is plain arithmetic, also the same
//! everywhere. Where the code is compiled for AVX2 and FMA (the build chosen at run time on a
//! processor that has them, [`native`]) and on aarch64, `mul_add` is one instruction; elsewhere it
//! is the C library's `fma`, correctly rounded in software, slower but with the same bits. The
//! two builds therefore differ in speed only.

use std::sync::OnceLock;

use nalgebra::Vector3;

type V3 = Vector3<f64>;

/// `a * b + c` with one rounding.
#[inline(always)]
pub(crate) fn madd(a: f64, b: f64, c: f64) -> f64 {
    a.mul_add(b, c)
}

/// `a . b`.
#[inline(always)]
pub(crate) fn dot(a: &V3, b: &V3) -> f64 {
    madd(a.x, b.x, madd(a.y, b.y, a.z * b.z))
}

/// `a s + y`.
#[inline(always)]
pub(crate) fn axpy(a: &V3, s: f64, y: &V3) -> V3 {
    V3::new(madd(a.x, s, y.x), madd(a.y, s, y.y), madd(a.z, s, y.z))
}

/// `a x b`.
#[inline(always)]
pub(crate) fn cross(a: &V3, b: &V3) -> V3 {
    V3::new(
        madd(a.y, b.z, -(a.z * b.y)),
        madd(a.z, b.x, -(a.x * b.z)),
        madd(a.x, b.y, -(a.y * b.x)),
    )
}

/// The environment variable that chooses the arithmetic's build: `portable` takes the build of
/// a processor without AVX2 and FMA whatever the processor has (same results, slower; for
/// checking that both builds agree); unset, empty or `native`, the build the processor allows.
pub const ARITHMETIC_VARIABLE: &str = "ACCD_GYM_ARITHMETIC";

/// The values [`ARITHMETIC_VARIABLE`] takes.
pub const ARITHMETIC_VALUES: [&str; 2] = ["native", "portable"];

/// Whether [`ARITHMETIC_VARIABLE`] asks for the portable build: `Ok(true)` for `portable`,
/// `Ok(false)` when unset, empty or `native`, and otherwise `Err` with the value it holds. Read
/// once per process.
pub fn portable_requested() -> std::result::Result<bool, String> {
    static CHOICE: OnceLock<std::result::Result<bool, String>> = OnceLock::new();
    CHOICE
        .get_or_init(|| match std::env::var(ARITHMETIC_VARIABLE) {
            Err(std::env::VarError::NotPresent) => Ok(false),
            Ok(v) if v.is_empty() || v == "native" => Ok(false),
            Ok(v) if v == "portable" => Ok(true),
            Ok(v) => Err(v),
            Err(std::env::VarError::NotUnicode(v)) => Err(v.to_string_lossy().into_owned()),
        })
        .clone()
}

/// Whether the build for AVX2 and FMA runs: the processor has both and [`ARITHMETIC_VARIABLE`]
/// does not ask for the portable build (a value it does not know counts as `native`; the Python
/// package rejects such a value on import). A question of speed only: both builds compute the
/// same bits.
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn native() -> bool {
    static NATIVE: OnceLock<bool> = OnceLock::new();
    *NATIVE.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && portable_requested() != Ok(true)
    })
}

/// The build of the right-hand side this process runs: `"native"` (compiled for AVX2 and FMA)
/// or `"portable"` (every other processor, or [`ARITHMETIC_VARIABLE`] set to `portable`). Both
/// give the same bits.
pub fn arithmetic() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    if native() {
        return "native";
    }
    "portable"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_are_rounded_once() {
        let a = V3::new(0.3, -1.7, 2.9);
        let b = V3::new(-4.1, 0.6, 1.25);
        let y = V3::new(1.0, 2.0, -3.0);
        assert!((dot(&a, &b) - a.dot(&b)).abs() < 1e-14);
        assert!((axpy(&a, 0.7, &y) - (a * 0.7 + y)).norm() < 1e-15);
        assert!((cross(&a, &b) - a.cross(&b)).norm() < 1e-14);
        // 1 + 2^-30 squared is 1 + 2^-29 + 2^-60: one rounding keeps the 2^-60 that a separate
        // product loses.
        let x = 1.0 + f64::powi(2.0, -30);
        assert_eq!(madd(x, x, -1.0), f64::powi(2.0, -29) + f64::powi(2.0, -60));
        assert_eq!(x * x - 1.0, f64::powi(2.0, -29));
    }
}
