//! Dense matrices with every operation in one fixed order of floating-point operations.
//!
//! The controller's design and its filter must give the same bits on every CPU, whatever the
//! vector width or the library a general-purpose routine would dispatch to (BLAS kernels choose
//! their summation order, blocking and fused multiply-adds by the processor). Here every sum is
//! a plain loop over its index in ascending order with separate multiplications and additions
//! (Rust never contracts them into fused multiply-adds), so the compiler may vectorize across
//! independent outputs but never reorders one output's sum. No allocation happens inside the
//! operations that take an output buffer.

/// A dense row-major matrix of `f64`.
#[derive(Debug, Clone, PartialEq)]
pub struct Matrix {
    rows: usize,
    cols: usize,
    data: Vec<f64>,
}

impl Matrix {
    /// A `rows` x `cols` matrix of zeros.
    pub fn zeros(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            data: vec![0.0; rows * cols],
        }
    }

    /// The `n` x `n` identity.
    pub fn identity(n: usize) -> Self {
        let mut m = Self::zeros(n, n);
        for i in 0..n {
            m[(i, i)] = 1.0;
        }
        m
    }

    /// A matrix from row-major values (`data.len() == rows * cols`).
    pub fn from_row_major(rows: usize, cols: usize, data: Vec<f64>) -> Self {
        assert_eq!(
            data.len(),
            rows * cols,
            "row-major data of a {rows} x {cols} matrix"
        );
        Self { rows, cols, data }
    }

    /// A matrix whose entry `(i, j)` is `f(i, j)`.
    pub fn from_fn(rows: usize, cols: usize, mut f: impl FnMut(usize, usize) -> f64) -> Self {
        let mut data = Vec::with_capacity(rows * cols);
        for i in 0..rows {
            for j in 0..cols {
                data.push(f(i, j));
            }
        }
        Self { rows, cols, data }
    }

    /// A diagonal matrix.
    pub fn diagonal(values: &[f64]) -> Self {
        let mut m = Self::zeros(values.len(), values.len());
        for (i, v) in values.iter().enumerate() {
            m[(i, i)] = *v;
        }
        m
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Number of columns.
    pub fn cols(&self) -> usize {
        self.cols
    }

    /// The values, row-major.
    pub fn as_slice(&self) -> &[f64] {
        &self.data
    }

    /// Row `i`.
    pub fn row(&self, i: usize) -> &[f64] {
        &self.data[i * self.cols..(i + 1) * self.cols]
    }

    /// The transpose.
    pub fn transpose(&self) -> Self {
        Self::from_fn(self.cols, self.rows, |i, j| self[(j, i)])
    }

    /// `self * other`; entry `(i, j)` is `sum_k self[i, k] * other[k, j]` summed over ascending k.
    pub fn mul(&self, other: &Matrix) -> Matrix {
        assert_eq!(self.cols, other.rows, "inner dimensions of a product");
        let mut out = Matrix::zeros(self.rows, other.cols);
        let n = other.cols;
        for i in 0..self.rows {
            let o = &mut out.data[i * n..(i + 1) * n];
            for k in 0..self.cols {
                let a = self.data[i * self.cols + k];
                let b = &other.data[k * n..(k + 1) * n];
                for (oj, bj) in o.iter_mut().zip(b) {
                    *oj += a * bj;
                }
            }
        }
        out
    }

    /// `self^T * other`, without forming the transpose (same order of sums as
    /// `self.transpose().mul(other)`).
    pub fn tr_mul(&self, other: &Matrix) -> Matrix {
        assert_eq!(self.rows, other.rows, "inner dimensions of a product");
        let mut out = Matrix::zeros(self.cols, other.cols);
        let n = other.cols;
        for i in 0..self.cols {
            let o = &mut out.data[i * n..(i + 1) * n];
            for k in 0..self.rows {
                let a = self.data[k * self.cols + i];
                let b = &other.data[k * n..(k + 1) * n];
                for (oj, bj) in o.iter_mut().zip(b) {
                    *oj += a * bj;
                }
            }
        }
        out
    }

    /// `self * other^T`: entry `(i, j)` is the dot product of row i of `self` and row j of
    /// `other`, summed over ascending k.
    pub fn mul_tr(&self, other: &Matrix) -> Matrix {
        assert_eq!(self.cols, other.cols, "inner dimensions of a product");
        Matrix::from_fn(self.rows, other.rows, |i, j| dot(self.row(i), other.row(j)))
    }

    /// `self + other`.
    pub fn add(&self, other: &Matrix) -> Matrix {
        self.zip(other, |a, b| a + b)
    }

    /// `self - other`.
    pub fn sub(&self, other: &Matrix) -> Matrix {
        self.zip(other, |a, b| a - b)
    }

    /// `s * self`.
    pub fn scale(&self, s: f64) -> Matrix {
        Matrix {
            rows: self.rows,
            cols: self.cols,
            data: self.data.iter().map(|x| s * x).collect(),
        }
    }

    fn zip(&self, other: &Matrix, f: impl Fn(f64, f64) -> f64) -> Matrix {
        assert_eq!(
            (self.rows, self.cols),
            (other.rows, other.cols),
            "shapes of an element-wise operation"
        );
        Matrix {
            rows: self.rows,
            cols: self.cols,
            data: self
                .data
                .iter()
                .zip(&other.data)
                .map(|(a, b)| f(*a, *b))
                .collect(),
        }
    }

    /// `(self + self^T) / 2` (a square matrix made exactly symmetric).
    pub fn symmetric_part(&self) -> Matrix {
        assert_eq!(self.rows, self.cols, "symmetric part of a square matrix");
        Matrix::from_fn(self.rows, self.cols, |i, j| {
            0.5 * (self[(i, j)] + self[(j, i)])
        })
    }

    /// The Frobenius norm, summed row by row in ascending order.
    pub fn frobenius(&self) -> f64 {
        self.data.iter().fold(0.0, |s, x| s + x * x).sqrt()
    }

    /// The largest absolute entry.
    pub fn max_abs(&self) -> f64 {
        self.data.iter().fold(0.0_f64, |m, x| m.max(x.abs()))
    }

    /// Whether every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.data.iter().all(|x| x.is_finite())
    }

    /// The block of `rows` x `cols` entries starting at `(r0, c0)`.
    pub fn block(&self, r0: usize, c0: usize, rows: usize, cols: usize) -> Matrix {
        Matrix::from_fn(rows, cols, |i, j| self[(r0 + i, c0 + j)])
    }

    /// Writes `m` into the block starting at `(r0, c0)`.
    pub fn set_block(&mut self, r0: usize, c0: usize, m: &Matrix) {
        for i in 0..m.rows {
            for j in 0..m.cols {
                self[(r0 + i, c0 + j)] = m[(i, j)];
            }
        }
    }

    /// `y = self * x`: each entry a dot product over ascending column index (no allocation).
    pub fn mul_vec_into(&self, x: &[f64], y: &mut [f64]) {
        debug_assert_eq!(x.len(), self.cols);
        debug_assert_eq!(y.len(), self.rows);
        for (i, yi) in y.iter_mut().enumerate() {
            *yi = dot(self.row(i), x);
        }
    }
}

