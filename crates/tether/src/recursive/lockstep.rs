//! [`super::solve`] for four chains at once, one per AVX2 lane ("lockstep"): the backward sweep,
//! the root's 3x3 system and the forward sweep of four independent tethers (four envs of a
//! batch) run as one stream of four-wide instructions.
//!
//! One chain's sweeps are a chain of dependent operations (`B_{k+1}` -> `B E` -> `K` -> `det`
//! -> `1/det` -> `B_k`, then `a_k` -> `a_{k+1}` forward): about 28 ns a segment on a Zen 3 core,
//! bound by latency, not by the instruction count. Four chains in lockstep fill those waits with
//! each other's work: about 10 ns per chain and segment against 28 alone, plus about 5 for
//! packing the inputs into lanes (`load_lanes`, 4x4 transposes; BENCHMARKS.md, ninth session).
//!
//! Bit for bit: lane j computes exactly the operations of [`super::solve`] with fused
//! multiply-adds ([`crate::arith::Fused`], what the single-chain path runs on a processor with
//! AVX2 and FMA) for chain j: the same operands in the same order, `fma(a, b, c)` for
//! `M::madd(a, b, c)`, a separate multiply, add or divide where the scalar code has one, negation
//! by flipping the sign bit, and the zero y component of `E_phi` kept as an operand where the
//! scalar code multiplies by it. Lanes never mix, so a lane whose chain fails (a singular mass
//! matrix, NaN) leaves the others untouched; its error is the one the scalar solve would return.
//! Each chain brings its own constants (segment length and mass, tip mass, elongation spring),
//! so four tethers of different configurations with the same number of segments step together.
//!
//! `dynamics::tests::lockstep_solve_is_bitwise_four_single_solves` compares the accelerations
//! and axial masses with four single solves on random bent, folded and spinning states, and the
//! errors of singular lanes.

use std::arch::x86_64::*;
use std::ops::{Add, Mul, Neg, Sub};

use super::{singular, ChainConstants};
use crate::chain::ChainState;
use crate::error::Result;

/// Four f64, one per chain.
#[derive(Clone, Copy)]
pub(crate) struct X4(__m256d);

impl X4 {
    #[inline(always)]
    fn splat(v: f64) -> Self {
        unsafe { X4(_mm256_set1_pd(v)) }
    }

    /// Lane j from `f(j)`.
    #[inline(always)]
    fn gather(f: impl Fn(usize) -> f64) -> Self {
        unsafe { X4(_mm256_set_pd(f(3), f(2), f(1), f(0))) }
    }

    #[inline(always)]
    fn lanes(self) -> [f64; 4] {
        let mut out = [0.0; 4];
        unsafe { _mm256_storeu_pd(out.as_mut_ptr(), self.0) };
        out
    }

    /// `a b + c` with one rounding (`M::madd` with `Fused`).
    #[inline(always)]
    fn madd(a: X4, b: X4, c: X4) -> X4 {
        unsafe { X4(_mm256_fmadd_pd(a.0, b.0, c.0)) }
    }

    #[inline(always)]
    fn div(self, o: X4) -> X4 {
        unsafe { X4(_mm256_div_pd(self.0, o.0)) }
    }

    /// Per lane: not greater than zero, or NaN (`!(x > 0)`), as a 4-bit mask.
    #[inline(always)]
    fn not_positive(self) -> u32 {
        unsafe {
            let gt = _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, _mm256_setzero_pd());
            (!_mm256_movemask_pd(gt) & 0b1111) as u32
        }
    }
}

impl Add for X4 {
    type Output = X4;
    #[inline(always)]
    fn add(self, o: X4) -> X4 {
        unsafe { X4(_mm256_add_pd(self.0, o.0)) }
    }
}

impl Sub for X4 {
    type Output = X4;
    #[inline(always)]
    fn sub(self, o: X4) -> X4 {
        unsafe { X4(_mm256_sub_pd(self.0, o.0)) }
    }
}

impl Mul for X4 {
    type Output = X4;
    #[inline(always)]
    fn mul(self, o: X4) -> X4 {
        unsafe { X4(_mm256_mul_pd(self.0, o.0)) }
    }
}

impl Neg for X4 {
    type Output = X4;
    #[inline(always)]
    fn neg(self) -> X4 {
        unsafe { X4(_mm256_xor_pd(self.0, _mm256_set1_pd(-0.0))) }
    }
}

type V = [X4; 3];

