//! O(n) solution of the tether's equations of motion `M(q) q'' = Q(t, q, q')` by an
//! articulated-body recursion over the chain, the hot path of [`crate::TetherModel::accelerations`].
//! The dense formulation of [`crate::dynamics`] (assemble `M`, Cholesky, O(n^3)) stays as the
//! test oracle; both use the same kinematics and loads.
//!
//! # The equations per segment
//! Write `b_k` for the inboard end (base) of segment k (0-based), `a_k = b_k''` for its
//! acceleration, `E_k = [E_phi E_psi]` (3x2) for the partials of its direction `e_k`, and
//! `e_k'' = w_k + E_k u_k` for the direction's acceleration, with `w_k` the convective part and
//! `u_k = (phi_k'', psi_k'')`. With `F_k` the external force on the centre, `X_k` the per-segment
//! vector of bending, joint damping and the rotational convective inertia `-I w_k` (the `extra` of
//! [`crate::dynamics`]), and `P_{k+1}` the force that everything outboard of the segment's outer
//! end exerts on it (`P_n = F_t - M_t a_n`, the tip body), the two equations of the angles of
//! segment k >= 1 are the projections of its moment balance about its base:
//!
//! ```text
//! E_k^T [ (l/2) (F_k - m c_k'') + l P_{k+1} + X_k - I E_k u_k ] = 0,
//! c_k'' = a_k + (l/2) e_k'',   a_{k+1} = a_k + l e_k''.
//! ```
//!
//! These are exactly the rows of the dense `M q'' = Q` (`Q_(k,b) = E_kb . G_k`, the suffix sums of
//! the dense `G_k` being the outboard forces `P_{k+1}` once the accelerations are included).
//!
//! # Backward sweep (tip to root): articulated inertias
//! Everything outboard of `b_k` reacts on its base linearly in the base's acceleration:
//! `P_k = b_k - A_k a_k` with `A_k` symmetric positive semi-definite (3x3). At the tip
//! `A_n = M_t 1`, `b_n = F_t`. Inserting `P_{k+1} = b_{k+1} - A_{k+1} a_{k+1}` into segment k's
//! equations, with
//!
//! ```text
//! C = (m l / 2) 1 + l A_{k+1},   D' = (m l^2 / 4) 1 + l^2 A_{k+1},   D = D' + I 1,
//! K = E^T D E (2x2, SPD),   r = (l/2) F_k + X_k + l b_{k+1},
//! ```
//!
//! gives `K u_k = E^T (r - D' w_k - C a_k)`, i.e. `u_k = y_k - G_k a_k` with
//! `y_k = K^-1 E^T (r - D' w_k)` and `G_k = K^-1 (C E)^T` (2x3), and summing the forces on the
//! segment, `P_k = F_k - m c_k'' + P_{k+1}`:
//!
//! ```text
//! A_k = A_{k+1} + m 1 - (C E) G_k,          (symmetric: (C E) K^-1 (C E)^T)
//! b_k = F_k + b_{k+1} - C w_k - (C E) y_k.
//! ```
//!
//! # Root: the elongation and segment 1 together
//! Segment 1 (k = 0) starts at `s e_1` and turns about the attachment point: its centre is at
//! `rho_c e` and its outer end at `rho_t e` with `rho_c = s + l/2`, `rho_t = s + l`. With the
//! three unknowns `z = (s'', phi_1'', psi_1'')` and the Jacobians
//! `J_c = [e, rho_c E]`, `J_t = [e, rho_t E]`, `J_r = [0, E]` of the centre, the outer end and the
//! direction, and biases `c0 = 2 s' e' + rho_c w`, `t0 = 2 s' e' + rho_t w`, Kane's equations are
//! the 3x3 SPD system
//!
//! ```text
//! (m J_c^T J_c + J_t^T A_1 J_t + I J_r^T J_r) z
//!     = J_c^T (F_1 - m c0) + J_t^T (b_1 - A_1 t0) + J_r^T X_1 - (k s + c_s s', 0, 0),
//! ```
//!
//! solved by LDL^T. (e, E_phi, E_psi are orthogonal with |E_phi| = cos psi, so
//! `J_c^T J_c = diag(1, rho_c^2 cos^2 psi, rho_c^2)` and `J_r^T J_r = diag(0, cos^2 psi, 1)`.)
//!
//! # Forward sweep (root to tip)
//! `a_1 = t0 + J_t z`, then for k >= 1: `u_k = y_k - G_k a_k`, `e_k'' = w_k + E_k u_k`,
//! `a_{k+1} = a_k + l e_k''`. The chain tensions come for free: the force on the base of
//! segment k is `P_k = b_k - A_k a_k`, its tension `P_k . e_k`.
//!
//! # As implemented
//! The same equations, arranged to be cheap:
//!
//! * The sweep carries `B = A + (m/2) 1` instead of `A`. Then `C = l B`, `D' = l^2 (B - (m/4) 1)`,
//!   `D = l^2 (B - (m/6) 1)`, and with `K^ = K / l^2 = E^T B E - (m/6) E^T E`:
//!
//!   ```text
//!   W   = (B E) K^-1                        (3x2; computed as (B E) adj(K^) / det K^)
//!   y_k = K^-1 E^T (r_k + b_{k+1} / l - B w_k),   r_k = F_k / (2l) + X_k / l^2 + (m/4) w_k
//!   l G_k = W^T
//!   B_k = B_{k+1} + m 1 - W (B E)^T
//!   b_k = F_k + b_{k+1} - l (B w_k + (B E) y_k)
//!   ```
//!
//!   starting from `B_n = (M_t + m/2) 1`, `b_n = F_t`; `r_k` does not depend on the outboard chain
//!   and comes from the vectorized loads pass (`chain.rs`).
//! * The forward step is `a_{k+1} = (a_k + l (w_k + E_k y_k)) - E_k (l G_k a_k)`, where
//!   `l G_k a_k` also gives `u_k`.
//! * The three steps are written over a lane type (`Lane`), of which one chain's `f64` (`One`)
//!   is the only one: several chains side by side in SIMD lanes (several envs of a batch
//!   stepped together) were measured and gained too little at the batch level to keep
//!   (docs/decisions.md, "Stepping envs in lockstep").
//! * Only the directions, loads and `K`, `W`, `y` live in the sweep; everything independent per
//!   segment (trigonometry, directions, rates, loads) is done beforehand in structure-of-arrays
//!   passes the compiler vectorizes. Every multiply-add is one fused multiply-add, on every
//!   processor (`arith.rs`).
//!
//! Each sweep costs O(1) per segment with fixed-size 3x3 / 2x2 algebra and no allocation.

