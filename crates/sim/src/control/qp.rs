//! A dense, strictly convex quadratic program solved exactly by the dual active-set method of
//! Goldfarb and Idnani (Math. Programming 27, 1983, pp. 1-33; the method of `quadprog`):
//!
//! ```text
//! min_x  1/2 x^T G x + g^T x     s.t.   lo_i <= c_i^T x <= hi_i   for every row i in use
//! ```
//!
//! with `G` symmetric positive definite, given once by `J0 = L^-T` (`G = L L^T`, [`QpFactor`]).
//! The method starts from the unconstrained minimizer `x = -G^-1 g` (the caller's) and adds the
//! most violated row at a time, dropping rows whose multiplier would turn negative, until no row
//! is violated by more than [`FEASIBILITY`]: every iterate minimizes the objective on its active
//! rows, so the end is the exact optimum up to rounding (the KKT residuals are at rounding level:
//! stationarity `G x + g - sum_i u_i n_i = 0`, `u_i >= 0`, `u_i = 0` off the active rows). It
//! keeps `J = L^-T Q` and the triangular `R` of `L^-1 N = Q [R; 0]` (`N`: the active rows' signed
//! normals), updated by Givens rotations when a row joins or leaves, so each step costs `O(n^2)`.
//!
//! Every sum runs in one fixed order with separate multiplications and additions (as
//! [`crate::control::matrix`]; the rotations use `sqrt`, which IEEE 754 rounds exactly, never
//! `hypot`), rows are chosen by a strict comparison in index order, and nothing is allocated per
//! solve ([`QpWork`]): the same inputs give the same bits on every CPU.

use crate::control::matrix::Matrix;

/// A row counts as violated when it misses its bound by more than this (in its own unit).
pub const FEASIBILITY: f64 = 1e-9;

/// One constraint row `c_i` (`x`'s length `n`).
#[derive(Debug, Clone, Copy)]
pub enum Row<'a> {
    /// `c = e_j`: a bound on `x_j`.
    Unit(usize),
    /// `c = (sign coef, 0, ..., 0) - e_slack`: a row on the leading `coef.len()` entries of
    /// `x`, relaxed by the slack variable `x_slack` (an upper bound `c^T x <= hi` on it is
    /// loosened by `x_slack >= 0`).
    Relaxed {
        /// The coefficients of the leading entries.
        coef: &'a [f64],
        /// `+1` or `-1`: the sign the coefficients are taken with.
        sign: f64,
        /// The slack variable's index.
        slack: usize,
    },
}

/// The rows of a QP: their number, each one's bounds and coefficients.
pub trait Rows {
    /// The number of rows (in use or not).
    fn len(&self) -> usize;
    /// Whether there are no rows.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The bounds `(lo, hi)` of row `i` (either may be infinite), `None` when it is not in use.
    fn bounds(&self, i: usize) -> Option<(f64, f64)>;
    /// The coefficients of row `i`.
    fn row(&self, i: usize) -> Row<'_>;
}

/// `c_i^T x`.
#[inline]
pub fn row_dot(row: Row<'_>, x: &[f64]) -> f64 {
    match row {
        Row::Unit(j) => x[j],
        Row::Relaxed { coef, sign, slack } => {
            let mut s = 0.0;
            for (c, v) in coef.iter().zip(x) {
                s += c * v;
            }
            sign * s - x[slack]
        }
    }
}

/// `G`'s factor `J0 = L^-T` (upper triangular, row-major), computed once per `G`.
#[derive(Debug, Clone)]
pub struct QpFactor {
    n: usize,
    j0: Vec<f64>,
}

