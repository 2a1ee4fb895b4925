//! The backward sweep of [`crate::recursive`] four lanes wide (AVX2 and FMA), bit for bit the
//! scalar sweep with fused multiply-adds ([`super::backward`]'s scalar loop with `Fused`).
//!
//! The scalar sweep spends most of its instructions on the 3-vectors `B E_phi`, `B E_psi`,
//! `B w`, the bias and the six entries of the articulated inertia `B`, each a few multiply-adds
//! per component; with twenty-odd values live it also spills. Here each 3-vector is one
//! register (x, y, z, and a lane that stays zero) and `B` is held as its three columns
//! `C0 = (xx, xy, xz)`, `C1 = (xy, yy, yz)`, `C2 = (xz, yz, zz)`, so that `B v` is
//! `C0 v_x + C1 v_y + C2 v_z` with, lane by lane, the very operations of [`super::Sym3`]'s
//! products. The dot products (the 2x2 system `K`, the projections `E^T v`) stay scalar, on
//! lanes taken out of the registers.
//!
//! Bit-for-bit rules kept throughout:
//! * every lane computes the scalar component's expression with the same operands in the same
//!   order (`fma(a, b, c)` for `M::madd(a, b, c)`, a separate multiply where the scalar code
//!   has one);
//! * the update of `B` is entry by entry `fma(-fma(a_i, be_j, a'_i be'_j), 1 / det, B_ij)` with
//!   `i <= j` as the scalar code writes it, never the mirrored `(j, i)` products (equal in
//!   exact arithmetic, not in floating point): column `C0'` is formed with `i = x` broadcast,
//!   `C2'` with `j = z` broadcast, and `C1'` takes `yy`, `yz` from the `i = y` products and
//!   `xy` from `C0'`;
//! * the mass on the diagonal is added to that lane alone (a blend), never as `+ 0` to the
//!   others, which would turn `-0` into `+0`.
//!
//! `dynamics::tests::vectorized_backward_sweep_is_bitwise_the_scalar_fused_sweep` compares
//! the accelerations, tensions and axial mass of both sweeps bitwise on random bent, folded and
//! spinning states; the physics fingerprints (`tests/test_physics_hash.py`) pin whole episodes.
//!
//! Measured (BENCHMARKS.md): 188 -> 129 instructions per segment and right-hand side, the
//! tether's RK4 step about 3.5 % faster (side-by-side runs). The sweep is bound by its chain of
//! dependent operations (`B_{k+1}` -> `B E` -> `K` -> `det` -> `1/det` -> `B_k`; about 60
//! cycles a segment measured), not by the instruction count; lane moves on that chain are what
//! the layout above keeps short.

use std::arch::x86_64::*;

use nalgebra::Vector3;

use super::{singular, Articulated, ChainConstants, Sym3};
use crate::chain::ChainState;
use crate::error::Result;

type V3 = Vector3<f64>;

/// `(x, y, z, 0)`.
#[inline(always)]
unsafe fn pack(x: f64, y: f64, z: f64) -> __m256d {
    _mm256_set_pd(0.0, z, y, x)
}

/// The first three lanes as a vector.
#[inline(always)]
unsafe fn unpack(v: __m256d) -> V3 {
    let mut out = [0.0; 4];
    _mm256_storeu_pd(out.as_mut_ptr(), v);
    V3::new(out[0], out[1], out[2])
}

#[inline(always)]
unsafe fn lane0(v: __m256d) -> f64 {
    _mm256_cvtsd_f64(v)
}

#[inline(always)]
unsafe fn lane1(v: __m256d) -> f64 {
    let low = _mm256_castpd256_pd128(v);
    _mm_cvtsd_f64(_mm_unpackhi_pd(low, low))
}

#[inline(always)]
unsafe fn lane2(v: __m256d) -> f64 {
    _mm_cvtsd_f64(_mm256_extractf128_pd::<1>(v))
}

#[inline(always)]
unsafe fn splat(x: f64) -> __m256d {
    _mm256_set1_pd(x)
}

/// The lanes of `v` as `IMM` picks them (two bits per lane, lane 0 lowest).
#[inline(always)]
unsafe fn splat_lane<const IMM: i32>(v: __m256d) -> __m256d {
    _mm256_permute4x64_pd::<IMM>(v)
}

const LANE0: i32 = 0b00_00_00_00;
const LANE1: i32 = 0b01_01_01_01;

/// `-(a b) + c` lane by lane with one rounding: the scalar `madd(-a, b, c)` (the negation is
/// exact).
#[inline(always)]
unsafe fn fnmadd(a: __m256d, b: __m256d, c: __m256d) -> __m256d {
    _mm256_fnmadd_pd(a, b, c)
}

#[inline(always)]
unsafe fn fmadd(a: __m256d, b: __m256d, c: __m256d) -> __m256d {
    _mm256_fmadd_pd(a, b, c)
}

#[inline(always)]
unsafe fn mul(a: __m256d, b: __m256d) -> __m256d {
    _mm256_mul_pd(a, b)
}

/// `B` of three columns back to its six entries.
#[inline(always)]
unsafe fn to_sym3(c0: __m256d, c1: __m256d, c2: __m256d) -> Sym3 {
    let (a, b, c) = (unpack(c0), unpack(c1), unpack(c2));
    Sym3 {
        xx: a.x,
        yy: b.y,
        zz: c.z,
        xy: a.y,
        xz: a.z,
        yz: b.z,
    }
}