use std::ops::{Add, Mul, Neg, Sub};

use nalgebra::Vector3;

use crate::arith::madd;
use crate::chain::ChainState;
use crate::error::{Result, TetherError};

type V3 = Vector3<f64>;

/// What the recursion needs of a number: one f64 ([`One`]), or several chains' values side by
/// side, one per lane. Every operation acts lane by lane and rounds as its `f64` counterpart.
pub(crate) trait Lane:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Neg<Output = Self>
{
    /// Number of lanes (chains solved together).
    const LANES: usize;
    /// What one lane of a stored value holds (`f64`, or the lanes side by side).
    type Stored: Copy + Default;

    /// Lane j from `f(j)`.
    fn gather(f: impl Fn(usize) -> f64) -> Self;
    /// Every lane `v`.
    fn splat(v: f64) -> Self;
    /// `a b + c`, fused or not as the lane type says.
    fn madd(a: Self, b: Self, c: Self) -> Self;
    /// `self / o`.
    fn div(self, o: Self) -> Self;
    /// Per lane: not greater than zero, or NaN (`!(x > 0)`), as a bit mask (bit j for lane j).
    fn not_positive(self) -> u32;
    /// The lanes, in order, into `out[..LANES]`.
    fn write(self, out: &mut [f64]);
    /// The lanes as stored.
    fn store(self) -> Self::Stored;
    /// The lanes from their stored form.
    fn load(stored: &Self::Stored) -> Self;
}

/// One chain's `f64`, with multiply-adds fused or not as `M` says.
#[derive(Clone, Copy)]
pub(crate) struct One(pub f64);

