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
//! solved by Cholesky.
//!
//! # Forward sweep (root to tip)
//! `a_1 = t0 + J_t z`, then for k >= 1: `u_k = y_k - G_k a_k`, `e_k'' = w_k + E_k u_k`,
//! `a_{k+1} = a_k + l e_k''`. The chain tensions come for free: the force on the base of
//! segment k is `P_k = b_k - A_k a_k`, its tension `P_k . e_k`.
//!
//! Each sweep costs O(1) per segment with fixed-size 3x3 / 2x2 algebra and no allocation.

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};

use crate::direction::DirectionJet;

type V3 = Vector3<f64>;

/// What the backward sweep leaves per segment for the forward sweep and the tensions.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Articulated {
    /// `G_k = K^-1 (C E)^T`: the angle accelerations' dependence on the base acceleration.
    g: Matrix2x3<f64>,
    /// `y_k`: the angle accelerations at zero base acceleration.
    y: Vector2<f64>,
    /// Articulated inertia `A_k` of everything outboard of the base of segment k.
    inertia: Matrix3<f64>,
    /// Bias force `b_k` of everything outboard of the base of segment k.
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

/// Per-segment inputs: directions and their partials, rates, convective accelerations,
/// external forces on the centres and the `extra` vectors, plus the tip force.
pub(crate) struct ChainLoads<'a> {
    pub jets: &'a [DirectionJet],
    pub e_dot: &'a [V3],
    pub e_conv: &'a [V3],
    pub force: &'a [V3],
    pub extra: &'a [V3],
    pub tip_force: V3,
}

/// Why the recursion failed: a non-positive pivot (the state is numerically singular).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Singular {
    /// 0-based segment whose elimination failed.
    pub segment: usize,
}

#[inline]
fn e_matrix(jet: &DirectionJet) -> Matrix3x2<f64> {
    Matrix3x2::from_columns(&[jet.e_phi, jet.e_psi])
}

/// Inverse of a symmetric 2x2 matrix, or `None` if it is not positive definite.
#[inline]
fn inverse_spd2(k: &Matrix2<f64>) -> Option<Matrix2<f64>> {
    let det = k[(0, 0)] * k[(1, 1)] - k[(0, 1)] * k[(1, 0)];
    if !(det > 0.0 && k[(0, 0)] > 0.0) || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    Some(Matrix2::new(
        k[(1, 1)] * inv,
        -k[(0, 1)] * inv,
        -k[(1, 0)] * inv,
        k[(0, 0)] * inv,
    ))
}

/// Solves the equations of motion in O(n): writes `q''` into `qdd` and, if given, the tensions
/// (n + 1 values, as [`crate::TetherModel::tensions`]) into `tensions`.
pub(crate) fn solve(
    c: &ChainConstants,
    loads: &ChainLoads<'_>,
    s: f64,
    sd: f64,
    work: &mut [Articulated],
    qdd: &mut [f64],
    tensions: Option<&mut [f64]>,
) -> Result<(), Singular> {
    let n = loads.jets.len();
    let (l, m) = (c.l, c.m);
    let eye = Matrix3::<f64>::identity();

    // Backward sweep, tip to segment 2.
    let mut a_mat = eye * c.tip_mass;
    let mut b_vec = loads.tip_force;
    for k in (1..n).rev() {
        let jet = &loads.jets[k];
        let e = e_matrix(jet);
        let w = loads.e_conv[k];
        let cm = eye * (0.5 * m * l) + a_mat * l;
        let dpm = eye * (0.25 * m * l * l) + a_mat * (l * l);
        let ce = cm * e;
        let de = dpm * e + e * c.rod_inertia;
        let kmat = e.transpose() * de;
        let kinv = inverse_spd2(&kmat).ok_or(Singular { segment: k })?;
        let r = loads.force[k] * (0.5 * l) + loads.extra[k] + b_vec * l;
        let y = kinv * (e.transpose() * (r - dpm * w));
        let g = kinv * ce.transpose();
        a_mat = a_mat + eye * m - ce * g;
        // Keep it exactly symmetric.
        a_mat = (a_mat + a_mat.transpose()) * 0.5;
        b_vec = loads.force[k] + b_vec - cm * w - ce * y;
        let art = &mut work[k];
        art.g = g;
        art.y = y;
        art.inertia = a_mat;
        art.bias = b_vec;
    }

    // Root: s and segment 1's angles.
    let jet = &loads.jets[0];
    let e1 = jet.e;
    let w = loads.e_conv[0];
    let (rho_c, rho_t) = (s + 0.5 * l, s + l);
    let jc = Matrix3::from_columns(&[e1, jet.e_phi * rho_c, jet.e_psi * rho_c]);
    let jt = Matrix3::from_columns(&[e1, jet.e_phi * rho_t, jet.e_psi * rho_t]);
    let jr = Matrix3::from_columns(&[V3::zeros(), jet.e_phi, jet.e_psi]);
    let mass3 =
        jc.transpose() * jc * m + jt.transpose() * a_mat * jt + jr.transpose() * jr * c.rod_inertia;
    let drift = loads.e_dot[0] * (2.0 * sd);
    let c0 = drift + w * rho_c;
    let t0 = drift + w * rho_t;
    let mut rhs3 = jc.transpose() * (loads.force[0] - c0 * m)
        + jt.transpose() * (b_vec - a_mat * t0)
        + jr.transpose() * loads.extra[0];
    rhs3[0] -= c.k * s + c.c_s * sd;
    let chol = mass3.cholesky().ok_or(Singular { segment: 0 })?;
    let z = chol.solve(&rhs3);
    qdd[0] = z[0];
    qdd[1] = z[1];
    qdd[2] = z[2];
    let e1dd = w + jet.e_phi * z[1] + jet.e_psi * z[2];
    let mut acc = t0 + jt * z;

    let mut tensions = tensions;
    if let Some(t) = tensions.as_deref_mut() {
        let com = e1 * z[0] + drift + e1dd * rho_c;
        let pull = loads.force[0] - com * m + b_vec - a_mat * acc;
        t[0] = pull.dot(&e1);
    }

    // Forward sweep.
    for k in 1..n {
        let art = &work[k];
        if let Some(t) = tensions.as_deref_mut() {
            t[k] = (art.bias - art.inertia * acc).dot(&loads.jets[k].e);
        }
        let u = art.y - art.g * acc;
        qdd[1 + 2 * k] = u[0];
        qdd[2 + 2 * k] = u[1];
        let jet = &loads.jets[k];
        acc += (loads.e_conv[k] + jet.e_phi * u[0] + jet.e_psi * u[1]) * l;
    }
    if let Some(t) = tensions {
        t[n] = (loads.tip_force - acc * c.tip_mass).dot(&loads.jets[n - 1].e);
    }
    Ok(())
}
