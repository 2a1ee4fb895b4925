//! The discrete algebraic Riccati equation, solved by the structured doubling algorithm.
//!
//! For `A` (n x n), `B` (n x m), `Q = Q^T >= 0` (n x n) and `R = R^T > 0` (m x m) the equation
//!
//! ```text
//! X = A^T X A - A^T X B (R + B^T X B)^-1 B^T X A + Q
//! ```
//!
//! has (for `(A, B)` stabilizable and `(Q, A)` detectable) one stabilizing solution `X`: the one
//! with `A - B K` stable, `K = (R + B^T X B)^-1 B^T X A`. It is the LQR's cost-to-go, and with
//! `(A, B, Q, R) = (F^T, H^T, W, V)` the steady-state Kalman filter's prior covariance.
//!
//! # The structured doubling algorithm (SDA)
//! Chu, Fan, Lin, Wang, "Structure-preserving algorithms for periodic discrete-time algebraic
//! Riccati equations", Int. J. Control 77 (2004); Chu, Fan, Lin, "A structure-preserving doubling
//! algorithm for continuous-time algebraic Riccati equations", Linear Algebra Appl. 396 (2005),
//! section 2 for the discrete equation. With `G = B R^-1 B^T`:
//!
//! ```text
//! A_0 = A,  G_0 = G,  H_0 = Q
//! W_k     = I + G_k H_k
//! A_{k+1} = A_k W_k^-1 A_k
//! G_{k+1} = G_k + A_k W_k^-1 G_k A_k^T
//! H_{k+1} = H_k + A_k^T H_k W_k^-1 A_k
//! ```
//!
//! `H_k` converges to `X` quadratically: `||H_k - X|| = O(rho^(2^k))`, `rho` the spectral radius
//! of the closed loop `A - B K`. `G_k` and `H_k` are kept exactly symmetric after each step. The
//! iteration stops when the relative change of `H_k` is below [`CHANGE_TOLERANCE`]; then the
//! equation's relative residual (the difference of the two sides over the largest of their
//! terms' norms) must be below [`RESIDUAL_TOLERANCE`] and the closed loop stable, or the solve
//! is an error. Every product and the LU factorizations are the fixed-order ones of
//! [`crate::control::matrix`]: the same bits on every CPU.

use crate::control::matrix::{spectral_radius, Lu, Matrix};
use crate::error::{Result, SimError};

/// Doubling steps at most (each squares the closed loop's contraction: 2^60 steps of it).
pub const MAX_DOUBLINGS: usize = 60;

/// The doubling stops when `||H_{k+1} - H_k||_F <= CHANGE_TOLERANCE ||H_{k+1}||_F`.
pub const CHANGE_TOLERANCE: f64 = 1e-14;

/// The largest relative residual of the equation accepted as a solution.
pub const RESIDUAL_TOLERANCE: f64 = 1e-9;

/// The stabilizing solution of one discrete algebraic Riccati equation, with how it was found.
#[derive(Debug, Clone)]
pub struct DareSolution {
    /// `X` (n x n, symmetric).
    pub x: Matrix,
    /// `K = (R + B^T X B)^-1 B^T X A` (m x n).
    pub gain: Matrix,
    /// The spectral radius of `A - B K`.
    pub closed_loop_radius: f64,
    /// `||X - (A^T X A - A^T X B K + Q)||_F` over the largest Frobenius norm of `X`, `A^T X A`,
    /// `A^T X B K`, `Q`.
    pub relative_residual: f64,
    /// Doubling steps taken.
    pub doublings: usize,
}