impl QpFactor {
    /// The factor of a symmetric positive definite `g` (its lower triangle is read), or `None`
    /// when the Cholesky factorization meets a pivot that is not positive and finite.
    pub fn new(g: &Matrix) -> Option<Self> {
        let n = g.rows();
        assert_eq!(g.cols(), n, "a square matrix");
        // Cholesky, row by row: L (row-major, lower).
        let mut l = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..=i {
                let mut s = g[(i, j)];
                for k in 0..j {
                    s -= l[i * n + k] * l[j * n + k];
                }
                if i == j {
                    if !(s > 0.0 && s.is_finite()) {
                        return None;
                    }
                    l[i * n + i] = s.sqrt();
                } else {
                    l[i * n + j] = s / l[j * n + j];
                }
            }
        }
        // L^-1 by forward substitution, column by column; J0 = (L^-1)^T.
        let mut j0 = vec![0.0; n * n];
        for col in 0..n {
            // x = L^-1 e_col: x_i = 0 for i < col.
            for i in col..n {
                let mut s = if i == col { 1.0 } else { 0.0 };
                for k in col..i {
                    s -= l[i * n + k] * j0[col * n + k];
                }
                j0[col * n + i] = s / l[i * n + i];
            }
        }
        // j0 now holds (L^-1)^T row-major: row `col` is column `col` of L^-1, i.e. J0[col][i] =
        // (L^-1)[i][col].
        if j0.iter().all(|v| v.is_finite()) {
            Some(Self { n, j0 })
        } else {
            None
        }
    }

    /// The number of variables.
    pub fn n(&self) -> usize {
        self.n
    }
}

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpEnd {
    /// The optimum, after this many active-set steps (additions and drops).
    Solved(usize),
    /// The step limit was reached first (the iterate is feasible on its active rows only).
    Limit,
    /// No point keeps every row (a violated row whose normal lies in the span of active rows
    /// with no multiplier left to release).
    Infeasible,
    /// A non-finite value appeared.
    NotFinite,
}

/// The work space of [`solve`] for up to `n` variables and `m` rows (no allocation per solve).
#[derive(Debug, Clone)]
pub struct QpWork {
    n: usize,
    j: Vec<f64>,
    r: Vec<f64>,
    d: Vec<f64>,
    z: Vec<f64>,
    dir: Vec<f64>,
    u: Vec<f64>,
    active: Vec<(usize, f64)>,
    side: Vec<i8>,
}

impl QpWork {
    /// A work space for `n` variables and `m` rows.
    pub fn new(n: usize, m: usize) -> Self {
        Self {
            n,
            j: vec![0.0; n * n],
            r: vec![0.0; n * n],
            d: vec![0.0; n],
            z: vec![0.0; n],
            dir: vec![0.0; n + 1],
            u: vec![0.0; n + 1],
            active: Vec::with_capacity(n + 1),
            side: vec![0; m],
        }
    }

    /// The active rows of the last solve: `(row, sign)` (`+1`: at its lower bound, `-1`: at its
    /// upper bound) and the multipliers `u >= 0` in the same order.
    pub fn active(&self) -> (&[(usize, f64)], &[f64]) {
        (&self.active, &self.u[..self.active.len()])
    }
}

/// The signed slack `s = sign (c^T x - b)` of a row on one side (`b` the bound of that side).
#[inline]
fn signed_slack(row: Row<'_>, x: &[f64], sign: f64, lo: f64, hi: f64) -> f64 {
    let v = row_dot(row, x);
    if sign > 0.0 {
        v - lo
    } else {
        hi - v
    }
}