impl One {
    #[inline(always)]
    pub(crate) fn new(v: f64) -> Self {
        One(v)
    }
}

impl Add for One {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        One::new(self.0 + o.0)
    }
}

impl Sub for One {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        One::new(self.0 - o.0)
    }
}

impl Mul for One {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        One::new(self.0 * o.0)
    }
}

impl Neg for One {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        One::new(-self.0)
    }
}

impl Lane for One {
    const LANES: usize = 1;
    type Stored = f64;

    #[inline(always)]
    fn gather(f: impl Fn(usize) -> f64) -> Self {
        One::new(f(0))
    }
    #[inline(always)]
    fn splat(v: f64) -> Self {
        One::new(v)
    }
    #[inline(always)]
    fn madd(a: Self, b: Self, c: Self) -> Self {
        One::new(madd(a.0, b.0, c.0))
    }
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        One::new(self.0 / o.0)
    }
    #[inline(always)]
    fn not_positive(self) -> u32 {
        u32::from(self.0.is_nan() || self.0 <= 0.0)
    }
    #[inline(always)]
    fn write(self, out: &mut [f64]) {
        out[0] = self.0;
    }
    #[inline(always)]
    fn store(self) -> f64 {
        self.0
    }
    #[inline(always)]
    fn load(stored: &f64) -> Self {
        One::new(*stored)
    }
}

/// A 3-vector.
pub(crate) type V<L> = [L; 3];

/// A symmetric 3x3 matrix by its entries xx, yy, zz, xy, xz, yz.
pub(crate) type S3<L> = [L; 6];

#[inline(always)]
fn dot<L: Lane>(a: &V<L>, b: &V<L>) -> L {
    L::madd(a[0], b[0], L::madd(a[1], b[1], a[2] * b[2]))
}

/// `a . b` for `a` with a zero y component, given as (x, z).
#[inline(always)]
fn dot_xz<L: Lane>(a: &[L; 2], b: &V<L>) -> L {
    L::madd(a[0], b[0], a[1] * b[2])
}

/// `a s + y`.
#[inline(always)]
fn axpy<L: Lane>(a: &V<L>, s: L, y: &V<L>) -> V<L> {
    [
        L::madd(a[0], s, y[0]),
        L::madd(a[1], s, y[1]),
        L::madd(a[2], s, y[2]),
    ]
}

#[inline(always)]
fn scale<L: Lane>(a: &V<L>, s: L) -> V<L> {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline(always)]
fn add3<L: Lane>(a: &V<L>, b: &V<L>) -> V<L> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline(always)]
fn sub3<L: Lane>(a: &V<L>, b: &V<L>) -> V<L> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
fn sym_mul<L: Lane>(b: &S3<L>, v: &V<L>) -> V<L> {
    [
        L::madd(b[0], v[0], L::madd(b[3], v[1], b[4] * v[2])),
        L::madd(b[3], v[0], L::madd(b[1], v[1], b[5] * v[2])),
        L::madd(b[4], v[0], L::madd(b[5], v[1], b[2] * v[2])),
    ]
}

/// `b v` for `v` with a zero y component, given as (x, z).
#[inline(always)]
fn sym_mul_xz<L: Lane>(b: &S3<L>, v: &[L; 2]) -> V<L> {
    [
        L::madd(b[0], v[0], b[4] * v[1]),
        L::madd(b[3], v[0], b[5] * v[1]),
        L::madd(b[4], v[0], b[2] * v[1]),
    ]
}

/// What the backward sweep leaves per segment for the forward sweep: the rows of `l G_k` and
/// `y_k`, per lane.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Articulated<T> {
    lg: [[T; 3]; 2],
    y: [T; 2],
}

/// `B_k` and `b_k` per segment, kept for the tensions.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Held {
    inertia: [f64; 6],
    bias: [f64; 3],
}