/// [`super::backward`]'s scalar loop four lanes wide; the same results bit for bit.
///
/// # Safety
/// The processor must have AVX2 and FMA ([`crate::arith::has_avx2_fma`]).
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn backward(
    time: f64,
    c: &ChainConstants,
    chain: &ChainState,
    work: &mut [Articulated],
    want_tensions: bool,
) -> Result<(Sym3, V3)> {
    let n = chain.segments();
    let (l, m) = (c.l, c.m);
    let inv_l = 1.0 / l;
    let m6 = m / 6.0;
    let d = c.tip_mass + 0.5 * m;
    let (mut c0, mut c1, mut c2) = (pack(d, 0.0, 0.0), pack(0.0, d, 0.0), pack(0.0, 0.0, d));
    let tip = chain.tip_force;
    let mut bias = pack(tip.x, tip.y, tip.z);
    let mass = splat(m);
    let (inv_l_v, neg_l) = (splat(inv_l), splat(-l));
    let (force, reduced, w) = (chain.force.view(n), chain.reduced.view(n), chain.w.view(n));
    let (ep, es) = (chain.e_phi.view(n), chain.e_psi.view(n));
    let cos_psi = &chain.cos_psi[..n];
    let work = &mut work[..n];
    for k in (1..n).rev() {
        let (epx, epz) = (ep.x[k], ep.z[k]);
        let (esx, esy, esz) = (es.x[k], es.y[k], es.z[k]);
        let cp = cos_psi[k];
        // B E_phi (E_phi has no y) and B E_psi, column by column.
        let bep = fmadd(c0, splat(epx), mul(c2, splat(epz)));
        let bes = fmadd(c0, splat(esx), fmadd(c1, splat(esy), mul(c2, splat(esz))));
        let bw = fmadd(
            c0,
            splat(w.x[k]),
            fmadd(c1, splat(w.y[k]), mul(c2, splat(w.z[k]))),
        );
        // The bases of the update, B + m 1: the mass on one lane by a blend.
        let base0 = _mm256_blend_pd::<0b0001>(c0, _mm256_add_pd(c0, mass));
        let base1 = _mm256_blend_pd::<0b0010>(c1, _mm256_add_pd(c1, mass));
        let base2 = _mm256_blend_pd::<0b0100>(c2, _mm256_add_pd(c2, mass));
        let (bep_x, bep_z) = (lane0(bep), lane2(bep));
        let (bes_x, bes_y, bes_z) = (lane0(bes), lane1(bes), lane2(bes));
        let k00 = (-m6 * cp).mul_add(cp, epx.mul_add(bep_x, epz * bep_z));
        let k01 = epx.mul_add(bes_x, epz * bes_z);
        let k11 = esx.mul_add(bes_x, esy.mul_add(bes_y, esz * bes_z)) - m6;
        let neg_k01 = splat(-k01);
        let a0 = fmadd(bes, neg_k01, mul(bep, splat(k11)));
        let a1 = fmadd(bep, neg_k01, mul(bes, splat(k00)));
        let det = k00.mul_add(k11, -(k01 * k01));
        if det.is_nan() || det <= 0.0 {
            return Err(singular(time, k + 1));
        }
        let inv = 1.0 / det;
        let inv_v = splat(inv);
        let v = fmadd(
            bias,
            inv_l_v,
            _mm256_sub_pd(pack(reduced.x[k], reduced.y[k], reduced.z[k]), bw),
        );
        let (v_x, v_y, v_z) = (lane0(v), lane1(v), lane2(v));
        let r0 = epx.mul_add(v_x, epz * v_z);
        let r1 = esx.mul_add(v_x, esy.mul_add(v_y, esz * v_z));
        let y0 = k11.mul_add(r0, -(k01 * r1)) * inv;
        let y1 = k00.mul_add(r1, -(k01 * r0)) * inv;
        let t = fmadd(bep, splat(y0), fmadd(bes, splat(y1), bw));
        bias = fmadd(
            t,
            neg_l,
            _mm256_add_pd(pack(force.x[k], force.y[k], force.z[k]), bias),
        );
        // B' = B + m 1 - W (B E)^T, entry (i, j), i <= j: fma(-fma(a0_i, be_j, a1_i be'_j),
        // 1/det, B_ij). Column x with i = x broadcast, column z with j = z broadcast (every
        // lane has i <= z); column y with i = y broadcast for yy and yz, and xy from column x.
        let n0 = fnmadd(
            fmadd(
                splat_lane::<LANE0>(a0),
                bep,
                mul(splat_lane::<LANE0>(a1), bes),
            ),
            inv_v,
            base0,
        );
        let n1 = fnmadd(
            fmadd(
                splat_lane::<LANE1>(a0),
                bep,
                mul(splat_lane::<LANE1>(a1), bes),
            ),
            inv_v,
            base1,
        );
        let n2 = fnmadd(fmadd(a0, splat(bep_z), mul(a1, splat(bes_z))), inv_v, base2);
        // Column y's lane x is column x's lane y (a swap within the low half).
        (c0, c1, c2) = (
            n0,
            _mm256_blend_pd::<0b0001>(n1, _mm256_permute_pd::<0b0101>(n0)),
            n2,
        );
        // l G = W^T.
        let art = &mut work[k];
        _mm256_storeu_pd(art.lg[0].as_mut_ptr(), mul(a0, inv_v));
        _mm256_storeu_pd(art.lg[1].as_mut_ptr(), mul(a1, inv_v));
        art.y = [y0, y1];
        if want_tensions {
            art.inertia = to_sym3(c0, c1, c2);
            art.bias = unpack(bias);
        }
    }
    Ok((to_sym3(c0, c1, c2), unpack(bias)))
}
