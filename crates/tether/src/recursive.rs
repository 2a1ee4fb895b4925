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
//! * Where the processor has AVX2 and FMA the backward sweep runs four lanes wide
//!   (`recursive/avx2.rs`: a 3-vector per register, `B` by its columns), bit for bit the scalar
//!   sweep with fused multiply-adds, which stays as its reference and as the portable path.
//! * Four chains (four envs of a batch) can run the three steps together, one per AVX2 lane
//!   (`recursive/lockstep.rs`, [`crate::TetherModel::accelerations_four`]): latency-bound for
//!   one chain, the sweeps then fill each other's waits; lane j is bit for bit chain j's fused
//!   solve.
//! * Only the directions, loads and `K`, `W`, `y` live in the sweep; everything independent per
//!   segment (trigonometry, directions, rates, loads) is done beforehand in structure-of-arrays
//!   passes the compiler vectorizes. Multiply-adds are fused where the processor has FMA
//!   (`arith.rs`).
//!
//! Each sweep costs O(1) per segment with fixed-size 3x3 / 2x2 algebra and no allocation.

use nalgebra::Vector3;

use crate::arith::{axpy, dot, dot_xz, Madd};
use crate::chain::ChainState;
use crate::error::{Result, TetherError};

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
pub(crate) mod lockstep;

type V3 = Vector3<f64>;

/// A symmetric 3x3 matrix by its six entries.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Sym3 {
    xx: f64,
    yy: f64,
    zz: f64,
    xy: f64,
    xz: f64,
    yz: f64,
}

impl Sym3 {
    #[inline(always)]
    fn diagonal(d: f64) -> Self {
        Sym3 {
            xx: d,
            yy: d,
            zz: d,
            ..Sym3::default()
        }
    }

    #[inline(always)]
    fn mul<M: Madd>(&self, v: &V3) -> V3 {
        V3::new(
            M::madd(self.xx, v.x, M::madd(self.xy, v.y, self.xz * v.z)),
            M::madd(self.xy, v.x, M::madd(self.yy, v.y, self.yz * v.z)),
            M::madd(self.xz, v.x, M::madd(self.yz, v.y, self.zz * v.z)),
        )
    }

    /// `self v` for a vector with a zero y component (de/dphi).
    #[inline(always)]
    fn mul_xz<M: Madd>(&self, v: &V3) -> V3 {
        V3::new(
            M::madd(self.xx, v.x, self.xz * v.z),
            M::madd(self.xy, v.x, self.yz * v.z),
            M::madd(self.xz, v.x, self.zz * v.z),
        )
    }
}