/// The recursion's inputs of a chain (or of chains side by side): the per-segment directions
/// and loads and the root's, from the kinematics and loads pass.
pub(crate) trait Inputs<L: Lane> {
    /// Segment k's `E_phi` (x, z: its y component is zero), `E_psi` and convective `w`.
    fn directions(&self, k: usize) -> ([L; 2], V<L>, V<L>);
    /// Segment k's force `F_k`, reduced load `r_k` and `cos psi_k`.
    fn loads(&self, k: usize) -> (V<L>, V<L>, L);
    /// Segment 1's direction `e`, its full `E_phi` (the y component, zero, kept as an operand),
    /// its rate `e'` and its `X`.
    fn root(&self) -> [V<L>; 4];
    /// The force on the tip body.
    fn tip_force(&self) -> V<L>;
}

/// One chain's inputs, read from its [`ChainState`] (sliced to its `n` segments).
struct ChainInputs<'a> {
    chain: &'a ChainState,
    n: usize,
}

impl Inputs<One> for ChainInputs<'_> {
    #[inline(always)]
    fn directions(&self, k: usize) -> ([One; 2], V<One>, V<One>) {
        let (c, n) = (self.chain, self.n);
        let (ep, es, w) = (c.e_phi.view(n), c.e_psi.view(n), c.w.view(n));
        (
            [One::new(ep.x[k]), One::new(ep.z[k])],
            one3(es.x[k], es.y[k], es.z[k]),
            one3(w.x[k], w.y[k], w.z[k]),
        )
    }
    #[inline(always)]
    fn loads(&self, k: usize) -> (V<One>, V<One>, One) {
        let (c, n) = (self.chain, self.n);
        let (f, r) = (c.force.view(n), c.reduced.view(n));
        (
            one3(f.x[k], f.y[k], f.z[k]),
            one3(r.x[k], r.y[k], r.z[k]),
            One::new(c.cos_psi[..n][k]),
        )
    }
    #[inline(always)]
    fn root(&self) -> [V<One>; 4] {
        let c = self.chain;
        [&c.e, &c.e_phi, &c.e_dot, &c.extra].map(|v| {
            let v = v.get(0);
            one3(v.x, v.y, v.z)
        })
    }
    #[inline(always)]
    fn tip_force(&self) -> V<One> {
        let f = self.chain.tip_force;
        one3(f.x, f.y, f.z)
    }
}

#[inline(always)]
fn one3(x: f64, y: f64, z: f64) -> V<One> {
    [One::new(x), One::new(y), One::new(z)]
}

#[inline(always)]
fn to_v3(v: &V<One>) -> V3 {
    V3::new(v[0].0, v[1].0, v[2].0)
}

/// Constants of the chain that the recursion needs.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ChainConstants {
    pub l: f64,
    pub m: f64,
    pub rod_inertia: f64,
    pub tip_mass: f64,
    pub k: f64,
    pub c_s: f64,
}

/// The axial element's spring and damper as one solve sees them: the stretch and rate they are
/// evaluated at (the state's own in a right-hand side) and the mass added to the stretch's
/// diagonal of `M` (zero in a right-hand side; `gamma h c_s + (gamma h)^2 k` in a stage of a
/// linearly implicit step, [`crate::axial::AxialStage`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Spring {
    pub s: f64,
    pub sd: f64,
    pub added_mass: f64,
}

fn singular(time: f64, segment: usize) -> TetherError {
    TetherError::Diverged {
        time,
        reason: format!("mass matrix lost positive definiteness at segment {segment}"),
    }
}