#[inline(always)]
fn dot(a: &V, b: &V) -> X4 {
    X4::madd(a[0], b[0], X4::madd(a[1], b[1], a[2] * b[2]))
}

/// `a . b` for `a` with a zero y component, given as (x, z).
#[inline(always)]
fn dot_xz(a: &[X4; 2], b: &V) -> X4 {
    X4::madd(a[0], b[0], a[1] * b[2])
}

/// `a s + y`.
#[inline(always)]
fn axpy(a: &V, s: X4, y: &V) -> V {
    [
        X4::madd(a[0], s, y[0]),
        X4::madd(a[1], s, y[1]),
        X4::madd(a[2], s, y[2]),
    ]
}

#[inline(always)]
fn scale(a: &V, s: X4) -> V {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline(always)]
fn add3(a: &V, b: &V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline(always)]
fn sub3(a: &V, b: &V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// A symmetric 3x3 by its entries xx, yy, zz, xy, xz, yz ([`super::Sym3`]).
type S3 = [X4; 6];

#[inline(always)]
fn sym_mul(b: &S3, v: &V) -> V {
    [
        X4::madd(b[0], v[0], X4::madd(b[3], v[1], b[4] * v[2])),
        X4::madd(b[3], v[0], X4::madd(b[1], v[1], b[5] * v[2])),
        X4::madd(b[4], v[0], X4::madd(b[5], v[1], b[2] * v[2])),
    ]
}

/// `b v` for `v` with a zero y component, given as (x, z).
#[inline(always)]
fn sym_mul_xz(b: &S3, v: &[X4; 2]) -> V {
    [
        X4::madd(b[0], v[0], b[4] * v[1]),
        X4::madd(b[3], v[0], b[5] * v[1]),
        X4::madd(b[4], v[0], b[2] * v[1]),
    ]
}

/// Where each per-segment input of the sweeps sits in [`Articulated4::inputs`].
const EP_X: usize = 0;
const EP_Z: usize = 1;
const ES: usize = 2;
const W: usize = 5;
const FORCE: usize = 8;
const REDUCED: usize = 11;
const COS_PSI: usize = 14;
const INPUTS: usize = 15;

/// Per segment: the sweeps' inputs of the four chains side by side (lane j for chain j, copied
/// in before the sweeps, so that the sweeps read each as one four-wide load from one place
/// rather than from 4 x 15 separate arrays), and what the backward sweep leaves for the forward
/// sweep (the rows of `l G_k` and `y_k`).
#[derive(Clone, Copy, Default)]
pub(crate) struct Articulated4 {
    inputs: [[f64; 4]; INPUTS],
    lg: [[[f64; 4]; 3]; 2],
    y: [[f64; 4]; 2],
}

impl std::fmt::Debug for Articulated4 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Articulated4").finish_non_exhaustive()
    }
}

#[inline(always)]
fn load(v: &[f64; 4]) -> X4 {
    unsafe { X4(_mm256_loadu_pd(v.as_ptr())) }
}

#[inline(always)]
fn store(out: &mut [f64; 4], v: X4) {
    unsafe { _mm256_storeu_pd(out.as_mut_ptr(), v.0) }
}

#[inline(always)]
fn load3(v: &[[f64; 4]]) -> V {
    [load(&v[0]), load(&v[1]), load(&v[2])]
}