/// What the backward sweep leaves per segment for the forward sweep and the tensions.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Articulated {
    /// Rows of `l G_k`: `u_k = y_k - G_k a_k` (x, y, z and a pad, so that the vectorized
    /// sweep stores a row in one instruction).
    lg: [[f64; 4]; 2],
    /// `y_k`.
    y: [f64; 2],
    /// `B_k = A_k + (m/2) 1` (kept only when tensions are asked for).
    inertia: Sym3,
    /// `b_k` (kept only when tensions are asked for).
    bias: V3,
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
/// linearly implicit step, [`crate::dynamics::AxialStage`]).
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
/// force and added mass as `spring` gives them. Writes `q''` into `qdd` and,
/// if given, the tensions (n + 1 values, as [`crate::TetherModel::tensions`]) into `tensions`.
/// Returns the effective axial mass `1 / (M^-1)_00`, kg (see [`root_axial_mass`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn solve<M: Madd>(
    time: f64,
    c: &ChainConstants,
    chain: &ChainState,
    s: f64,
    sd: f64,
    spring: Spring,
    work: &mut [Articulated],
    qdd: &mut [f64],
    tensions: Option<&mut [f64]>,
) -> Result<f64> {
    let n = chain.segments();
    let (l, m) = (c.l, c.m);
    let inv_l = 1.0 / l;

    // Backward sweep, tip to segment 2, on B = A + (m/2) 1: four lanes wide where the
    // processor has AVX2 and FMA (bit for bit the fused scalar sweep), scalar otherwise.
    let want_tensions = tensions.is_some();
    let qdd = &mut qdd[..2 * n + 1];
    let work = &mut work[..n];
    let (bm, bias) = backward::<M>(time, c, chain, work, want_tensions)?;
    let (ep_k, es_k, w_k) = (chain.e_phi.view(n), chain.e_psi.view(n), chain.w.view(n));

    // Root: s and segment 1's angles, against A_1 = B_1 - (m/2) 1 and b_1. With e, E_phi, E_psi
    // orthogonal (|E_phi| = cos psi), J_c^T J_c = diag(1, rho_c^2 cos^2 psi, rho_c^2) and
    // J_r^T J_r = diag(0, cos^2 psi, 1); the 3x3 system is solved by LDL^T.
    let (force, extra) = (chain.force.get(0), chain.extra.get(0));
    let half_m = 0.5 * m;
    let a_mat = Sym3 {
        xx: bm.xx - half_m,
        yy: bm.yy - half_m,
        zz: bm.zz - half_m,
        ..bm
    };
    let b_vec = bias;
    let (e1, e_phi, e_psi) = (chain.e.get(0), chain.e_phi.get(0), chain.e_psi.get(0));
    let w = chain.w.get(0);
    let cos2 = chain.cos_psi[0] * chain.cos_psi[0];
    let (rho_c, rho_t) = (s + 0.5 * l, s + l);
    let (ae, aep, aes) = (
        a_mat.mul::<M>(&e1),
        a_mat.mul::<M>(&e_phi),
        a_mat.mul::<M>(&e_psi),
    );
    let own = m * rho_c * rho_c + c.rod_inertia;
    let rho_t2 = rho_t * rho_t;
    let m11_own = m + dot::<M>(&e1, &ae);
    let m11 = m11_own + spring.added_mass;
    let m12 = rho_t * dot::<M>(&e1, &aep);
    let m13 = rho_t * dot::<M>(&e1, &aes);
    let m22 = M::madd(own, cos2, rho_t2 * dot::<M>(&e_phi, &aep));
    let m23 = rho_t2 * dot::<M>(&e_phi, &aes);
    let m33 = M::madd(rho_t2, dot::<M>(&e_psi, &aes), own);
    let drift = chain.e_dot.get(0) * (2.0 * sd);
    let c0 = axpy::<M>(&w, rho_c, &drift);
    let t0 = axpy::<M>(&w, rho_t, &drift);
    let f1 = axpy::<M>(&c0, -m, &force);
    let f2 = b_vec - a_mat.mul::<M>(&t0);
    let moment = axpy::<M>(&f1, rho_c, &axpy::<M>(&f2, rho_t, &extra));
    let r0 = dot::<M>(&e1, &(f1 + f2)) - M::madd(c.k, spring.s, c.c_s * spring.sd);
    let (r1, r2) = (dot::<M>(&e_phi, &moment), dot::<M>(&e_psi, &moment));
    let d1 = m11;
    let (l21, l31) = (m12 / d1, m13 / d1);
    let d2 = M::madd(-l21, m12, m22);
    let l32 = M::madd(-l31, m12, m23) / d2;
    let d3 = M::madd(-l32 * l32, d2, M::madd(-l31, m13, m33));
    if !(d1 > 0.0 && d2 > 0.0 && d3 > 0.0) {
        return Err(singular(time, 1));
    }
    let axial_mass = root_axial_mass(m11_own, m12, m13, m22, m23, m33);
    let y2 = M::madd(-l21, r0, r1);
    let y3 = M::madd(-l32, y2, M::madd(-l31, r0, r2));
    let z2 = y3 / d3;
    let z1 = M::madd(-l32, z2, y2 / d2);
    let z0 = M::madd(-l31, z2, M::madd(-l21, z1, r0 / d1));
    qdd[0] = z0;
    qdd[1] = z1;
    qdd[2] = z2;
    let e1dd_ang = axpy::<M>(&e_phi, z1, &(e_psi * z2));
    let mut acc = axpy::<M>(&e1dd_ang, rho_t, &axpy::<M>(&e1, z0, &t0));

    let mut tensions = tensions;
    if let Some(t) = tensions.as_deref_mut() {
        let com = e1 * z0 + drift + (w + e1dd_ang) * rho_c;
        let pull = force - com * m + b_vec - a_mat.mul::<M>(&acc);
        t[0] = pull.dot(&e1);
    }

    // Forward sweep.
    for k in 1..n {
        let art = &work[k];
        if let Some(t) = tensions.as_deref_mut() {
            // P_k = b_k - A_k a_k with A_k = B_k - (m/2) 1.
            let pull = art.bias - art.inertia.mul::<M>(&acc) + acc * (0.5 * m);
            t[k] = pull.dot(&chain.e.get(k));
        }
        let [c0, c1] = art.lg.map(|r| V3::new(r[0], r[1], r[2]));
        let [y0, y1] = art.y;
        // u = y - G a with l G a = (c0 . a, c1 . a); then a_{k+1} = a_k + l (w_k + E_k u_k)
        // = (a_k + phi_k) - E_k (l G a_k) with phi_k = l (w_k + E_k y_k) formed aside (a shorter
        // chain of dependent operations from segment to segment).
        let (d0, d1) = (dot::<M>(&c0, &acc), dot::<M>(&c1, &acc));
        qdd[1 + 2 * k] = M::madd(-inv_l, d0, y0);
        qdd[2 + 2 * k] = M::madd(-inv_l, d1, y1);
        let (ep, es) = (V3::new(ep_k.x[k], 0.0, ep_k.z[k]), es_k.get(k));
        let phi = axpy::<M>(&ep, y0, &axpy::<M>(&es, y1, &w_k.get(k)));
        let shifted = axpy::<M>(&phi, l, &acc);
        acc = axpy::<M>(&ep, -d0, &axpy::<M>(&es, -d1, &shifted));
    }
    if let Some(t) = tensions {
        t[n] = (chain.tip_force - acc * c.tip_mass).dot(&chain.e.get(n - 1));
    }
    Ok(axial_mass)
}

