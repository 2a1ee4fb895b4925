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
//! **Dense, O(n^3)** ([`crate::Solver::Dense`], the oracle): the mass matrix from the same
//! Jacobians, block `(k, k) = m J_c^T J_c + M_k J_t^T J_t + I J_r^T J_r` and block
//! `(k, j < k) = (m J_c,k + M_k J_t,k)^T J_t,j` with `M_k = m (n - 1 - k) + M_t` the mass beyond
//! segment k, the generalized forces `Q_k = J_c^T h_k + J_t^T S_{k+1} + J_r^T X_k - spring` from
//! `h_k = F_k - m c_k''|0` and the suffix sums `S_{k+1}` of the outboard `h` and the tip's, solved
//! by Cholesky.

use nalgebra::{Matrix3, Vector3};

use crate::chain::ChainState;
use crate::dynamics::AxialSolve;
use crate::error::{Result, TetherError};

type V3 = Vector3<f64>;
type M3 = Matrix3<f64>;

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

/// What the backward sweep leaves per segment.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Articulated {
    /// `H^-1 g`.
    y: V3,
    /// `H^-1 C^T`.
    g: M3,
    /// The outer end's bias and Jacobian, `t0` and `J_t`.
    t0: V3,
    jt: M3,
    /// `A_k` and `b_k` of the segment's joint.
    a: M3,
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
/// [`crate::dynamics::AxialStage`]) every element's force is evaluated at the stage's arguments
/// and its stretch entry of `H` gains the added mass.
#[allow(clippy::too_many_arguments)]
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
    let mut a = M3::identity() * c.tip_mass;
    let mut b = chain.tip_force;
    for k in (0..n).rev() {
        let sg = segment(c, chain, q, qd, k);
        let (force, extra) = (chain.force.get(k), chain.extra.get(k));
        let ajt = a * sg.jt;
        let mut h = sg.jc.transpose() * sg.jc * c.m
            + sg.jt.transpose() * ajt
            + sg.jr.transpose() * sg.jr * c.rod_inertia;
        let cm = sg.jc * c.m + ajt;
        let mut g = sg.jc.transpose() * (force - sg.c0 * c.m)
            + sg.jt.transpose() * (b - a * sg.t0)
            + sg.jr.transpose() * extra;
        match &axial {
            None => g.x -= c.k * sg.s + c.c * sg.sd,
            Some(a) => {
                let i = stretch_index(n, k);
                g.x -= c.k * a.stretch[i] + c.c * a.stretch_rate[i];
                h[(0, 0)] += a.added_mass;
            }
        }
        let chol = h.cholesky().ok_or_else(|| singular(time, k + 1))?;
        let y = chol.solve(&g);
        let gm = chol.solve(&cm.transpose());
        let a_next = a + M3::identity() * c.m - cm * gm;
        let a_next = (a_next + a_next.transpose()) * 0.5;
        let b_next = force + b - sg.c0 * c.m - a * sg.t0 - cm * y;
        work[k] = Articulated {
            y,
            g: gm,
            t0: sg.t0,
            jt: sg.jt,
            a: a_next,
            b: b_next,
        };
        a = a_next;
        b = b_next;
    }
    let mut acc = V3::zeros();
    let mut tensions = tensions;
    for (k, art) in work.iter().enumerate().take(n) {
        if let Some(t) = tensions.as_deref_mut() {
            t[k] = (art.b - art.a * acc).dot(&chain.e.get(k));
        }
        let z = art.y - art.g * acc;
        for (i, v) in z.iter().enumerate() {
            qdd[index(n, k, i)] = *v;
        }
        acc += art.t0 + art.jt * z;
    }
    if let Some(t) = tensions {
        t[n] = (chain.tip_force - acc * c.tip_mass).dot(&chain.e.get(n - 1));
    }
    Ok(())
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
