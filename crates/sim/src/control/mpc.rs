//! The MPC baseline: a linear model-predictive controller on the LQR's linearization and on its
//! Kalman filter's estimate ([`crate::control::filter`]), with the flap limits as hard
//! constraints and the capture's closing-speed limit as a soft constraint near the boom's
//! predicted arrival.
//!
//! # Problem (condensed, over `N` agent steps)
//! On the deviation from the LQR's offset-free reference, `e = dx - dx_ss`, `v = u - u_ss`
//! (`dx_ss`, `u_ss` of the current estimate of `w_y, w_z, r_y, r_z`; [`crate::control::lqr`]),
//! the plant is `e+ = A e + B v`, and
//!
//! ```text
//! min_V  sum_{k=1}^{N-1} e_k^T Q e_k + e_N^T P e_N + sum_{k=0}^{N-1} v_k^T R v_k
//!        + (s/2) sum_k |slack_k|^2
//! s.t.   -1 - u_ss <= v_k <= 1 - u_ss                                   (hard: the flap limits)
//!        |(V_cp e_k + V_cp dx_ss - r')_{y,z}| <= b + slack_k             (soft: near arrival)
//! ```
//!
//! with `Q`, `R` the LQR's weights and `P` its Riccati solution: without active constraints the
//! first command is the LQR's `u_ss - K e_0` (the same law up to rounding). `V_cp`: the capture
//! point's velocity per state, `r'` the boom tip's velocity (the estimate's, held over the
//! horizon). The velocity rows of step `k` are active where the predicted along-track distance
//! `|r_x + k T r'_x - P_x dx_0|` is under `window` or has changed sign (the boom's arrival), with
//! the per-axis bound `b = margin sqrt((c^2 - a^2) / 2)` (`c` = `boom.max_closing_speed`, `a` =
//! `boom.approach_speed`: the lateral box inside the closing-speed sphere left by the approach).
//!
//! # Solver
//! The unconstrained optimum `V* = -H^-1 f` is one precomputed product (`n` x `4N`); when it keeps
//! every active bound it is the answer. Otherwise ADMM (the OSQP iteration, dense) on
//! `min 1/2 V^T H V + f^T V s.t. l <= A V <= u`, `A = [I; C_v]`, with the matrix
//! `(H + sigma I + rho A^T A)^-1` precomputed, warm-started from `V*` clipped to the flap box
//! (duals zero), the flap rows projected onto their box and the velocity rows through the
//! proximal map of the quadratic slack penalty; it stops when the primal and dual residuals are
//! under [`TOLERANCE`]. The command is the first step's `u_ss + v_0`, clamped to [-1, 1].
//! **Fallback**: a solve that reaches `iterations` without converging ([`MpcStats::inexact`]) or
//! meets a non-finite estimate or iterate ([`MpcStats::fallbacks`]) returns the LQR's command
//! instead, and is counted. (An unconverged iterate flown as the command was measured to fly far
//! worse than the LQR.)
//!
//! Every sum runs in one fixed order with separate multiplications and additions, and each row
//! depends on nothing but its own estimate: the same bits whatever the batch, its size, the
//! threads or the CPU. No allocation per step ([`MpcScratch`] holds the work space).

use crate::control::filter::{FilterState, LqrFilter};
use crate::control::lqr::{EXTRA_STATES, MEASURED};
use crate::control::matrix::{dot, Lu, Matrix};
use crate::error::{Result, SimError};
use crate::task::linearize::WIND_DIM;
use crate::task::observation::{observation_index, ACT_DIM, OBSERVATION, OBS_DIM};

/// ADMM's stopping tolerance on the primal and dual residuals (flap-limit units, m/s).
pub const TOLERANCE: f64 = 1e-4;

/// ADMM's regularization of the primal step (relative to `rho`).
const SIGMA: f64 = 1e-6;