/// The backward sweep (tip to segment 2) on `B = A + (m/2) 1`, writing `l G_k` and `y_k` (and,
/// for the tensions, `B_k` and `b_k`) into `work`; returns `B_1` and `b_1` for the root. Four
/// lanes wide where the processor has AVX2 and FMA (`recursive/avx2.rs`); the scalar loop
/// below is its bitwise reference and the sweep of other processors.
#[inline(always)]
fn backward<M: Madd>(
    time: f64,
    c: &ChainConstants,
    chain: &ChainState,
    work: &mut [Articulated],
    want_tensions: bool,
) -> Result<(Sym3, V3)> {
    #[cfg(target_arch = "x86_64")]
    if M::VECTORIZED && crate::arith::has_avx2_fma() {
        // SAFETY: the processor has AVX2 and FMA, checked just above.
        return unsafe { avx2::backward(time, c, chain, work, want_tensions) };
    }
    let n = chain.segments();
    let (l, m) = (c.l, c.m);
    let inv_l = 1.0 / l;
    let m6 = m / 6.0;
    let mut bm = Sym3::diagonal(c.tip_mass + 0.5 * m);
    let mut bias = chain.tip_force;
    let (force_k, reduced_k, w_k) = (chain.force.view(n), chain.reduced.view(n), chain.w.view(n));
    let (ep_k, es_k) = (chain.e_phi.view(n), chain.e_psi.view(n));
    let cos_psi_k = &chain.cos_psi[..n];
    let work = &mut work[..n];
    for k in (1..n).rev() {
        let (force, reduced, w) = (force_k.get(k), reduced_k.get(k), w_k.get(k));
        let cos_psi = cos_psi_k[k];
        let (ep, es) = (&V3::new(ep_k.x[k], 0.0, ep_k.z[k]), &es_k.get(k));
        // Articulated inertia: depends on the geometry only.
        let bep = bm.mul_xz::<M>(ep);
        let bes = bm.mul::<M>(es);
        let k00 = M::madd(-m6 * cos_psi, cos_psi, dot_xz::<M>(ep, &bep));
        let k01 = dot_xz::<M>(ep, &bes);
        let k11 = dot::<M>(es, &bes) - m6;
        // W = (B E) K^-1 = (B E) adj(K) / det: the adjugate products run beside the division.
        let a0 = axpy::<M>(&bes, -k01, &(bep * k11));
        let a1 = axpy::<M>(&bep, -k01, &(bes * k00));
        let det = M::madd(k00, k11, -(k01 * k01));
        // (Not positive or NaN. An infinite det makes the accelerations non-finite, which the
        // integrator reports.)
        if det.is_nan() || det <= 0.0 {
            return Err(singular(time, k + 1));
        }
        let inv = 1.0 / det;
        // Bias: y = K^-1 E^T (r/l^2 + (m/4) w - B w), r/l^2 + (m/4) w = `reduced` + b / l.
        let bw = bm.mul::<M>(&w);
        let v = axpy::<M>(&bias, inv_l, &(reduced - bw));
        let (r0, r1) = (dot_xz::<M>(ep, &v), dot::<M>(es, &v));
        let y0 = M::madd(k11, r0, -(k01 * r1)) * inv;
        let y1 = M::madd(k00, r1, -(k01 * r0)) * inv;
        let t = axpy::<M>(&bep, y0, &axpy::<M>(&bes, y1, &bw));
        bias = axpy::<M>(&t, -l, &(force + bias));
        let upd =
            |a: f64, b: f64, c: f64, d: f64, base: f64| M::madd(-M::madd(a, b, c * d), inv, base);
        bm = Sym3 {
            xx: upd(a0.x, bep.x, a1.x, bes.x, bm.xx + m),
            yy: upd(a0.y, bep.y, a1.y, bes.y, bm.yy + m),
            zz: upd(a0.z, bep.z, a1.z, bes.z, bm.zz + m),
            xy: upd(a0.x, bep.y, a1.x, bes.y, bm.xy),
            xz: upd(a0.x, bep.z, a1.x, bes.z, bm.xz),
            yz: upd(a0.y, bep.z, a1.y, bes.z, bm.yz),
        };
        // l G = W^T.
        let art = &mut work[k];
        let (g0, g1) = (a0 * inv, a1 * inv);
        art.lg = [[g0.x, g0.y, g0.z, 0.0], [g1.x, g1.y, g1.z, 0.0]];
        art.y = [y0, y1];
        if want_tensions {
            art.inertia = bm;
            art.bias = bias;
        }
    }
    Ok((bm, bias))
}

