//! Sines and cosines of many angles at once, for the right-hand side's hot path.
//!
//! The model needs sin and cos of all 2n angles at every right-hand-side evaluation. libm's
//! `sin`/`cos` are called one angle at a time through the PLT; this batch version is branch-free
//! (Cody-Waite reduction by pi/2 in three parts, fdlibm's minimax kernels on [-pi/4, pi/4], the
//! quadrant applied with bit operations), so the compiler vectorizes the loop. It agrees with libm
//! to about 1 ulp of max(|sin x|, |cos x|) for |x| <= [`REDUCTION_LIMIT`] (tested); larger or
//! non-finite arguments fall back to the standard library.

/// Beyond this |x| the three-part reduction loses accuracy; such angles use `f64::sin_cos`.
pub const REDUCTION_LIMIT: f64 = 1.0e5;

const FRAC_2_PI: f64 = std::f64::consts::FRAC_2_PI;
/// 1.5 * 2^52: adding and subtracting it rounds to the nearest integer, and the sum's low bits
/// hold that integer modulo 4.
const ROUNDER: f64 = 6_755_399_441_055_744.0;
// pi/2 in three parts of 33 bits each (fdlibm's pio2_1, pio2_2, pio2_3): k * PIO2_1 and k * PIO2_2
// are exact for |k| < 2^20.
const PIO2_1: f64 = 1.5707963267341256;
const PIO2_2: f64 = 6.077100506303966e-11;
const PIO2_3: f64 = 2.0222662487111665e-21;

// fdlibm's __kernel_sin and __kernel_cos minimax coefficients on [-pi/4, pi/4].
const S1: f64 = -0.16666666666666632;
const S2: f64 = 0.00833333333332249;
const S3: f64 = -0.0001984126982985795;
const S4: f64 = 2.7557313707070068e-06;
const S5: f64 = -2.5050760253406863e-08;
const S6: f64 = 1.58969099521155e-10;
const C1: f64 = 0.0416666666666666;
const C2: f64 = -0.001388888888887411;
const C3: f64 = 2.480158728947673e-05;
const C4: f64 = -2.7557314351390663e-07;
const C5: f64 = 2.087572321298175e-09;
const C6: f64 = -1.1359647557788195e-11;

/// sin and cos of one angle (|x| <= [`REDUCTION_LIMIT`] for the fast path's accuracy).
#[inline(always)]
fn sin_cos_reduced(x: f64) -> (f64, f64) {
    let sum = x * FRAC_2_PI + ROUNDER;
    let k = sum - ROUNDER;
    let quadrant = sum.to_bits() & 3;
    let r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3;
    let z = r * r;
    let sin_poly = S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)));
    let s = r + (z * r) * (S1 + z * sin_poly);
    let cos_poly = z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    let c = w + (((1.0 - w) - hz) + z * cos_poly);
    // Quadrant q: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s).
    let swap = 0u64.wrapping_sub(quadrant & 1);
    let (sb, cb) = (s.to_bits(), c.to_bits());
    let a = (sb & !swap) | (cb & swap);
    let b = (cb & !swap) | (sb & swap);
    let sin_sign = (quadrant & 2) << 62;
    let cos_sign = ((quadrant + 1) & 2) << 62;
    (f64::from_bits(a ^ sin_sign), f64::from_bits(b ^ cos_sign))
}

