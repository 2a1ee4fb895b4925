//! The distributed elasticity ([`crate::Elasticity::Distributed`], the paper's "full model" of
//! section 2.3.6): a visco-elastic element at the inboard end of every segment.
//!
//! # Coordinates
//! `q = [s_1, phi_1, psi_1, ..., phi_n, psi_n, s_2, ..., s_n]` (3n entries): the attachment
//! model's layout (segment 1's element first, the angles at the same places) followed by the
//! stretches of the elements of segments 2 ... n. With `s_2 = ... = s_n = 0` the geometry is the
//! attachment model's; each element has stiffness `n k` and damping `n c_s`, so the n elements in
//! series have the whole tether's k and c_s and the same static stretch under a tip load.
//!
//! # Kinematics
//! Joint k (the inboard end of segment k's element, 0-based) is at `j_k`; segment k's rod runs
//! from `j_k + s_k e_k` to `j_{k+1} = j_k + (s_k + l) e_k`, its centre at `j_k + (s_k + l/2) e_k`.
//! Per segment the three coordinates `z_k = (s_k, phi_k, psi_k)` enter exactly as segment 1's do
//! in the attachment model: with `rho_c = s_k + l/2`, `rho_t = s_k + l`, the Jacobians of the
//! centre, the outer end and the direction with respect to `z_k` are
//! `J_c = [e, rho_c E]`, `J_t = [e, rho_t E]`, `J_r = [0, E]`, and the biases (accelerations at
//! zero `z''`, relative to the joint) `c0 = 2 s' e' + rho_c w`, `t0 = 2 s' e' + rho_t w`.
//! The rod's inertia is `m l^2 / 12` (the rod is rigid; the element is massless).
//!
//! # Solvers
//! **Recursive, O(n)** (the default, [`crate::Solver::Recursive`]): the articulated-body recursion
//! of [`crate::recursive`] with a 3x3 block per segment. With everything outboard of joint k
//! reacting as `P_k = b_k - A_k a_k` (`a_k` the joint's acceleration; `A_n = M_t 1`,
//! `b_n = F_t`), Kane's equations of segment k read `H z'' = g - C^T a_k` with
//!
//! ```text
//! H = m J_c^T J_c + J_t^T A_{k+1} J_t + I J_r^T J_r      (3x3 SPD)
//! C = m J_c + A_{k+1} J_t
//! g = J_c^T (F - m c0) + J_t^T (b_{k+1} - A_{k+1} t0) + J_r^T X - (n k s + n c_s s', 0, 0)
//! A_k = A_{k+1} + m 1 - C H^-1 C^T
//! b_k = F + b_{k+1} - m c0 - A_{k+1} t0 - C H^-1 g
//! ```
//!
//! and the forward sweep from the fixed attachment (`a_0 = 0`) gives
//! `z'' = H^-1 (g - C^T a_k)`, `a_{k+1} = a_k + t0 + J_t z''`; the tension at the inboard end of
//! segment k is `P_k . e_k` (which the element's equation makes equal to `n k s_k + n c_s s_k'`).
//!
//! *As implemented*, the sweep works in the segment's orthonormal frame `U = [e, E_phi / cos psi,
//! E_psi]`, where the Jacobians are diagonal scalings: `J_c = U D_c`, `J_t = U D_t`,
//! `J_r = U D_r` with `D_c = diag(1, rho_c cos psi, rho_c)`, `D_t = diag(1, rho_t cos psi, rho_t)`,
//! `D_r = diag(0, cos psi, 1)`. In the outer end's coordinates `w = D_t z` (`D_t` is invertible
//! away from the chart's singularity), with `A^ = U^T A_{k+1} U`,
//!
//! ```text
//! X = D_t^-1 H D_t^-1 = A^ + diag(m + d, delta, delta),   delta = (m rho_c^2 + I) / rho_t^2
//! D_t^-1 C^T = (X - E) U^T,   E = diag(d, eps, eps),   eps = delta - m rho_c / rho_t
//! A_k = U (diag(d, sigma, sigma) - E X^-1 E) U^T,      sigma = m + delta - 2 m rho_c / rho_t
//! g_w = D_t^-1 g,  y = X^-1 g_w,  b_k = F - m c0 + b_{k+1} - A_{k+1} t0 - U (g_w - E y)
//! forward: w'' = y - a^ + X^-1 E a^ (a^ = U^T a_k),  z'' = D_t^-1 w''
//! ```
//!
//! (`d` is the mass a linearly implicit stage adds to the stretch's diagonal, zero in a
//! right-hand side: then `A_k` has no inertia along `e`, the element being massless, and
//! `sigma - eps^2 / delta = m I / (m rho_c^2 + I)` is the rod's `m / 4` at its end.) `X` is
//! inverted by its cofactors; a 3x3 symmetric product each way between the frames is all the
//! sweep's matrix algebra. `E_phi` has no y component, so neither has the frame's second axis,
//! and its products skip it; the sweep is inlined into the solver's build with fused
//! multiply-adds ([`crate::arith`]).
//!
//! **Dense, O(n^3)** ([`crate::Solver::Dense`], the oracle): the mass matrix from the same
//! Jacobians, block `(k, k) = m J_c^T J_c + M_k J_t^T J_t + I J_r^T J_r` and block
//! `(k, j < k) = (m J_c,k + M_k J_t,k)^T J_t,j` with `M_k = m (n - 1 - k) + M_t` the mass beyond
//! segment k, the generalized forces `Q_k = J_c^T h_k + J_t^T S_{k+1} + J_r^T X_k - spring` from
//! `h_k = F_k - m c_k''|0` and the suffix sums `S_{k+1}` of the outboard `h` and the tip's, solved
//! by Cholesky.