/// The MPC's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcTuning {
    /// Horizon `N` in agent steps.
    pub horizon: usize,
    /// Fraction of the lateral closing-speed bound the prediction must keep (-).
    pub speed_margin: f64,
    /// Along-track distance to the boom under which a step's velocity rows are active, m.
    pub window: f64,
    /// Weight of the squared slack of a velocity row, per (m/s)^2.
    pub slack_weight: f64,
    /// ADMM's penalty, relative to the mean diagonal of the QP's Hessian (-).
    pub rho: f64,
    /// ADMM's iteration limit.
    pub iterations: usize,
}

impl MpcTuning {
    /// The largest horizon accepted.
    pub const MAX_HORIZON: usize = 200;

    /// The settings, each checked: an error naming the field, the value and the allowed range.
    pub fn new(
        horizon: usize,
        speed_margin: f64,
        window: f64,
        slack_weight: f64,
        rho: f64,
        iterations: usize,
    ) -> Result<Self> {
        if !(1..=Self::MAX_HORIZON).contains(&horizon) {
            return Err(SimError::invalid_config(
                "mpc.horizon",
                horizon,
                &format!("[1, {}]", Self::MAX_HORIZON),
            ));
        }
        if !(speed_margin.is_finite() && speed_margin > 0.0 && speed_margin <= 1.0) {
            return Err(SimError::invalid_config(
                "mpc.speed_margin",
                speed_margin,
                "(0, 1]",
            ));
        }
        for (name, v) in [
            ("window", window),
            ("slack_weight", slack_weight),
            ("rho", rho),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(SimError::invalid_config(
                    &format!("mpc.{name}"),
                    v,
                    "(0, inf)",
                ));
            }
        }
        if !(1..=100_000).contains(&iterations) {
            return Err(SimError::invalid_config(
                "mpc.iterations",
                iterations,
                "[1, 100000]",
            ));
        }
        Ok(Self {
            horizon,
            speed_margin,
            window,
            slack_weight,
            rho,
            iterations,
        })
    }
}

/// The capture conditions the MPC keeps (`boom.max_closing_speed`, `boom.approach_speed`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureLimits {
    /// Largest relative speed at capture, m/s.
    pub max_closing_speed: f64,
    /// The boom's along-track approach speed, m/s.
    pub approach_speed: f64,
}

/// How the steps went (counts over every row stepped).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MpcStats {
    /// Rows stepped.
    pub steps: u64,
    /// Rows whose unconstrained optimum broke an active bound and whose ADMM converged.
    pub constrained: u64,
    /// Rows whose ADMM reached its iteration limit and that got the LQR's command.
    pub inexact: u64,
    /// Rows whose solve failed and that got the LQR's command.
    pub fallbacks: u64,
}

/// How one solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// The unconstrained optimum kept every active bound.
    Unconstrained,
    /// ADMM converged.
    Constrained,
    /// ADMM reached its iteration limit (finite but not converged): the fallback command is used.
    Inexact,
    /// The solve failed: the fallback command is used.
    Fallback,
}

/// The precomputed QP of one design (see the module docs).
#[derive(Debug, Clone)]
pub struct MpcPlan {
    n: usize,
    horizon: usize,
    dt: f64,
    tuning: MpcTuning,
    /// The per-axis lateral speed bound `b`, m/s.
    bound: f64,
    /// `dx_ss^T` per unit of `w_y, w_z, r_y, r_z` (4 x n).
    x_ss_t: Matrix,
    /// `u_ss` per unit of `w_y, w_z, r_y, r_z` (4 x 4).
    u_ss: Matrix,
    /// The capture point's along-track position per state (n).
    cp_x: Vec<f64>,
    /// The capture point's y, z velocity per state (2 x n).
    cpv_yz: Matrix,
    /// The unconstrained optimum per `e_0` (4N x n).
    kall: Matrix,
    /// The QP's Hessian (4N x 4N).
    hessian: Matrix,
    /// The velocity rows per `V` (2N x 4N): step k's (y, z) at rows 2(k-1), 2(k-1)+1.
    cv: Matrix,
    /// The velocity rows per `e_0` (2N x n).
    cv0: Matrix,
    /// `(H + sigma I + rho A^T A)^-1` (4N x 4N).
    admm: Matrix,
    /// ADMM's penalty (absolute).
    rho: f64,
}

