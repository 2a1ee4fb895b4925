//! The lane type of four chains solved together, one per AVX2 lane ([`X4`]), and their inputs
//! side by side ([`Work4`]): [`super::sweeps`] over it runs the backward sweep, the root's 3x3
//! system and the forward sweep of four independent tethers (four envs of a batch) as one stream
//! of four-wide instructions.
//!
//! Bit for bit: every operation acts lane by lane and rounds as its `f64` counterpart with fused
//! multiply-adds ([`crate::arith::Fused`], what the single-chain path runs on a processor with
//! AVX2 and FMA); negation flips the sign bit. Lanes never mix, so a lane whose chain fails (a
//! singular mass matrix, NaN) leaves the others untouched. Each chain brings its own constants
//! (segment length and mass, tip mass, elongation spring), so four tethers of different
//! configurations with the same number of segments step together.
//!
//! `dynamics::tests::lockstep_solve_is_bitwise_four_single_solves` compares the accelerations
//! and axial masses with four single solves on random bent, folded and spinning states, and the
//! errors of singular lanes.

use std::arch::x86_64::*;
use std::ops::{Add, Mul, Neg, Sub};

use super::{sweeps, Articulated, ChainConstants, Inputs, Lane, Spring, V};
use crate::chain::ChainState;
use crate::error::Result;

/// Four f64, one per chain.
#[derive(Clone, Copy)]
pub(crate) struct X4(__m256d);

impl Lane for X4 {
    const LANES: usize = 4;
    type Stored = [f64; 4];

    #[inline(always)]
    fn gather(f: impl Fn(usize) -> f64) -> Self {
        unsafe { X4(_mm256_set_pd(f(3), f(2), f(1), f(0))) }
    }

    #[inline(always)]
    fn splat(v: f64) -> Self {
        unsafe { X4(_mm256_set1_pd(v)) }
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

    #[inline(always)]
    fn not_positive(self) -> u32 {
        unsafe {
            let gt = _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, _mm256_setzero_pd());
            (!_mm256_movemask_pd(gt) & 0b1111) as u32
        }
    }

    #[inline(always)]
    fn write(self, out: &mut [f64]) {
        let out = &mut out[..4];
        unsafe { _mm256_storeu_pd(out.as_mut_ptr(), self.0) }
    }

    #[inline(always)]
    fn store(self) -> [f64; 4] {
        let mut out = [0.0; 4];
        self.write(&mut out);
        out
    }

    #[inline(always)]
    fn load(stored: &[f64; 4]) -> Self {
        unsafe { X4(_mm256_loadu_pd(stored.as_ptr())) }
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

/// Where each per-segment input of the sweeps sits in a [`Segment4`].
const EP_X: usize = 0;
const EP_Z: usize = 1;
const ES: usize = 2;
const W: usize = 5;
const FORCE: usize = 8;
const REDUCED: usize = 11;
const COS_PSI: usize = 14;
const INPUTS: usize = 15;

/// Per segment: the sweeps' inputs of the four chains side by side, lane j for chain j, copied
/// in before the sweeps, so that the sweeps read each as one four-wide load from one place
/// rather than from 4 x 15 separate arrays.
type Segment4 = [[f64; 4]; INPUTS];

#[inline(always)]
fn load(v: &[f64; 4]) -> X4 {
    unsafe { X4(_mm256_loadu_pd(v.as_ptr())) }
}

#[inline(always)]
fn load3(v: &[[f64; 4]]) -> V<X4> {
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
                _mm256_storeu_pd(segments[k + i][slot].as_mut_ptr(), column);
            }
        }
        for k in whole..n {
            segments[k][slot] = [a[k], b[k], c[k], d[k]];
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
    segments: Vec<Segment4>,
    articulated: Vec<Articulated<[f64; 4]>>,
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
            self.segments.resize(n, Segment4::default());
            self.articulated.resize(n, Articulated::default());
        }
    }
}

/// The inputs of four chains side by side, as [`load_lanes`] left them.
struct Inputs4<'a> {
    segments: &'a [Segment4],
    root: &'a Root4,
}

impl Inputs<X4> for Inputs4<'_> {
    #[inline(always)]
    fn directions(&self, k: usize) -> ([X4; 2], V<X4>, V<X4>) {
        let i = &self.segments[k];
        (
            [load(&i[EP_X]), load(&i[EP_Z])],
            load3(&i[ES..]),
            load3(&i[W..]),
        )
    }

    #[inline(always)]
    fn loads(&self, k: usize) -> (V<X4>, V<X4>, X4) {
        let i = &self.segments[k];
        (load3(&i[FORCE..]), load3(&i[REDUCED..]), load(&i[COS_PSI]))
    }

    #[inline(always)]
    fn root(&self) -> [V<X4>; 4] {
        let (r, i) = (self.root, &self.segments[0]);
        let ep = [load(&i[EP_X]), load(&r.ep_y), load(&i[EP_Z])];
        [load3(&r.e), ep, load3(&r.e_dot), load3(&r.extra)]
    }

    #[inline(always)]
    fn tip_force(&self) -> V<X4> {
        load3(&self.root.tip_force)
    }
}

/// [`super::solve`] (without tensions) for four chains of `n` segments each, lane j for chain j,
/// bit for bit the fused single-chain solve, from the inputs [`load_lanes`] put into `work`.
/// Writes `q''` into `qdd[j]` and returns per chain its effective axial mass or the error of its
/// solve; the accelerations of a failed chain are unspecified.
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
    let inputs = Inputs4 {
        segments: &work.segments[..n],
        root: &work.root,
    };
    let springs = std::array::from_fn(|j| Spring {
        s: s[j],
        sd: sd[j],
        added_mass: 0.0,
    });
    let solved = sweeps::<4, X4, _>(
        c,
        &inputs,
        n,
        s,
        sd,
        springs,
        &mut work.articulated,
        qdd,
        &mut (),
    );
    std::array::from_fn(|j| solved.result(time[j], j))
}