/// Solves the equations of motion in O(n) from the kinematics and loads in `chain`: the backward
/// sweep (tip to root), the root's 3x3 system and the forward sweep, with the axial element's
/// force and added mass as `spring` gives them. Writes `q''` into `qdd` and, if given, the tensions (n + 1 values, as [`crate::TetherModel::tensions`]) into `tensions`
/// (`held`, n entries, holds what they need of the backward sweep). Returns the effective axial
/// mass `1 / (M^-1)_00`, kg (see [`Solved::result`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn solve(
    time: f64,
    c: &ChainConstants,
    chain: &ChainState,
    s: f64,
    sd: f64,
    spring: Spring,
    work: &mut [Articulated<f64>],
    held: &mut [Held],
    qdd: &mut [f64],
    tensions: Option<&mut [f64]>,
) -> Result<f64> {
    let n = chain.segments();
    let inputs = ChainInputs { chain, n };
    let qdd = &mut qdd[..2 * n + 1];
    let work = &mut work[..n];
    let held = &mut held[..n];
    let Some(t) = tensions else {
        let solved =
            sweeps::<1, One, _>([c], &inputs, n, [s], [sd], [spring], work, [qdd], &mut ());
        return solved.result(time, 0);
    };
    let mut watch = TensionWatch {
        held,
        chain,
        t: &mut t[..n + 1],
        half_m: 0.5 * c.m,
    };
    let solved = sweeps::<1, One, _>(
        [c],
        &inputs,
        n,
        [s],
        [sd],
        [spring],
        work,
        [qdd],
        &mut watch,
    );
    let axial_mass = solved.result(time, 0)?;
    let (r, t, m) = (&solved.root, watch.t, c.m);
    // The pull on segment 1's base: its load less its mass times its centre's acceleration, and
    // the outboard chain's reaction `b_1 - A_1 a_1`.
    let e1 = to_v3(&r.e1);
    let com = e1 * r.z0.0 + to_v3(&r.drift) + (to_v3(&r.w) + to_v3(&r.e1dd_ang)) * r.rho_c.0;
    let pull = to_v3(&r.force) - com * m + to_v3(&r.bias) - to_v3(&sym_mul(&r.a_mat, &r.acc1));
    t[0] = pull.dot(&e1);
    t[n] = (chain.tip_force - to_v3(&solved.acc) * c.tip_mass).dot(&chain.e.get(n - 1));
    Ok(axial_mass)
}

/// What [`sweeps`] shows of its steps, for the tensions: nothing by default.
pub(crate) trait Watch<L> {
    /// Backward step k's articulated inertia `B_k` and bias `b_k`.
    #[inline(always)]
    fn backward(&mut self, _k: usize, _bm: &S3<L>, _bias: &V<L>) {}
    /// Forward step k's base acceleration `a_k`, before the step.
    #[inline(always)]
    fn forward(&mut self, _k: usize, _acc: &V<L>) {}
}

impl<L> Watch<L> for () {}

/// The tensions of one chain: keeps `B_k` and `b_k` from the backward sweep, and writes segment
/// k's tension `P_k . e_k` in the forward sweep, `P_k = b_k - A_k a_k` with `A_k = B_k - (m/2) 1`.
struct TensionWatch<'a> {
    held: &'a mut [Held],
    chain: &'a ChainState,
    t: &'a mut [f64],
    half_m: f64,
}

impl Watch<One> for TensionWatch<'_> {
    #[inline(always)]
    fn backward(&mut self, k: usize, bm: &S3<One>, bias: &V<One>) {
        self.held[k] = Held {
            inertia: bm.map(|v| v.0),
            bias: bias.map(|v| v.0),
        };
    }

    #[inline(always)]
    fn forward(&mut self, k: usize, acc: &V<One>) {
        let h = &self.held[k];
        let inertia: S3<One> = h.inertia.map(One::new);
        let ba = to_v3(&sym_mul(&inertia, acc));
        let pull = V3::from(h.bias) - ba + to_v3(acc) * self.half_m;
        self.t[k] = pull.dot(&self.chain.e.get(k));
    }
}

/// What the root's step leaves for the tensions.
pub(crate) struct Root<L> {
    e1: V<L>,
    z0: L,
    drift: V<L>,
    w: V<L>,
    e1dd_ang: V<L>,
    rho_c: L,
    force: V<L>,
    bias: V<L>,
    a_mat: S3<L>,
    /// Segment 1's outer end's acceleration `a_1`.
    acc1: V<L>,
}

/// The result of [`sweeps`] for `N` lanes: per lane the first segment where the backward sweep
/// found the mass matrix singular and whether the root's system was, the axial masses, what the
/// root leaves for the tensions and the tip's acceleration.
pub(crate) struct Solved<const N: usize, L> {
    failed: [Option<usize>; N],
    root_bad: u32,
    axial_mass: [f64; N],
    root: Root<L>,
    acc: V<L>,
}