/// Minimizes the QP of `factor` (`G`) under `rows`, starting from `x` = the unconstrained
/// minimizer `-G^-1 g`, in at most `limit` active-set steps; `x` ends at the optimum when the
/// result is [`QpEnd::Solved`].
pub fn solve(
    factor: &QpFactor,
    rows: &impl Rows,
    x: &mut [f64],
    limit: usize,
    w: &mut QpWork,
) -> QpEnd {
    let n = factor.n;
    debug_assert_eq!(w.n, n);
    debug_assert_eq!(x.len(), n);
    debug_assert!(w.side.len() >= rows.len());
    w.j.copy_from_slice(&factor.j0);
    w.active.clear();
    w.side[..rows.len()].fill(0);
    let mut q = 0;
    let mut steps = 0;
    loop {
        // The most violated row not in the active set (strictly: the first in index order).
        let mut worst = -FEASIBILITY;
        let mut chosen = None;
        for i in 0..rows.len() {
            if w.side[i] != 0 {
                continue;
            }
            let Some((lo, hi)) = rows.bounds(i) else {
                continue;
            };
            let v = row_dot(rows.row(i), x);
            if !v.is_finite() {
                return QpEnd::NotFinite;
            }
            if v - lo < worst {
                worst = v - lo;
                chosen = Some((i, 1.0));
            }
            if hi - v < worst {
                worst = hi - v;
                chosen = Some((i, -1.0));
            }
        }
        let Some((p, sign)) = chosen else {
            // The active bounds on single variables hold exactly (the steps reach them up to
            // rounding).
            for &(i, sign) in &w.active {
                if let (Row::Unit(j), Some((lo, hi))) = (rows.row(i), rows.bounds(i)) {
                    x[j] = if sign > 0.0 { lo } else { hi };
                }
            }
            return QpEnd::Solved(steps);
        };
        let (lo, hi) = rows.bounds(p).expect("a row in use");
        let row = rows.row(p);
        w.u[q] = 0.0;
        loop {
            if steps >= limit {
                return QpEnd::Limit;
            }
            steps += 1;
            // d = J^T n+, n+ = sign c_p.
            match row {
                Row::Unit(jx) => {
                    for (k, d) in w.d.iter_mut().enumerate() {
                        *d = sign * w.j[jx * n + k];
                    }
                }
                Row::Relaxed {
                    coef,
                    sign: cs,
                    slack,
                } => {
                    w.d.fill(0.0);
                    for (k, c) in coef.iter().enumerate() {
                        let jr = &w.j[k * n..(k + 1) * n];
                        for (d, jv) in w.d.iter_mut().zip(jr) {
                            *d += c * jv;
                        }
                    }
                    let js = &w.j[slack * n..(slack + 1) * n];
                    for (d, jv) in w.d.iter_mut().zip(js) {
                        *d = sign * (cs * *d - jv);
                    }
                }
            }
            // Primal direction z = J2 d2, dual direction dir = R^-1 d1.
            for i in 0..n {
                let mut s = 0.0;
                for k in q..n {
                    s += w.j[i * n + k] * w.d[k];
                }
                w.z[i] = s;
            }
            for i in (0..q).rev() {
                let mut s = w.d[i];
                for k in i + 1..q {
                    s -= w.r[i * n + k] * w.dir[k];
                }
                w.dir[i] = s / w.r[i * n + i];
            }
            // The partial step: the first active multiplier to reach zero.
            let mut t1 = f64::INFINITY;
            let mut leaving = None;
            for k in 0..q {
                if w.dir[k] > 0.0 {
                    let t = w.u[k] / w.dir[k];
                    if t < t1 {
                        t1 = t;
                        leaving = Some(k);
                    }
                }
            }
            // The full step: the violated row reaches its bound.
            let mut d2 = 0.0;
            for k in q..n {
                d2 += w.d[k] * w.d[k];
            }
            let mut dd = 0.0;
            for v in &w.d {
                dd += v * v;
            }
            let mut zn = 0.0;
            match row {
                Row::Unit(jx) => zn = sign * w.z[jx],
                Row::Relaxed {
                    coef,
                    sign: cs,
                    slack,
                } => {
                    for (c, zv) in coef.iter().zip(&w.z) {
                        zn += c * zv;
                    }
                    zn = sign * (cs * zn - w.z[slack]);
                }
            }
            let t2 = if d2 <= 1e-24 * dd || zn <= 0.0 {
                f64::INFINITY
            } else {
                -signed_slack(row, x, sign, lo, hi) / zn
            };
            if !(t1.is_finite() || t2.is_finite()) {
                return QpEnd::Infeasible;
            }
            if !(t1.is_nan() || t2.is_nan()) && t2 <= t1 {
                // Full step, then row p joins the active set.
                for (xv, zv) in x.iter_mut().zip(&w.z) {
                    *xv += t2 * zv;
                }
                for k in 0..q {
                    w.u[k] -= t2 * w.dir[k];
                }
                w.u[q] += t2;
                add_row(w, q);
                w.active.push((p, sign));
                w.side[p] = if sign > 0.0 { 1 } else { -1 };
                q += 1;
                break;
            }
            // Partial step, then the blocking row leaves.
            let Some(l) = leaving else {
                return QpEnd::NotFinite;
            };
            if t2.is_finite() {
                for (xv, zv) in x.iter_mut().zip(&w.z) {
                    *xv += t1 * zv;
                }
            }
            for k in 0..q {
                w.u[k] -= t1 * w.dir[k];
            }
            w.u[q] += t1;
            w.u[l] = 0.0;
            drop_row(w, q, l);
            q -= 1;
            if !x.iter().all(|v| v.is_finite()) {
                return QpEnd::NotFinite;
            }
        }
        if !x.iter().all(|v| v.is_finite()) {
            return QpEnd::NotFinite;
        }
    }
}