/// Copies the inputs of the sweeps and the root of four chains (of `n` segments each) into
/// the lanes of `work` (sized by [`Work4::ensure`]), lane j from chain j; [`solve4`] reads them
/// from there. Four segments of four chains at a time: four loads, a 4x4 transpose in
/// registers, four stores.
///
/// # Safety
/// The processor must have AVX2 ([`crate::arith::has_avx2_fma`]).
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn load_lanes(chains: [&ChainState; 4], work: &mut Work4) {
    let n = chains[0].segments();
    let segments = &mut work.segments[..n];
    let sources: [(usize, [&[f64]; 4]); INPUTS] = [
        (EP_X, chains.map(|c| &c.e_phi.x[..n])),
        (EP_Z, chains.map(|c| &c.e_phi.z[..n])),
        (ES, chains.map(|c| &c.e_psi.x[..n])),
        (ES + 1, chains.map(|c| &c.e_psi.y[..n])),
        (ES + 2, chains.map(|c| &c.e_psi.z[..n])),
        (W, chains.map(|c| &c.w.x[..n])),
        (W + 1, chains.map(|c| &c.w.y[..n])),
        (W + 2, chains.map(|c| &c.w.z[..n])),
        (FORCE, chains.map(|c| &c.force.x[..n])),
        (FORCE + 1, chains.map(|c| &c.force.y[..n])),
        (FORCE + 2, chains.map(|c| &c.force.z[..n])),
        (REDUCED, chains.map(|c| &c.reduced.x[..n])),
        (REDUCED + 1, chains.map(|c| &c.reduced.y[..n])),
        (REDUCED + 2, chains.map(|c| &c.reduced.z[..n])),
        (COS_PSI, chains.map(|c| &c.cos_psi[..n])),
    ];
    let whole = n / 4 * 4;
    for (slot, [a, b, c, d]) in sources {
        for k in (0..whole).step_by(4) {
            let rows = [
                _mm256_loadu_pd(a[k..k + 4].as_ptr()),
                _mm256_loadu_pd(b[k..k + 4].as_ptr()),
                _mm256_loadu_pd(c[k..k + 4].as_ptr()),
                _mm256_loadu_pd(d[k..k + 4].as_ptr()),
            ];
            // Row j holds chain j's segments k .. k + 3; column i, segment k + i's four lanes.
            let t0 = _mm256_unpacklo_pd(rows[0], rows[1]);
            let t1 = _mm256_unpackhi_pd(rows[0], rows[1]);
            let t2 = _mm256_unpacklo_pd(rows[2], rows[3]);
            let t3 = _mm256_unpackhi_pd(rows[2], rows[3]);
            let columns = [
                _mm256_permute2f128_pd::<0x20>(t0, t2),
                _mm256_permute2f128_pd::<0x20>(t1, t3),
                _mm256_permute2f128_pd::<0x31>(t0, t2),
                _mm256_permute2f128_pd::<0x31>(t1, t3),
            ];
            for (i, column) in columns.into_iter().enumerate() {
                _mm256_storeu_pd(segments[k + i].inputs[slot].as_mut_ptr(), column);
            }
        }
        for k in whole..n {
            segments[k].inputs[slot] = [a[k], b[k], c[k], d[k]];
        }
    }
    let root = &mut work.root;
    for (j, chain) in chains.iter().enumerate() {
        let (e, e_dot, extra) = (chain.e.get(0), chain.e_dot.get(0), chain.extra.get(0));
        for c in 0..3 {
            root.e[c][j] = e[c];
            root.e_dot[c][j] = e_dot[c];
            root.extra[c][j] = extra[c];
            root.tip_force[c][j] = chain.tip_force[c];
        }
        root.ep_y[j] = chain.e_phi.y[0];
    }
}

/// What the root's 3x3 system reads of four chains besides segment 1's sweep inputs: segment
/// 1's direction, the y component of its `E_phi` (zero, kept as an operand), its rate and its
/// `X`, and the force on the tip.
#[derive(Clone, Copy, Default)]
pub(crate) struct Root4 {
    e: [[f64; 4]; 3],
    ep_y: [f64; 4],
    e_dot: [[f64; 4]; 3],
    extra: [[f64; 4]; 3],
    tip_force: [[f64; 4]; 3],
}

/// The lockstep solve's work space: per segment the inputs and the backward sweep's results,
/// and the root's inputs.
#[derive(Clone, Default)]
pub(crate) struct Work4 {
    segments: Vec<Articulated4>,
    root: Root4,
}

impl std::fmt::Debug for Work4 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Work4")
            .field("segments", &self.segments.len())
            .finish_non_exhaustive()
    }
}

impl Work4 {
    /// Sized for `n` segments (allocates only when `n` grows).
    pub(crate) fn ensure(&mut self, n: usize) {
        if self.segments.len() < n {
            self.segments.resize(n, Articulated4::default());
        }
    }
}