impl<const N: usize, L> Solved<N, L> {
    /// Lane j's effective axial mass `1 / (M^-1)_00`, kg, or the error of its solve at `time`.
    ///
    /// The backward sweep eliminates every outboard angle exactly, so the root matrix is the
    /// Schur complement of the outboard block of `M`, and by the block-inverse formula its
    /// inverse is the root block of `M^-1`: `(M^-1)_00 = (M_root^-1)_00`. Its reciprocal is in
    /// turn the Schur complement of segment 1's angle block in `M_root`:
    ///
    /// ```text
    /// 1 / (M^-1)_00 = m11 - [m12 m13] [[m22 m23] [m23 m33]]^-1 [m12 m13]^T.
    /// ```
    ///
    /// The axial damping `c_s` acts on s alone (a rank-one damping matrix `c_s e_0 e_0^T`), so
    /// `c_s (M^-1)_00` is exactly the rate of its damping mode. At least the segment mass
    /// (segment 1's centre moves at s' along e whatever the angle rates), which the root's
    /// positivity check keeps.
    pub(crate) fn result(&self, time: f64, j: usize) -> Result<f64> {
        match self.failed[j] {
            Some(segment) => Err(singular(time, segment)),
            None if self.root_bad & (1 << j) != 0 => Err(singular(time, 1)),
            None => Ok(self.axial_mass[j]),
        }
    }
}