use nalgebra::{Matrix3, Vector3};

use crate::arith::{axpy, dot, madd};
use crate::axial::AxialSolve;
use crate::chain::ChainState;
use crate::error::{Result, TetherError};

type V3 = Vector3<f64>;
type M3 = Matrix3<f64>;

/// `a . b` for an `a` whose y component is zero (the frame's second axis `e_phi / cos psi`).
#[inline(always)]
fn dot_xz(a: &V3, b: &V3) -> f64 {
    madd(a.x, b.x, a.z * b.z)
}

/// Index in q of segment k's stretch s_k (n segments).
#[inline(always)]
pub(crate) fn stretch_index(n: usize, k: usize) -> usize {
    if k == 0 {
        0
    } else {
        2 * n + k
    }
}

/// Index in q of coordinate `a` (0: stretch, 1: phi, 2: psi) of segment k.
#[inline(always)]
fn index(n: usize, k: usize, a: usize) -> usize {
    if a == 0 {
        stretch_index(n, k)
    } else {
        a + 2 * k
    }
}

/// Constants of the distributed chain.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Constants {
    pub l: f64,
    pub m: f64,
    pub rod_inertia: f64,
    pub tip_mass: f64,
    /// Stiffness and damping of one element, n k and n c_s.
    pub k: f64,
    pub c: f64,
}

/// A symmetric 3x3 matrix by its six entries.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Sym {
    xx: f64,
    yy: f64,
    zz: f64,
    xy: f64,
    xz: f64,
    yz: f64,
}

impl Sym {
    #[inline(always)]
    fn diagonal(d: f64) -> Self {
        Sym {
            xx: d,
            yy: d,
            zz: d,
            ..Sym::default()
        }
    }

    #[inline(always)]
    fn mul(&self, v: &V3) -> V3 {
        V3::new(
            madd(self.xx, v.x, madd(self.xy, v.y, self.xz * v.z)),
            madd(self.xy, v.x, madd(self.yy, v.y, self.yz * v.z)),
            madd(self.xz, v.x, madd(self.yz, v.y, self.zz * v.z)),
        )
    }