impl std::ops::Index<(usize, usize)> for Matrix {
    type Output = f64;
    #[inline]
    fn index(&self, (i, j): (usize, usize)) -> &f64 {
        debug_assert!(i < self.rows && j < self.cols);
        &self.data[i * self.cols + j]
    }
}

impl std::ops::IndexMut<(usize, usize)> for Matrix {
    #[inline]
    fn index_mut(&mut self, (i, j): (usize, usize)) -> &mut f64 {
        debug_assert!(i < self.rows && j < self.cols);
        &mut self.data[i * self.cols + j]
    }
}

/// `sum_k a[k] * b[k]` over ascending k, one multiplication and one addition per term.
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    let mut s = 0.0;
    for (x, y) in a.iter().zip(b) {
        s += x * y;
    }
    s
}

/// An LU factorization with partial pivoting, `P A = L U` (the pivot of each column: the first
/// entry of largest magnitude on or below the diagonal).
#[derive(Debug, Clone)]
pub struct Lu {
    lu: Matrix,
    pivots: Vec<usize>,
}

impl Lu {
    /// Factors the square matrix `a`; `None` when a pivot is zero or not finite (singular or
    /// overflowed).
    pub fn new(a: &Matrix) -> Option<Self> {
        assert_eq!(a.rows, a.cols, "LU of a square matrix");
        let n = a.rows;
        let mut lu = a.clone();
        let mut pivots = Vec::with_capacity(n);
        for k in 0..n {
            let mut p = k;
            let mut best = lu[(k, k)].abs();
            for i in k + 1..n {
                let v = lu[(i, k)].abs();
                if v > best {
                    best = v;
                    p = i;
                }
            }
            if best == 0.0 || !best.is_finite() {
                return None;
            }
            if p != k {
                for j in 0..n {
                    lu.data.swap(k * n + j, p * n + j);
                }
            }
            pivots.push(p);
            let pivot = lu[(k, k)];
            for i in k + 1..n {
                let f = lu[(i, k)] / pivot;
                lu[(i, k)] = f;
                if f != 0.0 {
                    let (upper, lower) = lu.data.split_at_mut(i * n);
                    let rk = &upper[k * n + k + 1..k * n + n];
                    let ri = &mut lower[k + 1..n];
                    for (x, y) in ri.iter_mut().zip(rk) {
                        *x -= f * y;
                    }
                }
            }
        }
        Some(Self { lu, pivots })
    }

