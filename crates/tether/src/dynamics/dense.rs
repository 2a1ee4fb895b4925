//! The dense formulation of the equations of motion (paper Eq. 12): the mass matrix `M(q)`
//! assembled in full and solved by Cholesky, O(n^3), with the generalized forces `Q` from the
//! same kinematics and loads as the recursion ([`crate::recursive`]). The reference the O(n)
//! solver is tested against ([`super::Solver::Dense`]), not a hot path.

use nalgebra::{DMatrix, Vector3};

use super::TetherModel;

use crate::axial::AxialSolve;
use crate::distributed::{self, stretch_index};
use crate::error::{Result, TetherError};
use crate::surroundings::Surroundings;

type V3 = Vector3<f64>;

impl TetherModel {
    /// Generalized forces Q (right-hand side of the dense formulation) into `rhs`, from the loads
    /// already computed.
    fn generalized_forces(&mut self, q: &[f64], qd: &[f64], rhs: &mut [f64]) {
        let (s, sd) = (q[0], qd[0]);
        let half = 0.5 * self.l;
        let ws = &mut self.ws;
        if ws.com_acc0.len() != self.n {
            ws.com_acc0.resize(self.n, V3::zeros());
        }
        let ch = &ws.chain;
        let mut pa = ch.e_dot.get(0) * (2.0 * sd) + ch.w.get(0) * s;
        for k in 0..self.n {
            ws.com_acc0[k] = pa + ch.w.get(k) * half;
            pa += ch.w.get(k) * self.l;
        }
        ws.tip_acc0 = pa;
        let mut suffix = ch.tip_force - ws.tip_acc0 * self.tip_mass;
        let mut total = suffix;
        for k in (0..self.n).rev() {
            let h = ch.force.get(k) - ws.com_acc0[k] * self.m;
            let (a_kk, l_k) = if k == 0 {
                (half + s, self.l + s)
            } else {
                (half, self.l)
            };
            let g = h * a_kk + suffix * l_k + ch.extra.get(k);
            rhs[1 + 2 * k] = ch.e_phi.get(k).dot(&g);
            rhs[2 + 2 * k] = ch.e_psi.get(k).dot(&g);
            suffix += h;
            total += h;
        }
        rhs[0] = ch.e.get(0).dot(&total) - self.k * s - self.c_s * sd;
    }

    /// Assembles the lower triangle of the mass matrix M(q) into the workspace.
    fn assemble_mass(&mut self, s: f64) {
        let n = self.n;
        let dim = 2 * n + 1;
        let ws = &mut self.ws;
        let (m, l, tip) = (self.m, self.l, self.tip_mass);
        let half = 0.5 * l;
        if ws.mass.len() != dim * dim {
            ws.mass.resize(dim * dim, 0.0);
        }
        ws.mass[0] = n as f64 * m + tip;
        let ch = &ws.chain;
        let e1 = ch.e.get(0);
        for k in 0..n {
            let (a_kk, l_k) = if k == 0 { (half + s, l + s) } else { (half, l) };
            let beyond = m * (n - 1 - k) as f64 + tip;
            let v_k = m * a_kk + beyond * l_k;
            let w_kk = m * a_kk * a_kk + beyond * l_k * l_k + self.rod_inertia;
            let (jk_phi, jk_psi) = (ch.e_phi.get(k), ch.e_psi.get(k));
            let (rp, rs) = (1 + 2 * k, 2 + 2 * k);
            ws.mass[rp * dim] = v_k * e1.dot(&jk_phi);
            ws.mass[rs * dim] = v_k * e1.dot(&jk_psi);
            // Rows of segment k against segments j < k: W_jk = l_j V_k.
            for j in 0..k {
                let l_j = if j == 0 { l + s } else { l };
                let w = l_j * v_k;
                let (jj_phi, jj_psi) = (ch.e_phi.get(j), ch.e_psi.get(j));
                let (cp, cs) = (1 + 2 * j, 2 + 2 * j);
                ws.mass[rp * dim + cp] = w * jk_phi.dot(&jj_phi);
                ws.mass[rp * dim + cs] = w * jk_phi.dot(&jj_psi);
                ws.mass[rs * dim + cp] = w * jk_psi.dot(&jj_phi);
                ws.mass[rs * dim + cs] = w * jk_psi.dot(&jj_psi);
            }
            let cos_psi = ch.cos_psi[k];
            ws.mass[rp * dim + rp] = w_kk * cos_psi * cos_psi;
            ws.mass[rs * dim + rp] = 0.0;
            ws.mass[rs * dim + rs] = w_kk;
        }
    }