    /// [`Sym::mul`] of a vector whose y component is zero.
    #[inline(always)]
    fn mul_xz(&self, v: &V3) -> V3 {
        V3::new(
            madd(self.xx, v.x, self.xz * v.z),
            madd(self.xy, v.x, self.yz * v.z),
            madd(self.xz, v.x, self.zz * v.z),
        )
    }

    /// The inverse of a positive definite matrix by its cofactors, or `None` where a leading
    /// minor is not positive (or NaN).
    #[inline(always)]
    fn inverse_spd(&self) -> Option<Sym> {
        let c_xx = madd(self.yy, self.zz, -(self.yz * self.yz));
        let c_xy = madd(self.xz, self.yz, -(self.xy * self.zz));
        let c_xz = madd(self.xy, self.yz, -(self.xz * self.yy));
        let minor2 = madd(self.xx, self.yy, -(self.xy * self.xy));
        let det = madd(self.xx, c_xx, madd(self.xy, c_xy, self.xz * c_xz));
        if !(self.xx > 0.0 && minor2 > 0.0 && det > 0.0) {
            return None;
        }
        let inv = 1.0 / det;
        Some(Sym {
            xx: c_xx * inv,
            yy: madd(self.xx, self.zz, -(self.xz * self.xz)) * inv,
            zz: minor2 * inv,
            xy: c_xy * inv,
            xz: c_xz * inv,
            yz: madd(self.xy, self.xz, -(self.xx * self.yz)) * inv,
        })
    }

    /// `U S U^T` for the orthonormal frame `U = [u0, u1, u2]` (columns).
    #[inline(always)]
    fn in_frame(&self, u0: &V3, u1: &V3, u2: &V3) -> Sym {
        // Columns of S U^T's transpose: r_i = sum_j S_ij u_j, then U S U^T = sum_i u_i r_i^T.
        let r0 = axpy(u0, self.xx, &axpy(u1, self.xy, &(u2 * self.xz)));
        let r1 = axpy(u0, self.xy, &axpy(u1, self.yy, &(u2 * self.yz)));
        let r2 = axpy(u0, self.xz, &axpy(u1, self.yz, &(u2 * self.zz)));
        let entry = |a: usize, b: usize| madd(u0[a], r0[b], madd(u1[a], r1[b], u2[a] * r2[b]));
        Sym {
            xx: entry(0, 0),
            yy: entry(1, 1),
            zz: entry(2, 2),
            xy: entry(0, 1),
            xz: entry(0, 2),
            yz: entry(1, 2),
        }
    }
}

/// What the backward sweep leaves per segment for the forward sweep (module documentation,
/// "as implemented").
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Articulated {
    /// `X^-1` in the segment's frame.
    x_inv: Sym,
    /// `E = diag(d, eps, eps)`: `d` and `eps`.
    e_d: f64,
    e_eps: f64,
    /// `X^-1 g_w`.
    y: V3,
    /// The outer end's bias `t0` (relative to the joint).
    t0: V3,
    /// `1 / rho_t`.
    inv_rho_t: f64,
    /// `1 / cos psi`.
    inv_cos: f64,
    /// `A_k` and `b_k` of the segment's joint (kept only when tensions are asked for).
    a: Sym,
    b: V3,
}

/// The per-segment Jacobians and biases.
struct Segment {
    jc: M3,
    jt: M3,
    jr: M3,
    c0: V3,
    t0: V3,
    s: f64,
    sd: f64,
}

#[inline(always)]
fn segment(c: &Constants, chain: &ChainState, q: &[f64], qd: &[f64], k: usize) -> Segment {
    let n = chain.segments();
    let i = stretch_index(n, k);
    let (s, sd) = (q[i], qd[i]);
    let (e, ep, es) = (chain.e.get(k), chain.e_phi.get(k), chain.e_psi.get(k));
    let (rho_c, rho_t) = (s + 0.5 * c.l, s + c.l);
    let drift = chain.e_dot.get(k) * (2.0 * sd);
    let w = chain.w.get(k);
    Segment {
        jc: M3::from_columns(&[e, ep * rho_c, es * rho_c]),
        jt: M3::from_columns(&[e, ep * rho_t, es * rho_t]),
        jr: M3::from_columns(&[V3::zeros(), ep, es]),
        c0: drift + w * rho_c,
        t0: drift + w * rho_t,
        s,
        sd,
    }
}