/// [`super::solve`] (without tensions) for four chains of `n` segments each, lane j for chain j,
/// bit for bit the fused single-chain solve, from the inputs [`load_lanes`] put into `work`
/// (lane j from chain j). Writes `q''`
/// into `qdd[j]` and returns per chain its effective axial mass or the error of its solve; the
/// accelerations of a failed chain are unspecified.
///
/// # Safety
/// The processor must have AVX2 and FMA ([`crate::arith::has_avx2_fma`]).
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn solve4(
    time: [f64; 4],
    c: [&ChainConstants; 4],
    n: usize,
    s: [f64; 4],
    sd: [f64; 4],
    work: &mut Work4,
    qdd: [&mut [f64]; 4],
) -> [Result<f64>; 4] {
    let root = &work.root;
    let work = &mut work.segments[..n];
    let [q0, q1, q2, q3] = qdd;
    let qdd = [
        &mut q0[..2 * n + 1],
        &mut q1[..2 * n + 1],
        &mut q2[..2 * n + 1],
        &mut q3[..2 * n + 1],
    ];
    let l = X4::gather(|j| c[j].l);
    let m = X4::gather(|j| c[j].m);
    let inv_l = X4::gather(|j| 1.0 / c[j].l);
    let m6 = X4::gather(|j| c[j].m / 6.0);
    let zero = X4::splat(0.0);

    // Backward sweep (super::backward's scalar loop), tip to segment 2. A lane whose
    // determinant is not positive (or NaN) keeps the first segment that failed, as the scalar
    // sweep returns there.
    let mut failed: [Option<usize>; 4] = [None; 4];
    let d = X4::gather(|j| c[j].tip_mass + 0.5 * c[j].m);
    let mut bm: S3 = [d, d, d, zero, zero, zero];
    let mut bias: V = load3(&root.tip_force);
    for k in (1..n).rev() {
        let i = &work[k].inputs;
        let ep = [load(&i[EP_X]), load(&i[EP_Z])];
        let (es, w) = (load3(&i[ES..]), load3(&i[W..]));
        let (force, reduced) = (load3(&i[FORCE..]), load3(&i[REDUCED..]));
        let cos_psi = load(&i[COS_PSI]);
        let bep = sym_mul_xz(&bm, &ep);
        let bes = sym_mul(&bm, &es);
        let k00 = X4::madd(-(m6 * cos_psi), cos_psi, dot_xz(&ep, &bep));
        let k01 = dot_xz(&ep, &bes);
        let k11 = dot(&es, &bes) - m6;
        let a0 = axpy(&bes, -k01, &scale(&bep, k11));
        let a1 = axpy(&bep, -k01, &scale(&bes, k00));
        let det = X4::madd(k00, k11, -(k01 * k01));
        let bad = det.not_positive();
        if bad != 0 {
            for (j, f) in failed.iter_mut().enumerate() {
                if bad & (1 << j) != 0 && f.is_none() {
                    *f = Some(k + 1);
                }
            }
        }
        let inv = X4::splat(1.0).div(det);
        let bw = sym_mul(&bm, &w);
        let v = axpy(&bias, inv_l, &sub3(&reduced, &bw));
        let (r0, r1) = (dot_xz(&ep, &v), dot(&es, &v));
        let y0 = X4::madd(k11, r0, -(k01 * r1)) * inv;
        let y1 = X4::madd(k00, r1, -(k01 * r0)) * inv;
        let t = axpy(&bep, y0, &axpy(&bes, y1, &bw));
        bias = axpy(&t, -l, &add3(&force, &bias));
        let upd =
            |a: X4, b: X4, c: X4, d: X4, base: X4| X4::madd(-X4::madd(a, b, c * d), inv, base);
        bm = [
            upd(a0[0], bep[0], a1[0], bes[0], bm[0] + m),
            upd(a0[1], bep[1], a1[1], bes[1], bm[1] + m),
            upd(a0[2], bep[2], a1[2], bes[2], bm[2] + m),
            upd(a0[0], bep[1], a1[0], bes[1], bm[3]),
            upd(a0[0], bep[2], a1[0], bes[2], bm[4]),
            upd(a0[1], bep[2], a1[1], bes[2], bm[5]),
        ];
        let art = &mut work[k];
        for (row, a) in art.lg.iter_mut().zip([a0, a1]) {
            for (out, v) in row.iter_mut().zip(scale(&a, inv)) {
                store(out, v);
            }
        }
        store(&mut art.y[0], y0);
        store(&mut art.y[1], y1);
    }

    // Root: s and segment 1's angles (super::solve's root, lane by lane).
    let half_m = X4::gather(|j| 0.5 * c[j].m);
    let a_mat: S3 = [
        bm[0] - half_m,
        bm[1] - half_m,
        bm[2] - half_m,
        bm[3],
        bm[4],
        bm[5],
    ];
    let b_vec = bias;
    let i = &work[0].inputs;
    let force = load3(&i[FORCE..]);
    let extra = load3(&root.extra);
    let e1 = load3(&root.e);
    let ep1 = [load(&i[EP_X]), load(&root.ep_y), load(&i[EP_Z])];
    let es1 = load3(&i[ES..]);
    let w = load3(&i[W..]);
    let cos_psi0 = load(&i[COS_PSI]);
    let cos2 = cos_psi0 * cos_psi0;
    let (s_v, sd_v) = (X4::gather(|j| s[j]), X4::gather(|j| sd[j]));
    let (rho_c, rho_t) = (s_v + X4::splat(0.5) * l, s_v + l);
    let (ae, aep, aes) = (
        sym_mul(&a_mat, &e1),
        sym_mul(&a_mat, &ep1),
        sym_mul(&a_mat, &es1),
    );
    let rod_inertia = X4::gather(|j| c[j].rod_inertia);
    let own = m * rho_c * rho_c + rod_inertia;
    let rho_t2 = rho_t * rho_t;
    let m11 = m + dot(&e1, &ae);
    let m12 = rho_t * dot(&e1, &aep);
    let m13 = rho_t * dot(&e1, &aes);
    let m22 = X4::madd(own, cos2, rho_t2 * dot(&ep1, &aep));
    let m23 = rho_t2 * dot(&ep1, &aes);
    let m33 = X4::madd(rho_t2, dot(&es1, &aes), own);
    let drift = scale(&load3(&root.e_dot), X4::splat(2.0) * sd_v);
    let c0 = axpy(&w, rho_c, &drift);
    let t0 = axpy(&w, rho_t, &drift);
    let f1 = axpy(&c0, -m, &force);
    let f2 = sub3(&b_vec, &sym_mul(&a_mat, &t0));
    let moment = axpy(&f1, rho_c, &axpy(&f2, rho_t, &extra));
    let (k_v, c_s) = (X4::gather(|j| c[j].k), X4::gather(|j| c[j].c_s));
    let r0 = dot(&e1, &add3(&f1, &f2)) - X4::madd(k_v, s_v, c_s * sd_v);
    let (r1, r2) = (dot(&ep1, &moment), dot(&es1, &moment));
    let d1 = m11;
    let (l21, l31) = (m12.div(d1), m13.div(d1));
    let d2 = X4::madd(-l21, m12, m22);
    let l32 = X4::madd(-l31, m12, m23).div(d2);
    let d3 = X4::madd(-(l32 * l32), d2, X4::madd(-l31, m13, m33));
    let root_bad = d1.not_positive() | d2.not_positive() | d3.not_positive();
    // root_axial_mass, lane by lane.
    let det = m22 * m33 - m23 * m23;
    let quad = m33 * m12 * m12 - X4::splat(2.0) * m23 * m12 * m13 + m22 * m13 * m13;
    let axial_mass = (m11 - quad.div(det)).lanes();
    let y2 = X4::madd(-l21, r0, r1);
    let y3 = X4::madd(-l32, y2, X4::madd(-l31, r0, r2));
    let z2 = y3.div(d3);
    let z1 = X4::madd(-l32, z2, y2.div(d2));
    let z0 = X4::madd(-l31, z2, X4::madd(-l21, z1, r0.div(d1)));
    for (i, z) in [z0, z1, z2].iter().enumerate() {
        let z = z.lanes();
        for j in 0..4 {
            qdd[j][i] = z[j];
        }
    }
    let e1dd_ang = axpy(&ep1, z1, &scale(&es1, z2));
    let mut acc = axpy(&e1dd_ang, rho_t, &axpy(&e1, z0, &t0));

    // Forward sweep.
    let neg_inv_l = -inv_l;
    for k in 1..n {
        let art = &work[k];
        let (lg0, lg1) = (load3(&art.lg[0]), load3(&art.lg[1]));
        let (y0, y1) = (load(&art.y[0]), load(&art.y[1]));
        let i = &art.inputs;
        let (d0, d1) = (dot(&lg0, &acc), dot(&lg1, &acc));
        let u0 = X4::madd(neg_inv_l, d0, y0).lanes();
        let u1 = X4::madd(neg_inv_l, d1, y1).lanes();
        for j in 0..4 {
            qdd[j][1 + 2 * k] = u0[j];
            qdd[j][2 + 2 * k] = u1[j];
        }
        let ep = [load(&i[EP_X]), zero, load(&i[EP_Z])];
        let (es, w) = (load3(&i[ES..]), load3(&i[W..]));
        let phi = axpy(&ep, y0, &axpy(&es, y1, &w));
        let shifted = axpy(&phi, l, &acc);
        acc = axpy(&ep, -d0, &axpy(&es, -d1, &shifted));
    }

    std::array::from_fn(|j| match failed[j] {
        Some(segment) => Err(singular(time[j], segment)),
        None if root_bad & (1 << j) != 0 => Err(singular(time[j], 1)),
        None => Ok(axial_mass[j]),
    })
}