/// The work space of [`MpcPlan::solve`] (no allocation per step).
#[derive(Debug, Clone)]
pub struct MpcScratch {
    e0: Vec<f64>,
    v: Vec<f64>,
    f: Vec<f64>,
    rhs: Vec<f64>,
    a: Vec<f64>,
    z: Vec<f64>,
    y: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    active: Vec<bool>,
}

impl MpcScratch {
    /// The plan `V` of the last solve (4N: step by step, four commands each, as deviations
    /// `v_k = u_k - u_ss`).
    pub fn plan(&self) -> &[f64] {
        &self.v
    }
}

impl MpcPlan {
    /// The plan for a plant `e+ = A e + B v` (`a` n x n, `b` n x 4) with the stage weights `q`
    /// (n x n), `r` (4 x 4), terminal weight `p` (n x n), the capture point's along-track
    /// position `cp_x` (n) and y, z velocity `cpv_yz` (2 x n) per state, the reference `x_ss`
    /// (n x 4) and `u_ss` (4 x 4) per unit of `w_y, w_z, r_y, r_z`, the agent step `dt`, the
    /// settings and the capture limits. [`SimError::Design`] when the QP's Hessian is singular.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        a: &Matrix,
        b: &Matrix,
        q: &Matrix,
        r: &Matrix,
        p: &Matrix,
        cp_x: &[f64],
        cpv_yz: &Matrix,
        x_ss: &Matrix,
        u_ss: &Matrix,
        dt: f64,
        tuning: MpcTuning,
        limits: CaptureLimits,
    ) -> Result<Self> {
        let n = a.rows();
        let horizon = tuning.horizon;
        let nv = ACT_DIM * horizon;
        let nc = 2 * horizon;
        // A^m B for m = 0..N-1.
        let mut powers_b = Vec::with_capacity(horizon);
        let mut ab = b.clone();
        for _ in 0..horizon {
            powers_b.push(ab.clone());
            ab = a.mul(&ab);
        }
        let mut hessian = Matrix::zeros(nv, nv);
        for k in 0..horizon {
            hessian.set_block(ACT_DIM * k, ACT_DIM * k, r);
        }
        let mut m = Matrix::zeros(nv, n);
        let mut cv = Matrix::zeros(nc, nv);
        let mut cv0 = Matrix::zeros(nc, n);
        let mut phi = Matrix::identity(n);
        for k in 1..=horizon {
            phi = a.mul(&phi);
            let mut gamma = Matrix::zeros(n, nv);
            for j in 0..k {
                gamma.set_block(0, ACT_DIM * j, &powers_b[k - 1 - j]);
            }
            let weight = if k == horizon { p } else { q };
            let qg = weight.mul(&gamma);
            hessian = hessian.add(&gamma.tr_mul(&qg));
            m = m.add(&qg.tr_mul(&phi));
            cv.set_block(2 * (k - 1), 0, &cpv_yz.mul(&gamma));
            cv0.set_block(2 * (k - 1), 0, &cpv_yz.mul(&phi));
        }
        let hessian = hessian.symmetric_part();
        let singular = || SimError::Design {
            what: "MPC".into(),
            reason: "the condensed QP's Hessian is singular".into(),
        };
        let kall = Lu::new(&hessian)
            .ok_or_else(singular)?
            .solve(&m)
            .scale(-1.0);
        let mean_diagonal = (0..nv).map(|i| hessian[(i, i)]).sum::<f64>() / nv as f64;
        let rho = tuning.rho * mean_diagonal;
        let mut kkt = hessian
            .add(&cv.tr_mul(&cv).scale(rho))
            .add(&Matrix::identity(nv).scale(rho * (1.0 + SIGMA)));
        kkt = kkt.symmetric_part();
        let admm = Lu::new(&kkt)
            .ok_or_else(singular)?
            .solve(&Matrix::identity(nv));
        let c = limits.max_closing_speed;
        let lateral = (c * c - limits.approach_speed * limits.approach_speed).max(0.0);
        let bound = tuning.speed_margin * (0.5 * lateral).sqrt();
        let plan = Self {
            n,
            horizon,
            dt,
            tuning,
            bound,
            x_ss_t: x_ss.transpose(),
            u_ss: u_ss.clone(),
            cp_x: cp_x.to_vec(),
            cpv_yz: cpv_yz.clone(),
            kall,
            hessian,
            cv,
            cv0,
            admm,
            rho,
        };
        if !(plan.kall.is_finite() && plan.admm.is_finite()) {
            return Err(SimError::Design {
                what: "MPC".into(),
                reason: "the condensed QP has non-finite entries".into(),
            });
        }
        Ok(plan)
    }

    /// The horizon `N`.
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// The per-axis lateral speed bound `b` (m/s).
    pub fn speed_bound(&self) -> f64 {
        self.bound
    }

    /// The unconstrained optimum's gain (4N x n; its first four rows are the first command's).
    pub fn unconstrained_gain(&self) -> &Matrix {
        &self.kall
    }

    /// A work space for [`Self::solve`].
    pub fn new_scratch(&self) -> MpcScratch {
        let nv = ACT_DIM * self.horizon;
        let rows = nv + 2 * self.horizon;
        MpcScratch {
            e0: vec![0.0; self.n],
            v: vec![0.0; nv],
            f: vec![0.0; nv],
            rhs: vec![0.0; nv],
            a: vec![0.0; rows],
            z: vec![0.0; rows],
            y: vec![0.0; rows],
            lo: vec![0.0; rows],
            hi: vec![0.0; rows],
            active: vec![false; rows],
        }
    }

    /// The command for the estimate `z = (dx, w, r, r')` (n + 8), or `fallback` when the solve
    /// fails (see the module docs), and how the solve ended.
    pub fn solve(
        &self,
        z: &[f64],
        fallback: [f64; ACT_DIM],
        s: &mut MpcScratch,
    ) -> ([f64; ACT_DIM], Outcome) {
        let n = self.n;
        let nv = ACT_DIM * self.horizon;
        debug_assert_eq!(z.len(), n + EXTRA_STATES);
        let (ir, iv) = (n + WIND_DIM, n + WIND_DIM + 3);
        let reference = [z[n], z[n + 1], z[ir + 1], z[ir + 2]];
        // e0 = dx - dx_ss, u_ss.
        for (i, e) in s.e0.iter_mut().enumerate() {
            *e = 0.0;
            for (j, rj) in reference.iter().enumerate() {
                *e += rj * self.x_ss_t[(j, i)];
            }
            *e = z[i] - *e;
        }
        let mut u_ss = [0.0; ACT_DIM];
        for (k, u) in u_ss.iter_mut().enumerate() {
            for (j, rj) in reference.iter().enumerate() {
                *u += self.u_ss[(k, j)] * rj;
            }
        }
        if !(s.e0.iter().all(|e| e.is_finite()) && u_ss.iter().all(|u| u.is_finite())) {
            return (fallback, Outcome::Fallback);
        }
        self.kall.mul_vec_into(&s.e0, &mut s.v);
        // Bounds: the flap rows, then the velocity rows (offsets moved into the bounds).
        for k in 0..self.horizon {
            for (j, u) in u_ss.iter().enumerate() {
                let i = ACT_DIM * k + j;
                s.lo[i] = -1.0 - u;
                s.hi[i] = 1.0 - u;
                s.active[i] = true;
            }
        }
        let along0 = z[ir] - dot(&self.cp_x, &z[..n]);
        let mut any_velocity = false;
        for k in 1..=self.horizon {
            let along = along0 + (k as f64 * self.dt) * z[iv];
            let near = along.abs() <= self.tuning.window || along * along0 <= 0.0;
            for axis in 0..2 {
                let row = 2 * (k - 1) + axis;
                let i = nv + row;
                s.active[i] = near;
                if near {
                    any_velocity = true;
                    let mut ss = 0.0;
                    for (j, rj) in reference.iter().enumerate() {
                        ss += rj * dot(self.cpv_yz.row(axis), self.x_ss_t.row(j));
                    }
                    let offset = dot(self.cv0.row(row), &s.e0) + ss - z[iv + 1 + axis];
                    s.lo[i] = -self.bound - offset;
                    s.hi[i] = self.bound - offset;
                } else {
                    s.lo[i] = f64::NEG_INFINITY;
                    s.hi[i] = f64::INFINITY;
                }
            }
        }
        // Rows of A V for V = V*.
        s.a[..nv].copy_from_slice(&s.v);
        if any_velocity {
            self.cv.mul_vec_into(&s.v, &mut s.a[nv..]);
        } else {
            s.a[nv..].fill(0.0);
        }
        let keeps =
            (0..s.a.len()).all(|i| !s.active[i] || (s.lo[i] <= s.a[i] && s.a[i] <= s.hi[i]));
        if keeps && s.v.iter().all(|v| v.is_finite()) {
            return (self.command(&s.v, u_ss), Outcome::Unconstrained);
        }
        // ADMM from V* clipped to the flap box.
        // f = -H V* (the linear term of the QP).
        self.hessian.mul_vec_into(&s.v, &mut s.f);
        s.f.iter_mut().for_each(|f| *f = -*f);
        for i in 0..nv {
            s.v[i] = s.v[i].clamp(s.lo[i], s.hi[i]);
        }
        s.a[..nv].copy_from_slice(&s.v);
        self.cv.mul_vec_into(&s.v, &mut s.a[nv..]);
        for i in 0..s.a.len() {
            s.z[i] = self.prox(i < nv, s.a[i], s.lo[i], s.hi[i]);
            s.y[i] = 0.0;
        }
        let rho = self.rho;
        let sigma = SIGMA * rho;
        for _ in 0..self.tuning.iterations {
            // rhs = sigma V - f + (rho z_u - y_u) + C_v^T (rho z_c - y_c).
            for i in 0..nv {
                s.rhs[i] = sigma * s.v[i] - s.f[i] + (rho * s.z[i] - s.y[i]);
            }
            for row in 0..2 * self.horizon {
                let c = rho * s.z[nv + row] - s.y[nv + row];
                for (r, cv) in s.rhs.iter_mut().zip(self.cv.row(row)) {
                    *r += c * cv;
                }
            }
            self.admm.mul_vec_into(&s.rhs, &mut s.v);
            s.a[..nv].copy_from_slice(&s.v);
            self.cv.mul_vec_into(&s.v, &mut s.a[nv..]);
            let (mut primal, mut dual) = (0.0_f64, 0.0_f64);
            for i in 0..s.a.len() {
                let ai = s.a[i];
                let zi = self.prox(i < nv, ai + s.y[i] / rho, s.lo[i], s.hi[i]);
                dual = dual.max(rho * (zi - s.z[i]).abs());
                s.z[i] = zi;
                s.y[i] += rho * (ai - zi);
                primal = primal.max((ai - zi).abs());
            }
            if !(primal.is_finite() && dual.is_finite()) {
                break;
            }
            if primal <= TOLERANCE && dual <= TOLERANCE && s.v.iter().all(|v| v.is_finite()) {
                return (self.command(&s.v, u_ss), Outcome::Constrained);
            }
        }
        if s.v.iter().all(|v| v.is_finite()) {
            (fallback, Outcome::Inexact)
        } else {
            (fallback, Outcome::Fallback)
        }
    }

    /// The proximal step of row `i`: the projection onto `[lo, hi]` for a flap row (`hard`), the
    /// minimizer of the slack penalty plus ADMM's quadratic for a velocity row.
    #[inline]
    fn prox(&self, hard: bool, v: f64, lo: f64, hi: f64) -> f64 {
        let p = v.clamp(lo, hi);
        if hard {
            p
        } else {
            p + (v - p) * (self.rho / (self.rho + self.tuning.slack_weight))
        }
    }

    fn command(&self, v: &[f64], u_ss: [f64; ACT_DIM]) -> [f64; ACT_DIM] {
        std::array::from_fn(|j| (u_ss[j] + v[j]).clamp(-1.0, 1.0))
    }
}