fn singular(time: f64, segment: usize) -> TetherError {
    TetherError::Diverged {
        time,
        reason: format!("mass matrix lost positive definiteness at segment {segment}"),
    }
}

/// The O(n) recursion (module documentation): q'' into `qdd`, the tensions (n + 1 values) into
/// `tensions` if given. With `axial` (a stage of a linearly implicit step,
/// [`crate::axial::AxialStage`]) every element's force is evaluated at the stage's arguments
/// and its stretch entry of `H` gains the added mass. Inlined into its caller, which compiles it
/// with fused multiply-adds where the processor has them ([`crate::arith`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn solve(
    time: f64,
    c: &Constants,
    chain: &ChainState,
    q: &[f64],
    qd: &[f64],
    work: &mut [Articulated],
    qdd: &mut [f64],
    tensions: Option<&mut [f64]>,
    axial: Option<AxialSolve<'_>>,
) -> Result<()> {
    let n = chain.segments();
    let (l, m) = (c.l, c.m);
    let want_tensions = tensions.is_some();
    let added = axial.as_ref().map_or(0.0, |a| a.added_mass);
    // The element's force's arguments: the state's stretches, or the stage's.
    let (spring_s, spring_sd) = match &axial {
        None => (q, qd),
        Some(ax) => (ax.stretch, ax.stretch_rate),
    };
    let stretches = Stretches::new(n, q, qd, spring_s, spring_sd);
    let (e, e_phi, e_psi) = (chain.e.view(n), chain.e_phi.view(n), chain.e_psi.view(n));
    let (e_dot, w, force, extra) = (
        chain.e_dot.view(n),
        chain.w.view(n),
        chain.force.view(n),
        chain.extra.view(n),
    );
    let cos_psi = &chain.cos_psi[..n];
    let work = &mut work[..n];
    let mut a = Sym::diagonal(c.tip_mass);
    let mut b = chain.tip_force;
    for k in (0..n).rev() {
        let (s, sd, spring_s, spring_sd) = stretches.get(k);
        let spring = madd(c.k, spring_s, c.c * spring_sd);
        // The segment's frame U = [e, e_phi / cos psi, e_psi]; e_phi has no y component.
        let inv_cos = 1.0 / cos_psi[k];
        let u0 = e.get(k);
        let u1 = V3::new(e_phi.x[k] * inv_cos, 0.0, e_phi.z[k] * inv_cos);
        let u2 = e_psi.get(k);
        let (rho_c, rho_t) = (s + 0.5 * l, s + l);
        let inv_rho_t = 1.0 / rho_t;
        let drift = e_dot.get(k) * (2.0 * sd);
        let wk = w.get(k);
        let c0 = axpy(&wk, rho_c, &drift);
        let t0 = axpy(&wk, rho_t, &drift);
        // A in the segment's frame.
        let (a0, a1, a2) = (a.mul(&u0), a.mul_xz(&u1), a.mul(&u2));
        let delta = madd(m * rho_c, rho_c, c.rod_inertia) * inv_rho_t * inv_rho_t;
        let gp = m * rho_c * inv_rho_t;
        let x = Sym {
            xx: dot(&u0, &a0) + (m + added),
            yy: dot_xz(&u1, &a1) + delta,
            zz: dot(&u2, &a2) + delta,
            xy: dot(&u0, &a1),
            xz: dot(&u0, &a2),
            yz: dot_xz(&u1, &a2),
        };
        let x_inv = x.inverse_spd().ok_or_else(|| singular(time, k + 1))?;
        let eps = delta - gp;
        let sigma = m + delta - 2.0 * gp;
        let eps2 = eps * eps;
        // A_k = U (diag(d, sigma, sigma) - E X^-1 E) U^T.
        let local = Sym {
            xx: madd(-added * added, x_inv.xx, added),
            yy: madd(-eps2, x_inv.yy, sigma),
            zz: madd(-eps2, x_inv.zz, sigma),
            xy: -added * eps * x_inv.xy,
            xz: -added * eps * x_inv.xz,
            yz: -eps2 * x_inv.yz,
        };
        // The bias: g_w = D_t^-1 g, y = X^-1 g_w, b_k = f1 + f2 - U (g_w - E y).
        let f1 = axpy(&c0, -m, &force.get(k));
        let f2 = b - a.mul(&t0);
        let ext = extra.get(k);
        let ratio = rho_c * inv_rho_t;
        let g_w = V3::new(
            dot(&u0, &f1) + dot(&u0, &f2) - spring,
            madd(
                dot_xz(&u1, &f1),
                ratio,
                madd(dot_xz(&u1, &ext), inv_rho_t, dot_xz(&u1, &f2)),
            ),
            madd(
                dot(&u2, &f1),
                ratio,
                madd(dot(&u2, &ext), inv_rho_t, dot(&u2, &f2)),
            ),
        );
        let y = x_inv.mul(&g_w);
        let r = V3::new(
            madd(-added, y.x, g_w.x),
            madd(-eps, y.y, g_w.y),
            madd(-eps, y.z, g_w.z),
        );
        let ur = axpy(&u0, r.x, &axpy(&u1, r.y, &(u2 * r.z)));
        b = f1 + f2 - ur;
        a = local.in_frame(&u0, &u1, &u2);
        let art = &mut work[k];
        art.x_inv = x_inv;
        art.e_d = added;
        art.e_eps = eps;
        art.y = y;
        art.t0 = t0;
        art.inv_rho_t = inv_rho_t;
        art.inv_cos = inv_cos;
        if want_tensions {
            art.a = a;
            art.b = b;
        }
    }
    let mut acc = V3::zeros();
    let mut tensions = tensions;
    let (stretch_qdd, angles_qdd) = qdd.split_at_mut(1);
    let (angles_qdd, rest_qdd) = angles_qdd.split_at_mut(2 * n);
    let rest_qdd = &mut rest_qdd[..n - 1];
    for (k, (art, angles)) in work.iter().zip(angles_qdd.chunks_exact_mut(2)).enumerate() {
        let u0 = e.get(k);
        let u1 = V3::new(e_phi.x[k] * art.inv_cos, 0.0, e_phi.z[k] * art.inv_cos);
        let u2 = e_psi.get(k);
        if let Some(t) = tensions.as_deref_mut() {
            t[k] = dot(&(art.b - art.a.mul(&acc)), &u0);
        }
        // w'' = y - a_loc + X^-1 E a_loc, z'' = D_t^-1 w''.
        let a_loc = V3::new(dot(&u0, &acc), dot_xz(&u1, &acc), dot(&u2, &acc));
        let ea = V3::new(art.e_d * a_loc.x, art.e_eps * a_loc.y, art.e_eps * a_loc.z);
        let wdd = art.y - a_loc + art.x_inv.mul(&ea);
        if k == 0 {
            stretch_qdd[0] = wdd.x;
        } else {
            rest_qdd[k - 1] = wdd.x;
        }
        angles[0] = wdd.y * art.inv_rho_t * art.inv_cos;
        angles[1] = wdd.z * art.inv_rho_t;
        acc += axpy(&u0, wdd.x, &axpy(&u1, wdd.y, &axpy(&u2, wdd.z, &art.t0)));
    }
    if let Some(t) = tensions {
        t[n] = dot(
            &axpy(&acc, -c.tip_mass, &chain.tip_force),
            &chain.e.get(n - 1),
        );
    }
    Ok(())
}