    /// [`TetherModel::accelerations_axial`] by the dense formulation: `M` and `Q` as
    /// [`TetherModel::accelerations_dense`] assembles them, the stretch rows' forces moved to
    /// the stage's arguments and their diagonal augmented, solved by Cholesky.
    pub(super) fn dense_axial<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        axial: &AxialSolve<'_>,
    ) -> Result<S::TipReport> {
        self.check_len("q", q)?;
        self.check_len("qd", qd)?;
        self.check_len("qdd", qdd)?;
        let report = self.prepare::<S>(time, q, qd, surroundings)?;
        let dim = self.dofs();
        let (elements, k, c) = if self.distributed {
            let cst = self.distributed_constants();
            if self.ws.mass.len() != dim * dim {
                self.ws.mass.resize(dim * dim, 0.0);
            }
            distributed::generalized_forces(&cst, &self.ws.chain, q, qd, qdd);
            distributed::assemble_mass(&cst, &self.ws.chain, q, &mut self.ws.mass);
            (self.n, self.element_k, self.element_c)
        } else {
            self.generalized_forces(q, qd, qdd);
            self.assemble_mass(q[0]);
            (1, self.k, self.c_s)
        };
        for e in 0..elements {
            let i = stretch_index(self.n, e);
            qdd[i] += k * (q[i] - axial.stretch[i]) + c * (qd[i] - axial.stretch_rate[i]);
            self.ws.mass[i * dim + i] += axial.added_mass;
        }
        cholesky_in_place(&mut self.ws.mass, dim).map_err(|col| TetherError::Diverged {
            time,
            reason: format!("mass matrix lost positive definiteness at column {col}"),
        })?;
        cholesky_solve(&self.ws.mass, dim, qdd);
        Ok(report)
    }

    /// [`TetherModel::accelerations`] by the dense formulation, whatever the configured solver:
    /// assembles M(q) (allocated on first use) and solves it by Cholesky, O(n^3). The reference.
    pub fn accelerations_dense<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
    ) -> Result<S::TipReport> {
        self.check_len("q", q)?;
        self.check_len("qd", qd)?;
        self.check_len("qdd", qdd)?;
        let report = self.prepare::<S>(time, q, qd, surroundings)?;
        if self.distributed {
            let c = self.distributed_constants();
            let dim = self.dofs();
            if self.ws.mass.len() != dim * dim {
                self.ws.mass.resize(dim * dim, 0.0);
            }
            distributed::generalized_forces(&c, &self.ws.chain, q, qd, qdd);
            distributed::assemble_mass(&c, &self.ws.chain, q, &mut self.ws.mass);
        } else {
            self.generalized_forces(q, qd, qdd);
            self.assemble_mass(q[0]);
        }
        let dim = self.dofs();
        cholesky_in_place(&mut self.ws.mass, dim).map_err(|col| TetherError::Diverged {
            time,
            reason: format!("mass matrix lost positive definiteness at column {col}"),
        })?;
        cholesky_solve(&self.ws.mass, dim, qdd);
        if !self.distributed {
            self.axial_mass = dense_axial_mass(&self.ws.mass, dim, &mut self.ws.unit);
        }
        Ok(report)
    }

    /// The mass matrix M(q) (symmetric, dim x dim). Allocates; for analysis and tests.
    pub fn mass_matrix(&mut self, q: &[f64]) -> Result<DMatrix<f64>> {
        self.check_len("q", q)?;
        self.ws.chain.directions(q);
        let dim = self.dofs();
        if self.distributed {
            let c = self.distributed_constants();
            if self.ws.mass.len() != dim * dim {
                self.ws.mass.resize(dim * dim, 0.0);
            }
            distributed::assemble_mass(&c, &self.ws.chain, q, &mut self.ws.mass);
        } else {
            self.assemble_mass(q[0]);
        }
        Ok(DMatrix::from_fn(dim, dim, |r, c| {
            let (r, c) = if r >= c { (r, c) } else { (c, r) };
            self.ws.mass[r * dim + c]
        }))
    }

    /// [`TetherModel::tensions`] by the dense formulation: the accelerations by
    /// [`TetherModel::accelerations_dense`], then Newton's law for everything outboard of each
    /// joint.
    pub(super) fn tensions_dense<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        tensions: &mut [f64],
    ) -> Result<()> {
        self.accelerations_dense(time, q, qd, surroundings, qdd)?;
        if self.distributed {
            // A massless element carries its own force: the tension at the inboard end of
            // segment k is n k s_k + n c_s s_k' (the element's equation of motion); the tip's
            // pull is Newton's law for the tip body with the accelerations just solved.
            let mut acc = V3::zeros();
            let ch = &self.ws.chain;
            for k in 0..self.n {
                let (s, sd) = self.stretch(q, qd, k);
                let i = stretch_index(self.n, k);
                tensions[k] = self.element_k * s + self.element_c * sd;
                let (e, ep, es) = (ch.e.get(k), ch.e_phi.get(k), ch.e_psi.get(k));
                let edd = ch.w.get(k) + ep * qdd[1 + 2 * k] + es * qdd[2 + 2 * k];
                acc += e * qdd[i] + ch.e_dot.get(k) * (2.0 * sd) + edd * (s + self.l);
            }
            tensions[self.n] = (ch.tip_force - acc * self.tip_mass).dot(&ch.e.get(self.n - 1));
            return Ok(());
        }
        let ws = &self.ws;
        let (s, sd, sdd) = (q[0], qd[0], qdd[0]);
        let ch = &ws.chain;
        let acc_dir = |k: usize| {
            ch.w.get(k) + ch.e_phi.get(k) * qdd[1 + 2 * k] + ch.e_psi.get(k) * qdd[2 + 2 * k]
        };
        let e1dd = acc_dir(0);
        let mut pa = ch.e.get(0) * sdd + ch.e_dot.get(0) * (2.0 * sd) + e1dd * s;
        // Accelerations of centres, stored in place of nothing: accumulate forward, then sum backward.
        // Two passes keep it allocation-free: first the tip acceleration, then walk inward.
        for k in 0..self.n {
            pa += acc_dir(k) * self.l;
        }
        let mut pull = ch.tip_force - pa * self.tip_mass;
        tensions[self.n] = pull.dot(&ch.e.get(self.n - 1));
        // Walk inward: the base of segment k is the tip position minus l e_j for j >= k.
        let mut base_acc = pa;
        for k in (0..self.n).rev() {
            let ek_dd = acc_dir(k);
            base_acc -= ek_dd * self.l;
            let com_acc = base_acc + ek_dd * (0.5 * self.l);
            pull += ch.force.get(k) - com_acc * self.m;
            tensions[k] = pull.dot(&ch.e.get(k));
        }
        Ok(())
    }
}