/// Rotates `d`'s entries `q+1..n` into entry `q` (the same rotations on `J`'s columns) and makes
/// `d[..=q]` column `q` of `R`.
fn add_row(w: &mut QpWork, q: usize) {
    let n = w.n;
    for k in (q + 1..n).rev() {
        let (a, b) = (w.d[k - 1], w.d[k]);
        if b == 0.0 {
            continue;
        }
        let h = (a * a + b * b).sqrt();
        let (c, s) = (a / h, b / h);
        w.d[k - 1] = h;
        w.d[k] = 0.0;
        for i in 0..n {
            let (x1, x2) = (w.j[i * n + k - 1], w.j[i * n + k]);
            w.j[i * n + k - 1] = c * x1 + s * x2;
            w.j[i * n + k] = c * x2 - s * x1;
        }
    }
    for i in 0..=q {
        w.r[i * n + q] = w.d[i];
    }
}

/// Removes active position `l` of `q` (its column of `R`, its multiplier and its entry) and
/// restores `R`'s triangle by rotations of its rows (the same on `J`'s columns).
fn drop_row(w: &mut QpWork, q: usize, l: usize) {
    let n = w.n;
    let (p, _) = w.active.remove(l);
    w.side[p] = 0;
    for m in l..q {
        w.u[m] = w.u[m + 1];
    }
    for m in l..q - 1 {
        for i in 0..=m + 1 {
            w.r[i * n + m] = w.r[i * n + m + 1];
        }
    }
    for k in l..q - 1 {
        let (a, b) = (w.r[k * n + k], w.r[(k + 1) * n + k]);
        if b == 0.0 {
            continue;
        }
        let h = (a * a + b * b).sqrt();
        let (c, s) = (a / h, b / h);
        for m in k..q - 1 {
            let (x1, x2) = (w.r[k * n + m], w.r[(k + 1) * n + m]);
            w.r[k * n + m] = c * x1 + s * x2;
            w.r[(k + 1) * n + m] = c * x2 - s * x1;
        }
        w.r[(k + 1) * n + k] = 0.0;
        for i in 0..n {
            let (x1, x2) = (w.j[i * n + k], w.j[i * n + k + 1]);
            w.j[i * n + k] = c * x1 + s * x2;
            w.j[i * n + k + 1] = c * x2 - s * x1;
        }
    }
}