    /// `A^-1 b` for a matrix of right-hand sides `b` (one column each).
    pub fn solve(&self, b: &Matrix) -> Matrix {
        let n = self.lu.rows;
        assert_eq!(b.rows, n, "rows of the right-hand side");
        let m = b.cols;
        let mut x = b.clone();
        for (k, &p) in self.pivots.iter().enumerate() {
            if p != k {
                for j in 0..m {
                    x.data.swap(k * m + j, p * m + j);
                }
            }
        }
        // Forward substitution with the unit lower triangle, row by row.
        for i in 1..n {
            let (done, rest) = x.data.split_at_mut(i * m);
            let xi = &mut rest[..m];
            for k in 0..i {
                let f = self.lu[(i, k)];
                if f != 0.0 {
                    for (a, b) in xi.iter_mut().zip(&done[k * m..(k + 1) * m]) {
                        *a -= f * b;
                    }
                }
            }
        }
        // Back substitution with the upper triangle.
        for i in (0..n).rev() {
            let (head, tail) = x.data.split_at_mut((i + 1) * m);
            let xi = &mut head[i * m..];
            for k in i + 1..n {
                let f = self.lu[(i, k)];
                if f != 0.0 {
                    for (a, b) in xi.iter_mut().zip(&tail[(k - i - 1) * m..(k - i) * m]) {
                        *a -= f * b;
                    }
                }
            }
            let d = self.lu[(i, i)];
            for a in xi.iter_mut() {
                *a /= d;
            }
        }
        x
    }

    /// `max |U_ii| / min |U_ii|`: a cheap lower bound of the condition number, for error messages
    /// and checks.
    pub fn pivot_ratio(&self) -> f64 {
        let n = self.lu.rows;
        let (mut lo, mut hi) = (f64::INFINITY, 0.0_f64);
        for i in 0..n {
            let d = self.lu[(i, i)].abs();
            lo = lo.min(d);
            hi = hi.max(d);
        }
        hi / lo
    }
}

/// The minimum-norm solution `x` of the underdetermined system `m x = rhs` (`m` of full row
/// rank, fewer rows than columns; one column of `x` per column of `rhs`), by a Householder QR
/// factorization of `m^T = Q R`: `x = Q [R^-T rhs; 0]`. Returns the smallest over the largest
/// `|R_ii|` as the error when it is below `rcond` (numerically rank deficient: the minimum-norm
/// solution would depend on where the singular values are cut).
pub fn min_norm_solve(m: &Matrix, rhs: &Matrix, rcond: f64) -> std::result::Result<Matrix, f64> {
    let (q, p) = (m.rows, m.cols);
    assert!(q <= p, "a minimum-norm solve of an underdetermined system");
    assert_eq!(rhs.rows, q, "rows of the right-hand side");
    let mut n = m.transpose(); // p x q
    let mut reflectors: Vec<(Vec<f64>, f64)> = Vec::with_capacity(q);
    let mut diag = Vec::with_capacity(q);
    for k in 0..q {
        let mut v: Vec<f64> = (k..p).map(|i| n[(i, k)]).collect();
        let norm = v.iter().fold(0.0, |s, x| s + x * x).sqrt();
        let alpha = if v[0] > 0.0 { -norm } else { norm };
        v[0] -= alpha;
        let vv = v.iter().fold(0.0, |s, x| s + x * x);
        diag.push(alpha);
        if vv > 0.0 {
            for j in k + 1..q {
                let mut s = 0.0;
                for (i, vi) in v.iter().enumerate() {
                    s += vi * n[(k + i, j)];
                }
                let f = 2.0 * s / vv;
                for (i, vi) in v.iter().enumerate() {
                    n[(k + i, j)] -= f * vi;
                }
            }
        }
        reflectors.push((v, vv));
    }
    let hi = diag.iter().fold(0.0_f64, |m, d| m.max(d.abs()));
    let lo = diag.iter().fold(f64::INFINITY, |m, d| m.min(d.abs()));
    if lo.is_nan() || lo <= rcond * hi {
        return Err(lo / hi);
    }
    // w = R^-T rhs (R^T is lower triangular: forward substitution), then x = Q [w; 0].
    let cols = rhs.cols;
    let mut x = Matrix::zeros(p, cols);
    for i in 0..q {
        for c in 0..cols {
            let mut s = rhs[(i, c)];
            for k in 0..i {
                s -= n[(k, i)] * x[(k, c)];
            }
            x[(i, c)] = s / diag[i];
        }
    }
    for (k, (v, vv)) in reflectors.iter().enumerate().rev() {
        if *vv == 0.0 {
            continue;
        }
        for c in 0..cols {
            let mut s = 0.0;
            for (i, vi) in v.iter().enumerate() {
                s += vi * x[(k + i, c)];
            }
            let f = 2.0 * s / vv;
            for (i, vi) in v.iter().enumerate() {
                x[(k + i, c)] -= f * vi;
            }
        }
    }
    Ok(x)
}