/// The effective mass the axial element moves, `1 / (M^-1)_00`, kg, from the root's 3x3 system
/// (rows `m11 .. m33` in the order s, phi_1, psi_1).
///
/// The backward sweep eliminates every outboard angle exactly, so the root matrix is the Schur
/// complement of the outboard block of `M`, and by the block-inverse formula its inverse is the
/// root block of `M^-1`: `(M^-1)_00 = (M_root^-1)_00`. Its reciprocal is in turn the Schur
/// complement of segment 1's angle block in `M_root`:
///
/// ```text
/// 1 / (M^-1)_00 = m11 - [m12 m13] [[m22 m23] [m23 m33]]^-1 [m12 m13]^T.
/// ```
///
/// The axial damping `c_s` acts on s alone (a rank-one damping matrix `c_s e_0 e_0^T`), so
/// `c_s (M^-1)_00` is exactly the rate of its damping mode. At least the segment mass (segment
/// 1's centre moves at s' along e whatever the angle rates), which the caller's guard keeps.
#[inline(always)]
fn root_axial_mass(m11: f64, m12: f64, m13: f64, m22: f64, m23: f64, m33: f64) -> f64 {
    let det = m22 * m33 - m23 * m23;
    let quad = m33 * m12 * m12 - 2.0 * m23 * m12 * m13 + m22 * m13 * m13;
    m11 - quad / det
}