/// The KKT residuals of a solution `x` with the active rows and multipliers of `w`, for `G` and
/// `g`: `(stationarity, primal)`, the largest `|G x + g - sum_i u_i n_i|` and the largest bound
/// violation over the rows in use. (The multipliers are `>= 0` by construction.)
pub fn kkt_residuals(
    g_mat: &Matrix,
    g: &[f64],
    rows: &impl Rows,
    x: &[f64],
    w: &QpWork,
) -> (f64, f64) {
    let n = x.len();
    let mut grad = vec![0.0; n];
    g_mat.mul_vec_into(x, &mut grad);
    for (gr, gi) in grad.iter_mut().zip(g) {
        *gr += gi;
    }
    let (active, u) = w.active();
    for (&(i, sign), &ui) in active.iter().zip(u) {
        match rows.row(i) {
            Row::Unit(j) => grad[j] -= ui * sign,
            Row::Relaxed {
                coef,
                sign: cs,
                slack,
            } => {
                for (gr, c) in grad.iter_mut().zip(coef) {
                    *gr -= ui * sign * cs * c;
                }
                grad[slack] += ui * sign;
            }
        }
    }
    let stationarity = grad.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut primal = 0.0_f64;
    for i in 0..rows.len() {
        if let Some((lo, hi)) = rows.bounds(i) {
            let v = row_dot(rows.row(i), x);
            primal = primal.max(lo - v).max(v - hi);
        }
    }
    (stationarity, primal)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows given as dense vectors on `x` (the slack of `Relaxed` unused: index `n - 1` with a
    /// zero coefficient trick is not needed; every test row is a unit or relaxed row).
    struct Dense {
        units: Vec<(usize, f64, f64)>,
        relaxed: Vec<(Vec<f64>, usize, f64, f64)>,
    }

    impl Rows for Dense {
        fn len(&self) -> usize {
            self.units.len() + self.relaxed.len()
        }
        fn bounds(&self, i: usize) -> Option<(f64, f64)> {
            if i < self.units.len() {
                Some((self.units[i].1, self.units[i].2))
            } else {
                let r = &self.relaxed[i - self.units.len()];
                Some((r.2, r.3))
            }
        }
        fn row(&self, i: usize) -> Row<'_> {
            if i < self.units.len() {
                Row::Unit(self.units[i].0)
            } else {
                let r = &self.relaxed[i - self.units.len()];
                Row::Relaxed {
                    coef: &r.0,
                    sign: 1.0,
                    slack: r.1,
                }
            }
        }
    }

    fn unconstrained(g_mat: &Matrix, g: &[f64]) -> Vec<f64> {
        let lu = crate::control::matrix::Lu::new(g_mat).unwrap();
        let b = Matrix::from_fn(g.len(), 1, |i, _| -g[i]);
        let s = lu.solve(&b);
        (0..g.len()).map(|i| s[(i, 0)]).collect()
    }

    /// A small SPD matrix from a seed (fixed, hand-written pseudo-random entries).
    fn spd(n: usize, seed: u64) -> Matrix {
        let mut state = seed;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let a = Matrix::from_fn(n, n, |_, _| next());
        a.tr_mul(&a).add(&Matrix::identity(n).scale(0.1))
    }

    #[test]
    fn a_box_on_a_separable_objective_is_the_clipped_minimizer() {
        // min 1/2 (2 x0^2 + x1^2) - 4 x0 + x1, x in [-1, 1]^2: unconstrained (2, -1) -> (1, -1).
        let g_mat = Matrix::diagonal(&[2.0, 1.0]);
        let g = [-4.0, 1.0];
        let rows = Dense {
            units: vec![(0, -1.0, 1.0), (1, -1.0, 1.0)],
            relaxed: vec![],
        };
        let mut x = unconstrained(&g_mat, &g);
        assert_eq!(x, vec![2.0, -1.0]);
        let mut w = QpWork::new(2, rows.len());
        let end = solve(&QpFactor::new(&g_mat).unwrap(), &rows, &mut x, 50, &mut w);
        assert_eq!(end, QpEnd::Solved(1));
        assert_eq!(x, vec![1.0, -1.0]);
        // The multiplier of x0 <= 1 is the gradient there: 2 * 1 - 4 = -2, so u = 2.
        let (active, u) = w.active();
        assert_eq!(active, &[(0, -1.0)]);
        assert!((u[0] - 2.0).abs() < 1e-14);
    }

    #[test]
    fn the_optimum_matches_a_brute_force_over_active_sets() {
        // Random strictly convex QPs with box rows and general rows; the brute force solves the
        // equality QP of every subset of rows at either bound and keeps the best feasible point
        // whose multipliers are non-negative (the unique KKT point).
        for seed in 0..40 {
            let n = 4;
            let g_mat = spd(n, seed);
            let g: Vec<f64> = (0..n)
                .map(|i| ((seed as f64 + 1.0) * (i as f64 + 0.7)).sin() * 3.0)
                .collect();
            let c1: Vec<f64> = (0..n - 1)
                .map(|i| ((seed + 3 * i as u64) as f64).cos())
                .collect();
            let rows = Dense {
                units: vec![(0, -0.5, 0.5), (1, -0.3, 0.8), (2, -1.0, 0.2)],
                relaxed: vec![(c1, 3, -0.4, 0.4)],
            };
            let mut x = unconstrained(&g_mat, &g);
            let mut w = QpWork::new(n, rows.len());
            let end = solve(&QpFactor::new(&g_mat).unwrap(), &rows, &mut x, 100, &mut w);
            assert!(matches!(end, QpEnd::Solved(_)), "seed {seed}: {end:?}");
            let (stat, primal) = kkt_residuals(&g_mat, &g, &rows, &x, &w);
            assert!(
                stat < 1e-10 && primal < FEASIBILITY,
                "seed {seed}: {stat} {primal}"
            );
            assert!(w.active().1.iter().all(|&u| u >= 0.0));
            let best = brute_force(&g_mat, &g, &rows);
            for (a, b) in x.iter().zip(&best) {
                assert!((a - b).abs() < 1e-9, "seed {seed}: {x:?} vs {best:?}");
            }
        }
    }

    /// The minimizer by enumeration: for every assignment of each row to (free, lower, upper),
    /// the equality-constrained minimizer; the feasible one of lowest objective.
    fn brute_force(g_mat: &Matrix, g: &[f64], rows: &Dense) -> Vec<f64> {
        let n = g.len();
        let m = rows.len();
        let dense = |i: usize| -> Vec<f64> {
            let mut c = vec![0.0; n];
            match rows.row(i) {
                Row::Unit(j) => c[j] = 1.0,
                Row::Relaxed { coef, sign, slack } => {
                    for (ci, v) in c.iter_mut().zip(coef) {
                        *ci = sign * v;
                    }
                    c[slack] -= 1.0;
                }
            }
            c
        };
        let objective = |x: &[f64]| {
            let mut gx = vec![0.0; n];
            g_mat.mul_vec_into(x, &mut gx);
            (0..n)
                .map(|i| 0.5 * x[i] * gx[i] + g[i] * x[i])
                .sum::<f64>()
        };
        let mut best: Option<(f64, Vec<f64>)> = None;
        for code in 0..3usize.pow(m as u32) {
            let mut eq = Vec::new();
            let mut c = code;
            for i in 0..m {
                let (lo, hi) = rows.bounds(i).unwrap();
                match c % 3 {
                    1 => eq.push((dense(i), lo)),
                    2 => eq.push((dense(i), hi)),
                    _ => {}
                }
                c /= 3;
            }
            let k = eq.len();
            let kkt = Matrix::from_fn(n + k, n + k, |i, j| match (i < n, j < n) {
                (true, true) => g_mat[(i, j)],
                (true, false) => eq[j - n].0[i],
                (false, true) => eq[i - n].0[j],
                _ => 0.0,
            });
            let Some(lu) = crate::control::matrix::Lu::new(&kkt) else {
                continue;
            };
            let rhs = Matrix::from_fn(n + k, 1, |i, _| if i < n { -g[i] } else { eq[i - n].1 });
            let s = lu.solve(&rhs);
            let x: Vec<f64> = (0..n).map(|i| s[(i, 0)]).collect();
            let feasible = (0..m).all(|i| {
                let (lo, hi) = rows.bounds(i).unwrap();
                let v = row_dot(rows.row(i), &x);
                v >= lo - 1e-9 && v <= hi + 1e-9
            });
            if feasible {
                let f = objective(&x);
                if best.as_ref().is_none_or(|(bf, _)| f < *bf) {
                    best = Some((f, x));
                }
            }
        }
        best.unwrap().1
    }

    #[test]
    fn contradictory_rows_are_infeasible_never_nan() {
        // x0 >= 1 and x0 <= -1 given as two rows on the same variable.
        let g_mat = Matrix::identity(2);
        let rows = Dense {
            units: vec![(0, 1.0, f64::INFINITY), (0, f64::NEG_INFINITY, -1.0)],
            relaxed: vec![],
        };
        let mut x = vec![0.0, 0.0];
        let mut w = QpWork::new(2, rows.len());
        let end = solve(&QpFactor::new(&g_mat).unwrap(), &rows, &mut x, 50, &mut w);
        assert_eq!(end, QpEnd::Infeasible);
        assert!(x.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn a_matrix_that_is_not_positive_definite_has_no_factor() {
        assert!(QpFactor::new(&Matrix::diagonal(&[1.0, 0.0])).is_none());
        assert!(QpFactor::new(&Matrix::diagonal(&[1.0, f64::NAN])).is_none());
    }
}