/// The backward sweep, the root's system and the forward sweep of `N` chains of `n` segments
/// each, one per lane of `L`: lane j for chain j with constants `c[j]`, elongation `s[j]` and
/// its rate `sd[j]`, writing `q''` into `qdd[j]` (`2 n + 1` values); `watch` sees the steps of
/// both sweeps (for one chain's tensions). The accelerations of a lane
/// whose mass matrix was singular (or NaN) are unspecified; [`Solved::result`] gives its error.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn sweeps<const N: usize, L: Lane, I: Inputs<L>>(
    c: [&ChainConstants; N],
    inputs: &I,
    n: usize,
    s: [f64; N],
    sd: [f64; N],
    springs: [Spring; N],
    work: &mut [Articulated<L::Stored>],
    qdd: [&mut [f64]; N],
    watch: &mut impl Watch<L>,
) -> Solved<N, L> {
    const { assert!(N == L::LANES && N <= 32) };
    let work = &mut work[..n];
    let mut qdd = qdd.map(|q| &mut q[..2 * n + 1]);
    let l = L::gather(|j| c[j].l);
    let m = L::gather(|j| c[j].m);
    let inv_l = L::gather(|j| 1.0 / c[j].l);
    let m6 = L::gather(|j| c[j].m / 6.0);
    let zero = L::splat(0.0);

    // Backward sweep, tip to segment 2, on B = A + (m/2) 1. A lane whose determinant is not
    // positive (or NaN) keeps the first segment where it failed.
    let mut failed: [Option<usize>; N] = [None; N];
    let all = (1u32 << N) - 1;
    let mut bad_lanes = 0u32;
    let d = L::gather(|j| c[j].tip_mass + 0.5 * c[j].m);
    let mut bm: S3<L> = [d, d, d, zero, zero, zero];
    let mut bias: V<L> = inputs.tip_force();
    for k in (1..n).rev() {
        let (ep, es, w) = inputs.directions(k);
        let (force, reduced, cos_psi) = inputs.loads(k);
        // Articulated inertia: depends on the geometry only.
        let bep = sym_mul_xz(&bm, &ep);
        let bes = sym_mul(&bm, &es);
        let k00 = L::madd(-(m6 * cos_psi), cos_psi, dot_xz(&ep, &bep));
        let k01 = dot_xz(&ep, &bes);
        let k11 = dot(&es, &bes) - m6;
        // W = (B E) K^-1 = (B E) adj(K) / det: the adjugate products run beside the division.
        let a0 = axpy(&bes, -k01, &scale(&bep, k11));
        let a1 = axpy(&bep, -k01, &scale(&bes, k00));
        let det = L::madd(k00, k11, -(k01 * k01));
        // (An infinite det makes the accelerations non-finite, which the integrator reports.)
        let bad = det.not_positive() & !bad_lanes;
        if bad != 0 {
            for (j, f) in failed.iter_mut().enumerate() {
                if bad & (1 << j) != 0 {
                    *f = Some(k + 1);
                }
            }
            bad_lanes |= bad;
            if bad_lanes == all {
                break;
            }
        }
        let inv = L::splat(1.0).div(det);
        // Bias: y = K^-1 E^T (r/l^2 + (m/4) w - B w), r/l^2 + (m/4) w = `reduced` + b / l.
        let bw = sym_mul(&bm, &w);
        let v = axpy(&bias, inv_l, &sub3(&reduced, &bw));
        let (r0, r1) = (dot_xz(&ep, &v), dot(&es, &v));
        let y0 = L::madd(k11, r0, -(k01 * r1)) * inv;
        let y1 = L::madd(k00, r1, -(k01 * r0)) * inv;
        let t = axpy(&bep, y0, &axpy(&bes, y1, &bw));
        bias = axpy(&t, -l, &add3(&force, &bias));
        let upd = |a: L, b: L, c: L, d: L, base: L| L::madd(-L::madd(a, b, c * d), inv, base);
        bm = [
            upd(a0[0], bep[0], a1[0], bes[0], bm[0] + m),
            upd(a0[1], bep[1], a1[1], bes[1], bm[1] + m),
            upd(a0[2], bep[2], a1[2], bes[2], bm[2] + m),
            upd(a0[0], bep[1], a1[0], bes[1], bm[3]),
            upd(a0[0], bep[2], a1[0], bes[2], bm[4]),
            upd(a0[1], bep[2], a1[1], bes[2], bm[5]),
        ];
        // l G = W^T.
        let art = &mut work[k];
        art.lg = [scale(&a0, inv), scale(&a1, inv)].map(|g| g.map(L::store));
        art.y = [y0.store(), y1.store()];
        watch.backward(k, &bm, &bias);
    }

    // Root: s and segment 1's angles, against A_1 = B_1 - (m/2) 1 and b_1. With e, E_phi, E_psi
    // orthogonal (|E_phi| = cos psi), J_c^T J_c = diag(1, rho_c^2 cos^2 psi, rho_c^2) and
    // J_r^T J_r = diag(0, cos^2 psi, 1); the 3x3 system is solved by LDL^T.
    let half_m = L::gather(|j| 0.5 * c[j].m);
    let a_mat: S3<L> = [
        bm[0] - half_m,
        bm[1] - half_m,
        bm[2] - half_m,
        bm[3],
        bm[4],
        bm[5],
    ];
    let b_vec = bias;
    let (_, es1, w) = inputs.directions(0);
    let (force, _, cos_psi0) = inputs.loads(0);
    let [e1, ep1, e_dot, extra] = inputs.root();
    let cos2 = cos_psi0 * cos_psi0;
    let (s_v, sd_v) = (L::gather(|j| s[j]), L::gather(|j| sd[j]));
    let (rho_c, rho_t) = (s_v + L::splat(0.5) * l, s_v + l);
    let (ae, aep, aes) = (
        sym_mul(&a_mat, &e1),
        sym_mul(&a_mat, &ep1),
        sym_mul(&a_mat, &es1),
    );
    let rod_inertia = L::gather(|j| c[j].rod_inertia);
    let own = m * rho_c * rho_c + rod_inertia;
    let rho_t2 = rho_t * rho_t;
    let m11_own = m + dot(&e1, &ae);
    let m11 = m11_own + L::gather(|j| springs[j].added_mass);
    let m12 = rho_t * dot(&e1, &aep);
    let m13 = rho_t * dot(&e1, &aes);
    let m22 = L::madd(own, cos2, rho_t2 * dot(&ep1, &aep));
    let m23 = rho_t2 * dot(&ep1, &aes);
    let m33 = L::madd(rho_t2, dot(&es1, &aes), own);
    let drift = scale(&e_dot, L::splat(2.0) * sd_v);
    let c0 = axpy(&w, rho_c, &drift);
    let t0 = axpy(&w, rho_t, &drift);
    let f1 = axpy(&c0, -m, &force);
    let f2 = sub3(&b_vec, &sym_mul(&a_mat, &t0));
    let moment = axpy(&f1, rho_c, &axpy(&f2, rho_t, &extra));
    let (k_v, c_s) = (L::gather(|j| c[j].k), L::gather(|j| c[j].c_s));
    let (spring_s, spring_sd) = (L::gather(|j| springs[j].s), L::gather(|j| springs[j].sd));
    let r0 = dot(&e1, &add3(&f1, &f2)) - L::madd(k_v, spring_s, c_s * spring_sd);
    let (r1, r2) = (dot(&ep1, &moment), dot(&es1, &moment));
    let d1 = m11;
    let (l21, l31) = (m12.div(d1), m13.div(d1));
    let d2 = L::madd(-l21, m12, m22);
    let l32 = L::madd(-l31, m12, m23).div(d2);
    let d3 = L::madd(-(l32 * l32), d2, L::madd(-l31, m13, m33));
    let root_bad = d1.not_positive() | d2.not_positive() | d3.not_positive();
    // The axial mass (see `Solved::result`).
    let det = m22 * m33 - m23 * m23;
    let quad = m33 * m12 * m12 - L::splat(2.0) * m23 * m12 * m13 + m22 * m13 * m13;
    let mut axial_mass = [0.0; N];
    (m11_own - quad.div(det)).write(&mut axial_mass);
    let y2 = L::madd(-l21, r0, r1);
    let y3 = L::madd(-l32, y2, L::madd(-l31, r0, r2));
    let z2 = y3.div(d3);
    let z1 = L::madd(-l32, z2, y2.div(d2));
    let z0 = L::madd(-l31, z2, L::madd(-l21, z1, r0.div(d1)));
    write_lanes(&mut qdd, 0, z0);
    write_lanes(&mut qdd, 1, z1);
    write_lanes(&mut qdd, 2, z2);
    let e1dd_ang = axpy(&ep1, z1, &scale(&es1, z2));
    let mut acc = axpy(&e1dd_ang, rho_t, &axpy(&e1, z0, &t0));
    let root = Root {
        e1,
        z0,
        drift,
        w,
        e1dd_ang,
        rho_c,
        force,
        bias: b_vec,
        a_mat,
        acc1: acc,
    };

    // Forward sweep: u = y - G a with l G a = (c0 . a, c1 . a); then a_{k+1} = a_k + l (w_k +
    // E_k u_k) = (a_k + phi_k) - E_k (l G a_k) with phi_k = l (w_k + E_k y_k) formed aside (a
    // shorter chain of dependent operations from segment to segment).
    let neg_inv_l = -inv_l;
    for (k, art) in work.iter().enumerate().skip(1) {
        watch.forward(k, &acc);
        let [lg0, lg1] = art.lg.map(|row| row.map(|v| L::load(&v)));
        let [y0, y1] = art.y.map(|v| L::load(&v));
        let (d0, d1) = (dot(&lg0, &acc), dot(&lg1, &acc));
        write_lanes(&mut qdd, 1 + 2 * k, L::madd(neg_inv_l, d0, y0));
        write_lanes(&mut qdd, 2 + 2 * k, L::madd(neg_inv_l, d1, y1));
        let ([ep_x, ep_z], es, w) = inputs.directions(k);
        let ep = [ep_x, zero, ep_z];
        let phi = axpy(&ep, y0, &axpy(&es, y1, &w));
        let shifted = axpy(&phi, l, &acc);
        acc = axpy(&ep, -d0, &axpy(&es, -d1, &shifted));
    }
    Solved {
        failed,
        root_bad,
        axial_mass,
        root,
        acc,
    }
}

/// Lane j of `v` into `out[j][i]`.
#[inline(always)]
fn write_lanes<const N: usize, L: Lane>(out: &mut [&mut [f64]; N], i: usize, v: L) {
    let mut lanes = [0.0; N];
    v.write(&mut lanes);
    for (out, v) in out.iter_mut().zip(lanes) {
        out[i] = v;
    }
}