/// The stretches and their rates, of the state and of the element's force, by segment (segment
/// 1's at index 0 of q, the others' at 2n + k), read without bounds checks in the sweep.
struct Stretches<'a> {
    first: [f64; 4],
    s: &'a [f64],
    sd: &'a [f64],
    spring_s: &'a [f64],
    spring_sd: &'a [f64],
}

impl<'a> Stretches<'a> {
    #[inline(always)]
    fn new(
        n: usize,
        q: &'a [f64],
        qd: &'a [f64],
        spring_s: &'a [f64],
        spring_sd: &'a [f64],
    ) -> Self {
        let tail = |v: &'a [f64]| &v[2 * n..3 * n];
        Stretches {
            first: [q[0], qd[0], spring_s[0], spring_sd[0]],
            s: tail(q),
            sd: tail(qd),
            spring_s: tail(spring_s),
            spring_sd: tail(spring_sd),
        }
    }

    /// `(s, s', spring's s, spring's s')` of segment k (k < n).
    #[inline(always)]
    fn get(&self, k: usize) -> (f64, f64, f64, f64) {
        if k == 0 {
            (self.first[0], self.first[1], self.first[2], self.first[3])
        } else {
            (self.s[k], self.sd[k], self.spring_s[k], self.spring_sd[k])
        }
    }
}