/// Solves `X = A^T X A - A^T X B (R + B^T X B)^-1 B^T X A + Q` for its stabilizing solution.
/// `what` names the equation in errors ([`SimError::Design`]): no convergence, a non-finite or
/// singular step, a residual over [`RESIDUAL_TOLERANCE`] or an unstable closed loop.
pub fn solve_dare(
    a: &Matrix,
    b: &Matrix,
    q: &Matrix,
    r: &Matrix,
    what: &str,
) -> Result<DareSolution> {
    let n = a.rows();
    assert!(a.cols() == n && b.rows() == n && q.rows() == n && q.cols() == n);
    assert!(r.rows() == b.cols() && r.cols() == b.cols());
    let fail = |reason: String| SimError::Design {
        what: what.to_owned(),
        reason,
    };
    let r_lu = Lu::new(r).ok_or_else(|| fail("the input weight R is singular".into()))?;
    // G = B R^-1 B^T.
    let g0 = b.mul(&r_lu.solve(&b.transpose())).symmetric_part();
    let mut ak = a.clone();
    let mut gk = g0;
    let mut hk = q.symmetric_part();
    let identity = Matrix::identity(n);
    let mut doublings = 0;
    loop {
        if doublings == MAX_DOUBLINGS {
            return Err(fail(format!(
                "the doubling did not converge in {MAX_DOUBLINGS} steps (no stabilizing solution: \
                 the pair is not stabilizable or detectable)"
            )));
        }
        doublings += 1;
        let w = identity.add(&gk.mul(&hk));
        let lu = Lu::new(&w)
            .ok_or_else(|| fail(format!("I + G H is singular at doubling {doublings}")))?;
        let wa = lu.solve(&ak); // W^-1 A_k
        let wg = lu.solve(&gk); // W^-1 G_k
        let a_next = ak.mul(&wa);
        let g_next = gk.add(&ak.mul(&wg).mul_tr(&ak)).symmetric_part();
        let h_next = hk.add(&ak.tr_mul(&hk.mul(&wa))).symmetric_part();
        if !(a_next.is_finite() && g_next.is_finite() && h_next.is_finite()) {
            return Err(fail(format!(
                "the doubling overflowed at step {doublings} (no stabilizing solution)"
            )));
        }
        let change = h_next.sub(&hk).frobenius();
        let size = h_next.frobenius();
        ak = a_next;
        gk = g_next;
        hk = h_next;
        if change <= CHANGE_TOLERANCE * size {
            break;
        }
    }
    let x = hk;
    // K = (R + B^T X B)^-1 B^T X A and the residual of the equation.
    let xb = x.mul(b);
    let s = r.add(&b.tr_mul(&xb)).symmetric_part();
    let s_lu = Lu::new(&s).ok_or_else(|| fail("R + B^T X B is singular".into()))?;
    let bxa = xb.tr_mul(a); // B^T X A
    let gain = s_lu.solve(&bxa);
    let axa = a.tr_mul(&x.mul(a));
    let axbk = bxa.tr_mul(&gain); // A^T X B K
    let rhs = axa.sub(&axbk).add(q);
    let scale = x
        .frobenius()
        .max(axa.frobenius())
        .max(axbk.frobenius())
        .max(q.frobenius());
    let relative_residual = x.sub(&rhs).frobenius() / scale;
    if relative_residual.is_nan() || relative_residual > RESIDUAL_TOLERANCE {
        return Err(fail(format!(
            "the solution's relative residual {relative_residual:.3e} is over {RESIDUAL_TOLERANCE:.0e} \
             after {doublings} doublings"
        )));
    }
    let closed_loop_radius = spectral_radius(&a.sub(&b.mul(&gain)));
    if closed_loop_radius.is_nan() || closed_loop_radius >= 1.0 {
        return Err(fail(format!(
            "the closed loop is not stable (spectral radius {closed_loop_radius:.6})"
        )));
    }
    Ok(DareSolution {
        x,
        gain,
        closed_loop_radius,
        relative_residual,
        doublings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalar_equation_has_its_closed_form_solution() {
        // x = a^2 x - a^2 x^2 b^2 / (r + b^2 x) + q with a = 1.2, b = 1, q = 1, r = 1:
        // x^2 - a^2 x - 1 = 0 (after clearing r + x) -> x = (a^2 + sqrt(a^4 + 4)) / 2.
        let m = |v: f64| Matrix::from_row_major(1, 1, vec![v]);
        let sol = solve_dare(&m(1.2), &m(1.0), &m(1.0), &m(1.0), "test").unwrap();
        let a2: f64 = 1.44;
        let exact = (a2 + (a2 * a2 + 4.0).sqrt()) / 2.0;
        assert!((sol.x[(0, 0)] - exact).abs() < 1e-13 * exact);
        assert!(sol.closed_loop_radius < 1.0);
    }

    #[test]
    fn an_unstabilizable_pair_is_an_error() {
        // An unstable mode the input cannot reach.
        let a = Matrix::diagonal(&[1.5, 0.5]);
        let b = Matrix::from_row_major(2, 1, vec![0.0, 1.0]);
        let err = solve_dare(
            &a,
            &b,
            &Matrix::identity(2),
            &Matrix::identity(1),
            "test LQR",
        )
        .unwrap_err();
        assert!(err.to_string().contains("test LQR"), "{err}");
    }
}
