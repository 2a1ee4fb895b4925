//! The LQR baseline's per-step work: the Kalman filter's predict and update, then the control
//! law, for one env (the design: [`crate::control::lqr`]).
//!
//! ```text
//! z- = F z + G u_sent                     (predict with the command actually sent; z- = 0 at an episode's start)
//! z  = z- + L (y_m - y*_m - H z-)          (update with the observation)
//! u  = clip(-K dx + K_ff (w_y, w_z, r_y, r_z), -1, 1)
//! ```
//!
//! Every sum runs over its index in ascending order with separate multiplications and additions
//! (the matrices are stored transposed so that each term is a scaled column added to the
//! outputs, which the compiler vectorizes across outputs without reordering any one sum): a
//! row's result depends on nothing but its own inputs, the same bits on every CPU, with any
//! batch size and any number of threads. No allocation per step: each env's [`FilterState`]
//! holds its scratch space.

use crate::control::lqr::{LqrDesign, EXTRA_STATES, MEASURED, MEASURED_DIM};
use crate::control::matrix::Matrix;
use crate::error::{Result, SimError};
use crate::task::linearize::WIND_DIM;
use crate::task::observation::{ACT_DIM, OBS_DIM};

/// The matrices of one design in the layout the step reads (see the module docs).
#[derive(Debug, Clone)]
pub struct LqrFilter {
    n: usize,
    /// `F^T` (nz x nz): row j is column j of `F`.
    ft: Matrix,
    /// `G^T` (4 x nz).
    gt: Matrix,
    /// `H^T` (nz x 24).
    ht: Matrix,
    /// `L^T` (24 x nz).
    lt: Matrix,
    /// `K^T` (n x 4).
    kt: Matrix,
    /// `K_ff^T` (4 x 4).
    kfft: Matrix,
    y_trim: [f64; MEASURED_DIM],
}

/// One env's filter state: the estimate `z`, the last command sent `u` (flap-limit units), and
/// whether the next observation starts an episode; plus its scratch space.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterState {
    /// The estimate `z = (dx, w, r, r')`.
    pub z: Vec<f64>,
    /// The command the next prediction uses.
    pub u: [f64; ACT_DIM],
    /// Whether the next observation initialises the estimate (one update from zero).
    pub fresh: bool,
    prior: Vec<f64>,
}

impl FilterState {
    /// A state that starts afresh at its next observation.
    pub fn new(nz: usize) -> Self {
        Self {
            z: vec![0.0; nz],
            u: [0.0; ACT_DIM],
            fresh: true,
            prior: vec![0.0; nz],
        }
    }
}

impl LqrFilter {
    /// The step's form of a design.
    pub fn new(design: &LqrDesign) -> Self {
        Self::from_parts(
            design.n,
            &design.f,
            &design.g,
            &design.h,
            &design.l,
            &design.k,
            &design.k_ff,
            design.y_trim,
        )
        .expect("a design's matrices have its shapes")
    }

    /// The filter from a design's matrices (`n` plant states; `F` nz x nz, `G` nz x 4, `H`
    /// 24 x nz, `L` nz x 24, `K` 4 x n, `K_ff` 4 x 4, `nz = n + 8`): an error naming the
    /// matrix whose shape does not fit, or a non-finite entry.
    #[allow(clippy::too_many_arguments)]
    pub fn from_parts(
        n: usize,
        f: &Matrix,
        g: &Matrix,
        h: &Matrix,
        l: &Matrix,
        k: &Matrix,
        k_ff: &Matrix,
        y_trim: [f64; MEASURED_DIM],
    ) -> Result<Self> {
        let nz = n + EXTRA_STATES;
        let shapes = [
            ("f", f, (nz, nz)),
            ("g", g, (nz, ACT_DIM)),
            ("h", h, (MEASURED_DIM, nz)),
            ("l", l, (nz, MEASURED_DIM)),
            ("k", k, (ACT_DIM, n)),
            ("k_ff", k_ff, (ACT_DIM, WIND_DIM + 2)),
        ];
        for (name, m, (rows, cols)) in shapes {
            if (m.rows(), m.cols()) != (rows, cols) {
                return Err(SimError::invalid_config(
                    &format!("lqr.{name}"),
                    format!("a {} x {} matrix", m.rows(), m.cols()),
                    &format!("a {rows} x {cols} matrix"),
                ));
            }
            if !m.is_finite() {
                return Err(SimError::invalid_config(
                    &format!("lqr.{name}"),
                    "a matrix with non-finite entries",
                    "finite entries",
                ));
            }
        }
        if y_trim.iter().any(|y| !y.is_finite()) {
            return Err(SimError::invalid_config(
                "lqr.y_trim",
                "non-finite entries",
                "finite entries",
            ));
        }
        Ok(Self {
            n,
            ft: f.transpose(),
            gt: g.transpose(),
            ht: h.transpose(),
            lt: l.transpose(),
            kt: k.transpose(),
            kfft: k_ff.transpose(),
            y_trim,
        })
    }