/// The MPC baseline of one design: the LQR's Kalman filter for the estimate and the fallback,
/// and the plan for the command.
#[derive(Debug, Clone)]
pub struct Mpc {
    filter: LqrFilter,
    plan: MpcPlan,
}

impl Mpc {
    /// The MPC of the LQR design given by its filter and parts: `F` (nz x nz), `G` (nz x 4),
    /// `H` (24 x nz) of the filter, the LQR's `Q` (n x n), `r_flap`, Riccati solution `P`
    /// (n x n), the reference `x_ss` (n x 4) and `u_ss` (4 x 4), the agent step `dt`, the settings
    /// and the capture limits. The capture point's position and velocity per state are read from
    /// `H`'s boom rows.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        filter: LqrFilter,
        f: &Matrix,
        g: &Matrix,
        h: &Matrix,
        q: &Matrix,
        r_flap: f64,
        p: &Matrix,
        x_ss: &Matrix,
        u_ss: &Matrix,
        dt: f64,
        tuning: MpcTuning,
        limits: CaptureLimits,
    ) -> Result<Self> {
        let n = filter.n();
        let nz = filter.nz();
        let shapes = [
            ("f", f, (nz, nz)),
            ("g", g, (nz, ACT_DIM)),
            ("h", h, (MEASURED.len(), nz)),
            ("q", q, (n, n)),
            ("p", p, (n, n)),
            ("x_ss", x_ss, (n, WIND_DIM + 2)),
            ("u_ss", u_ss, (ACT_DIM, WIND_DIM + 2)),
        ];
        for (name, m, (rows, cols)) in shapes {
            if (m.rows(), m.cols()) != (rows, cols) || !m.is_finite() {
                return Err(SimError::invalid_config(
                    &format!("mpc.{name}"),
                    format!("a {} x {} matrix", m.rows(), m.cols()),
                    &format!("a finite {rows} x {cols} matrix"),
                ));
            }
        }
        for (name, v) in [
            ("r_flap", r_flap),
            ("dt", dt),
            ("max_closing_speed", limits.max_closing_speed),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(SimError::invalid_config(
                    &format!("mpc.{name}"),
                    v,
                    "(0, inf)",
                ));
            }
        }
        if !(limits.approach_speed.is_finite() && limits.approach_speed >= 0.0) {
            return Err(SimError::invalid_config(
                "mpc.approach_speed",
                limits.approach_speed,
                "[0, inf)",
            ));
        }
        let row = |name: &str| {
            let obs = observation_index(name).expect("a name of the observation table");
            let k = MEASURED
                .iter()
                .position(|&m| m == obs)
                .expect("a measured entry");
            (k, OBSERVATION[obs].scale)
        };
        let (px, sp) = row("boom_rel_x");
        let cp_x: Vec<f64> = (0..n).map(|j| -h[(px, j)] / sp).collect();
        let (vy, svy) = row("boom_rel_vy");
        let (vz, svz) = row("boom_rel_vz");
        let cpv_yz = Matrix::from_fn(2, n, |i, j| {
            if i == 0 {
                -h[(vy, j)] / svy
            } else {
                -h[(vz, j)] / svz
            }
        });
        let a = f.block(0, 0, n, n);
        let b = g.block(0, 0, n, ACT_DIM);
        let r = Matrix::identity(ACT_DIM).scale(r_flap);
        let plan = MpcPlan::new(
            &a, &b, q, &r, p, &cp_x, &cpv_yz, x_ss, u_ss, dt, tuning, limits,
        )?;
        Ok(Self { filter, plan })
    }

    /// The filter (for new states).
    pub fn filter(&self) -> &LqrFilter {
        &self.filter
    }

    /// The plan (for new scratch space).
    pub fn plan(&self) -> &MpcPlan {
        &self.plan
    }

    /// One step for the rows `selected` selects: the LQR filter's step
    /// ([`LqrFilter::step_rows`]), then each row's MPC command from its estimate, which also
    /// becomes the command the row's next prediction uses. Adds to `stats`.
    pub fn step_rows(
        &self,
        states: &mut [FilterState],
        obs: &[[f64; OBS_DIM]],
        selected: &[bool],
        commands: &mut [[f32; ACT_DIM]],
        scratch: &mut MpcScratch,
        stats: &mut MpcStats,
    ) -> Result<()> {
        self.filter.step_rows(states, obs, selected, commands)?;
        for ((state, &chosen), command) in states.iter_mut().zip(selected).zip(commands.iter_mut())
        {
            if !chosen {
                continue;
            }
            let (u, outcome) = self.plan.solve(&state.z, state.u, scratch);
            stats.steps += 1;
            match outcome {
                Outcome::Unconstrained => {}
                Outcome::Constrained => stats.constrained += 1,
                Outcome::Inexact => stats.inexact += 1,
                Outcome::Fallback => stats.fallbacks += 1,
            }
            if u.iter().any(|v| !v.is_finite()) {
                return Err(SimError::Diverged {
                    time: 0.0,
                    reason: "the MPC's command is not finite".into(),
                });
            }
            state.u = u;
            *command = u.map(|v| v as f32);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::riccati::solve_dare;

    const DT: f64 = 0.1;

    /// A 1-axis double integrator `(p, v)` driven by the first command (the other three do
    /// nothing and cost `r`), its velocity the capture point's y velocity.
    fn double_integrator(horizon: usize, margin: f64) -> (MpcPlan, Matrix) {
        let a = Matrix::from_row_major(2, 2, vec![1.0, DT, 0.0, 1.0]);
        let b = Matrix::from_fn(2, ACT_DIM, |i, j| match (i, j) {
            (0, 0) => 0.5 * DT * DT,
            (1, 0) => DT,
            _ => 0.0,
        });
        let q = Matrix::diagonal(&[10.0, 1.0]);
        let r = Matrix::identity(ACT_DIM).scale(0.01);
        let p = solve_dare(&a, &b, &q, &r, "test").unwrap();
        let cpv = Matrix::from_row_major(2, 2, vec![0.0, 1.0, 0.0, 0.0]);
        let tuning = MpcTuning::new(horizon, margin, 1.0, 1e6, 1.0, 20_000).unwrap();
        let limits = CaptureLimits {
            max_closing_speed: 1.0,
            approach_speed: 0.0,
        };
        let plan = MpcPlan::new(
            &a,
            &b,
            &q,
            &r,
            &p.x,
            &[0.0, 0.0],
            &cpv,
            &Matrix::zeros(2, 4),
            &Matrix::zeros(ACT_DIM, 4),
            DT,
            tuning,
            limits,
        )
        .unwrap();
        (plan, p.gain)
    }

    /// The estimate `z` of the test plant: `(p, v)`, no wind, the boom at `boom_x` along track,
    /// at rest.
    fn estimate(p0: f64, v0: f64, boom_x: f64) -> Vec<f64> {
        let mut z = vec![0.0; 2 + EXTRA_STATES];
        z[0] = p0;
        z[1] = v0;
        z[2 + WIND_DIM] = boom_x;
        z
    }

    /// The predicted trajectory of a plan `V`.
    fn simulate(p0: f64, v0: f64, v: &[f64]) -> Vec<(f64, f64)> {
        let (mut p, mut vel) = (p0, v0);
        v.chunks(ACT_DIM)
            .map(|u| {
                p += DT * vel + 0.5 * DT * DT * u[0];
                vel += DT * u[0];
                (p, vel)
            })
            .collect()
    }

    #[test]
    fn without_active_constraints_the_first_command_is_the_lqr_s() {
        let (plan, k) = double_integrator(30, 1.0);
        for i in 0..ACT_DIM {
            for j in 0..2 {
                let (mpc, lqr) = (plan.unconstrained_gain()[(i, j)], -k[(i, j)]);
                assert!(
                    (mpc - lqr).abs() <= 1e-9 * (1.0 + lqr.abs()),
                    "{mpc} vs {lqr}"
                );
            }
        }
        let mut s = plan.new_scratch();
        // Far from the boom (no velocity rows) and close to the target: nothing is active.
        let (u, outcome) = plan.solve(&estimate(0.01, 0.0, 100.0), [9.0; 4], &mut s);
        assert_eq!(outcome, Outcome::Unconstrained);
        assert!((u[0] - (-k[(0, 0)] * 0.01)).abs() < 1e-12);
    }

    #[test]
    fn the_flap_limits_hold_where_the_unconstrained_optimum_breaks_them() {
        let (plan, k) = double_integrator(30, 1.0);
        let mut s = plan.new_scratch();
        // 5 m off: the LQR asks for -K (5, 0), far beyond the flap limit.
        assert!(k[(0, 0)] * 5.0 > 1.0);
        let (u, outcome) = plan.solve(&estimate(5.0, 0.0, 100.0), [9.0; 4], &mut s);
        assert_eq!(outcome, Outcome::Constrained);
        assert_eq!(u[0], -1.0);
        for v in s.plan() {
            assert!(v.abs() <= 1.0 + 10.0 * TOLERANCE, "{v}");
        }
    }

    #[test]
    fn the_velocity_bound_holds_on_the_prediction_near_the_boom() {
        let (plan, _) = double_integrator(40, 0.5);
        let b = plan.speed_bound();
        assert!((b - 0.5 * (0.5_f64).sqrt()).abs() < 1e-15);
        let mut s = plan.new_scratch();
        // Unconstrained, the velocity from 1 m off peaks well above b.
        let (_, free) = plan.solve(&estimate(1.0, 0.0, 100.0), [9.0; 4], &mut s);
        assert_ne!(free, Outcome::Fallback);
        let peak_free = simulate(1.0, 0.0, s.plan())
            .iter()
            .fold(0.0_f64, |m, x| m.max(x.1.abs()));
        assert!(peak_free > 2.0 * b, "{peak_free} vs {b}");
        // At the boom (along-track distance 0): every step's velocity row is active.
        let (u, outcome) = plan.solve(&estimate(1.0, 0.0, 0.0), [9.0; 4], &mut s);
        assert_eq!(outcome, Outcome::Constrained);
        assert!(u[0].abs() <= 1.0);
        let slack = 1e-3; // the heavy quadratic slack penalty leaves a small violation
        for (k, (_, v)) in simulate(1.0, 0.0, s.plan()).iter().enumerate() {
            assert!(v.abs() <= b + slack, "step {k}: {v} vs {b}");
        }
        // It still moves towards the target.
        assert!(u[0] < 0.0);
    }

    #[test]
    fn an_infeasible_start_is_softened_and_never_nan() {
        let (plan, _) = double_integrator(20, 0.5);
        let mut s = plan.new_scratch();
        // Already at 3 m/s at the boom: no flap sequence brings the velocity under b in one step.
        let (u, outcome) = plan.solve(&estimate(0.0, 3.0, 0.0), [0.25; 4], &mut s);
        assert!(u.iter().all(|v| v.is_finite() && v.abs() <= 1.0));
        assert_ne!(outcome, Outcome::Unconstrained);
        assert_ne!(outcome, Outcome::Fallback);
        if outcome == Outcome::Constrained {
            assert_eq!(u[0], -1.0, "full braking");
        } else {
            assert_eq!(u, [0.25; 4], "the fallback command");
        }
        // A non-finite estimate gives the fallback.
        let (u, outcome) = plan.solve(&estimate(f64::NAN, 0.0, 0.0), [0.25; 4], &mut s);
        assert_eq!((u, outcome), ([0.25; 4], Outcome::Fallback));
    }

    #[test]
    fn a_zero_horizon_is_a_config_error_naming_the_field() {
        let err = MpcTuning::new(0, 1.0, 1.0, 1.0, 1.0, 10).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("mpc.horizon") && text.contains("[1, 200]"),
            "{text}"
        );
    }
}