/// Stores `v` at (r, c) of the lower triangle of a row-major `dim x dim` matrix.
#[inline(always)]
fn put(mass: &mut [f64], dim: usize, r: usize, c: usize, v: f64) {
    let (r, c) = if r >= c { (r, c) } else { (c, r) };
    mass[r * dim + c] = v;
}

/// The lower triangle of the mass matrix (3n x 3n) into `mass` (module documentation); needs the
/// directions of `chain` only (the biases `segment` also forms are not used).
pub(crate) fn assemble_mass(c: &Constants, chain: &ChainState, q: &[f64], mass: &mut [f64]) {
    let n = chain.segments();
    let dim = 3 * n;
    for k in 0..n {
        let sk = segment(c, chain, q, q, k);
        let beyond = c.m * (n - 1 - k) as f64 + c.tip_mass;
        let own = sk.jc.transpose() * sk.jc * c.m
            + sk.jt.transpose() * sk.jt * beyond
            + sk.jr.transpose() * sk.jr * c.rod_inertia;
        for x in 0..3 {
            for y in 0..3 {
                put(mass, dim, index(n, k, x), index(n, k, y), own[(x, y)]);
            }
        }
        let v = sk.jc * c.m + sk.jt * beyond;
        for j in 0..k {
            let sj = segment(c, chain, q, q, j);
            let block = v.transpose() * sj.jt;
            for x in 0..3 {
                for y in 0..3 {
                    put(mass, dim, index(n, k, x), index(n, j, y), block[(x, y)]);
                }
            }
        }
    }
}

/// The generalized forces Q into `rhs` (module documentation).
pub(crate) fn generalized_forces(
    c: &Constants,
    chain: &ChainState,
    q: &[f64],
    qd: &[f64],
    rhs: &mut [f64],
) {
    let n = chain.segments();
    // Joint accelerations at zero q'': j_{k+1}'' = j_k'' + t0_k; the tip is j_n''.
    let mut joint = V3::zeros();
    for k in 0..n {
        joint += segment(c, chain, q, qd, k).t0;
    }
    let mut suffix = chain.tip_force - joint * c.tip_mass;
    for k in (0..n).rev() {
        let sg = segment(c, chain, q, qd, k);
        joint -= sg.t0;
        let h = chain.force.get(k) - (joint + sg.c0) * c.m;
        let mut g = sg.jc.transpose() * h
            + sg.jt.transpose() * suffix
            + sg.jr.transpose() * chain.extra.get(k);
        g.x -= c.k * sg.s + c.c * sg.sd;
        for (i, v) in g.iter().enumerate() {
            rhs[index(n, k, i)] = *v;
        }
        suffix += h;
    }
}