    /// Plant states `n`.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Observer states `nz`.
    pub fn nz(&self) -> usize {
        self.n + EXTRA_STATES
    }

    /// A state for this filter that starts afresh.
    pub fn new_state(&self) -> FilterState {
        FilterState::new(self.nz())
    }

    /// One step for one env: predicts from `state` with its last command, updates with the
    /// observation `obs` (the env's, all 25 entries), writes the command to `command` and keeps
    /// it (as f64) as the command the next prediction uses. [`SimError::Diverged`] if the
    /// command is not finite (an estimate that overflowed): never a NaN command.
    pub fn step(
        &self,
        state: &mut FilterState,
        obs: &[f64; OBS_DIM],
        command: &mut [f32; ACT_DIM],
    ) -> Result<()> {
        let nz = self.nz();
        debug_assert_eq!(state.z.len(), nz);
        let prior = &mut state.prior;
        prior.fill(0.0);
        if !state.fresh {
            for (j, zj) in state.z.iter().enumerate() {
                axpy(prior, *zj, self.ft.row(j));
            }
            for (k, uk) in state.u.iter().enumerate() {
                axpy(prior, *uk, self.gt.row(k));
            }
        }
        let mut predicted = [0.0; MEASURED_DIM];
        for (j, pj) in prior.iter().enumerate() {
            axpy(&mut predicted, *pj, self.ht.row(j));
        }
        let mut innovation = [0.0; MEASURED_DIM];
        for (m, &i) in MEASURED.iter().enumerate() {
            innovation[m] = (obs[i] - self.y_trim[m]) - predicted[m];
        }
        // z = z- + L innovation: the correction summed first (into z), then the prior added.
        let mut u = [0.0; ACT_DIM];
        let z = &mut state.z;
        z.fill(0.0);
        for (m, im) in innovation.iter().enumerate() {
            axpy(z, *im, self.lt.row(m));
        }
        for (zi, pi) in z.iter_mut().zip(prior.iter()) {
            *zi += *pi;
        }
        for (j, zj) in z[..self.n].iter().enumerate() {
            axpy(&mut u, -*zj, self.kt.row(j));
        }
        let n = self.n;
        let reference = [z[n], z[n + 1], z[n + WIND_DIM + 1], z[n + WIND_DIM + 2]];
        let mut feedforward = [0.0; ACT_DIM];
        for (r, rr) in reference.iter().enumerate() {
            axpy(&mut feedforward, *rr, self.kfft.row(r));
        }
        for (k, c) in command.iter_mut().enumerate() {
            let v = (u[k] + feedforward[k]).clamp(-1.0, 1.0);
            if !v.is_finite() {
                return Err(SimError::Diverged {
                    time: 0.0,
                    reason: "the LQR's Kalman filter estimate is not finite".into(),
                });
            }
            state.u[k] = v;
            *c = v as f32;
        }
        state.fresh = false;
        Ok(())
    }
}

/// `y += a x`, element by element (each output one addition: vectorizes across outputs).
#[inline]
fn axpy(y: &mut [f64], a: f64, x: &[f64]) {
    debug_assert_eq!(y.len(), x.len());
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}