/// `sin[i], cos[i] = sin(x[i]), cos(x[i])` for all i (`sin` and `cos` at least as long as `x`).
#[inline(always)]
pub fn sin_cos_batch(x: &[f64], sin: &mut [f64], cos: &mut [f64]) {
    let len = x.len();
    let (sin, cos) = (&mut sin[..len], &mut cos[..len]);
    let mut out_of_range = 0usize;
    for i in 0..len {
        (sin[i], cos[i]) = sin_cos_reduced(x[i]);
        out_of_range += usize::from(!(0.0..=REDUCTION_LIMIT).contains(&x[i].abs()));
    }
    // Rare: redo the arguments out of range with the standard library.
    if out_of_range > 0 {
        for i in 0..len {
            if !(0.0..=REDUCTION_LIMIT).contains(&x[i].abs()) {
                (sin[i], cos[i]) = libm::sincos(x[i]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two finite doubles.
    fn ulps(a: f64, b: f64) -> f64 {
        if a == b {
            return 0.0;
        }
        let scale = a.abs().max(b.abs());
        // Near zero (sin at multiples of pi), compare against the ulp of 1e-300 floor.
        let ulp = f64::EPSILON * scale.max(1e-300);
        (a - b).abs() / ulp
    }

    #[test]
    fn constants_are_fdlibms() {
        let expect: [(f64, u64); 15] = [
            (PIO2_1, 0x3FF921FB54400000),
            (PIO2_2, 0x3DD0B4611A600000),
            (PIO2_3, 0x3BA3198A2E000000),
            (S1, 0xBFC5555555555549),
            (S2, 0x3F8111111110F8A6),
            (S3, 0xBF2A01A019C161D5),
            (S4, 0x3EC71DE357B1FE7D),
            (S5, 0xBE5AE5E68A2B9CEB),
            (S6, 0x3DE5D93A5ACFD57C),
            (C1, 0x3FA555555555554C),
            (C2, 0xBF56C16C16C15177),
            (C3, 0x3EFA01A019CB1590),
            (C4, 0xBE927E4F809C52AD),
            (C5, 0x3E21EE9EBDB4B1C4),
            (C6, 0xBDA8FAE9BE8838D4),
        ];
        for (v, bits) in expect {
            assert_eq!(v.to_bits(), bits, "{v:e}");
        }
    }

    #[test]
    fn agrees_with_libm_within_one_ulp() {
        let mut x = Vec::new();
        let mut state = 0x1234_5678_9ABC_DEF0u64;
        for i in 0..200_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let u = (state >> 11) as f64 / (1u64 << 53) as f64;
            let range = [4.0, 40.0, 1e3, REDUCTION_LIMIT][i % 4];
            x.push((2.0 * u - 1.0) * range);
        }
        // Quadrant boundaries and special points.
        for k in -20..=20 {
            let b = k as f64 * std::f64::consts::FRAC_PI_4;
            x.extend([b, b.next_up(), b.next_down()]);
        }
        x.extend([
            0.0,
            -0.0,
            1e-300,
            -1e-300,
            2e5,
            -3e7,
            1e300,
            f64::NAN,
            f64::INFINITY,
        ]);
        let (mut s, mut c) = (vec![0.0; x.len()], vec![0.0; x.len()]);
        sin_cos_batch(&x, &mut s, &mut c);
        let mut worst = 0.0f64;
        for i in 0..x.len() {
            let (es, ec) = libm::sincos(x[i]);
            if !x[i].is_finite() {
                assert!(s[i].is_nan() && c[i].is_nan());
                continue;
            }
            // Both libm and the batch are within 1 ulp of the truth (libm within 0.5): allow the
            // sum, relative to the larger of |sin|, |cos| (cancellation near zeros is absolute).
            let big = es.abs().max(ec.abs());
            let ds = (s[i] - es).abs() / (f64::EPSILON * big);
            let dc = (c[i] - ec).abs() / (f64::EPSILON * big);
            worst = worst.max(ds).max(dc);
            assert!(
                ds <= 1.5 && dc <= 1.5,
                "x = {:e}: sin {:e} vs {:e}, cos {:e} vs {:e}",
                x[i],
                s[i],
                es,
                c[i],
                ec
            );
            assert!(ulps(s[i] * s[i] + c[i] * c[i], 1.0) <= 4.0);
        }
        eprintln!("worst difference from libm: {worst:.2} ulp of max(|sin|, |cos|)");
    }
}