/// In-place Cholesky factorisation of the lower triangle of a row-major `dim x dim` matrix.
/// Returns the failing column if the matrix is not (numerically) positive definite.
fn cholesky_in_place(a: &mut [f64], dim: usize) -> std::result::Result<(), usize> {
    for j in 0..dim {
        let row_j = j * dim;
        let mut d = a[row_j + j];
        for k in 0..j {
            d -= a[row_j + k] * a[row_j + k];
        }
        if !(d.is_finite() && d > 0.0) {
            return Err(j);
        }
        let d = d.sqrt();
        a[row_j + j] = d;
        let inv = 1.0 / d;
        for i in (j + 1)..dim {
            let row_i = i * dim;
            let mut v = a[row_i + j];
            for k in 0..j {
                v -= a[row_i + k] * a[row_j + k];
            }
            a[row_i + j] = v * inv;
        }
    }
    Ok(())
}

/// `1 / (M^-1)_00` from the Cholesky factor L of M ([`cholesky_in_place`]): `(M^-1)_00 =
/// |L^-1 e_0|^2`, by forward substitution into `unit` (resized to `dim` on first use).
fn dense_axial_mass(l: &[f64], dim: usize, unit: &mut Vec<f64>) -> f64 {
    if unit.len() != dim {
        unit.resize(dim, 0.0);
    }
    let mut sum = 0.0;
    for i in 0..dim {
        let row = i * dim;
        let mut v = if i == 0 { 1.0 } else { 0.0 };
        for k in 0..i {
            v -= l[row + k] * unit[k];
        }
        unit[i] = v / l[row + i];
        sum += unit[i] * unit[i];
    }
    1.0 / sum
}

/// Solves L L^T x = b in place, with L from [`cholesky_in_place`].
fn cholesky_solve(l: &[f64], dim: usize, b: &mut [f64]) {
    for i in 0..dim {
        let row = i * dim;
        let mut v = b[i];
        for k in 0..i {
            v -= l[row + k] * b[k];
        }
        b[i] = v / l[row + i];
    }
    for i in (0..dim).rev() {
        let mut v = b[i];
        for k in (i + 1)..dim {
            v -= l[k * dim + i] * b[k];
        }
        b[i] = v / l[i * dim + i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_spd_system() {
        let a = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let mut l = a;
        cholesky_in_place(&mut l, 3).unwrap();
        let mut x = [1.0, 2.0, 3.0];
        cholesky_solve(&l, 3, &mut x);
        for r in 0..3 {
            let ax: f64 = (0..3).map(|c| a[r * 3 + c] * x[c]).sum();
            assert!((ax - [1.0, 2.0, 3.0][r]).abs() < 1e-12);
        }
        let mut bad = [1.0, 2.0, 2.0, 1.0];
        assert_eq!(cholesky_in_place(&mut bad, 2), Err(1));
    }
}