/// The spectral radius of a square matrix, from the norms of its repeated squares:
/// `rho(M) = lim ||M^m||^(1/m)`, `m = 2^k`, each square normalized to keep it finite (Gelfand's
/// formula). With `k` = 40 squarings a constant factor `c` in `||M^m|| ~ c rho^m` changes the
/// estimate by `c^(1/m)`, below 1e-10 relative for any `c` under 1e40.
pub fn spectral_radius(m: &Matrix) -> f64 {
    let mut norm = m.frobenius();
    if norm == 0.0 || !norm.is_finite() {
        return norm;
    }
    let mut log = norm.ln();
    let mut weight = 1.0;
    let mut x = m.scale(1.0 / norm);
    for _ in 0..40 {
        let sq = x.mul(&x);
        norm = sq.frobenius();
        if norm == 0.0 {
            return 0.0; // nilpotent
        }
        weight *= 0.5;
        log = 2.0 * log + norm.ln();
        x = sq.scale(1.0 / norm);
    }
    (log * weight).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> Matrix {
        Matrix::from_row_major(3, 3, vec![2.0, 1.0, 1.0, 4.0, -6.0, 0.0, -2.0, 7.0, 2.0])
    }

    #[test]
    fn products_agree_with_each_other_and_the_hand_result() {
        let a = example();
        let b = Matrix::from_fn(3, 2, |i, j| (i + 2 * j) as f64 - 1.0);
        let ab = a.mul(&b);
        assert_eq!(ab, a.transpose().tr_mul(&b));
        assert_eq!(ab, a.mul_tr(&b.transpose()));
        assert_eq!(ab[(1, 1)], 4.0 * 1.0 - 6.0 * 2.0);
    }

    #[test]
    fn lu_solves_and_refuses_a_singular_matrix() {
        let a = example();
        let x = Matrix::from_fn(3, 2, |i, j| 1.0 + i as f64 - j as f64);
        let b = a.mul(&x);
        let lu = Lu::new(&a).unwrap();
        let got = lu.solve(&b);
        assert!(got.sub(&x).max_abs() < 1e-14, "{got:?}");
        let singular = Matrix::from_row_major(2, 2, vec![1.0, 2.0, 2.0, 4.0]);
        assert!(Lu::new(&singular).is_none());
    }

    #[test]
    fn min_norm_solve_gives_the_pseudo_inverse_solution() {
        // x + y + 2 z = 4: the minimum-norm solution is (1, 1, 2) * 4 / 6.
        let m = Matrix::from_row_major(1, 3, vec![1.0, 1.0, 2.0]);
        let x = min_norm_solve(&m, &Matrix::from_row_major(1, 1, vec![4.0]), 1e-10).unwrap();
        let want = [4.0 / 6.0, 4.0 / 6.0, 8.0 / 6.0];
        for (i, w) in want.iter().enumerate() {
            assert!((x[(i, 0)] - w).abs() < 1e-15, "{x:?}");
        }
        let deficient = Matrix::from_row_major(2, 3, vec![1.0, 1.0, 2.0, 2.0, 2.0, 4.0]);
        assert!(min_norm_solve(&deficient, &Matrix::zeros(2, 1), 1e-10).is_err());
    }

    #[test]
    fn spectral_radius_of_a_rotation_and_a_jordan_block() {
        let (c, s) = (0.9 * 0.3_f64.cos(), 0.9 * 0.3_f64.sin());
        let rot = Matrix::from_row_major(2, 2, vec![c, -s, s, c]);
        assert!((spectral_radius(&rot) - 0.9).abs() < 1e-12);
        let jordan = Matrix::from_row_major(2, 2, vec![0.5, 100.0, 0.0, 0.5]);
        assert!((spectral_radius(&jordan) - 0.5).abs() < 1e-9);
    }
}
