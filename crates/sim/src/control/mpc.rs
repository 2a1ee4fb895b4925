//! The MPC baseline: a linear model-predictive controller on the LQR's linearization and on its
//! Kalman filter's estimate ([`crate::control::filter`]), with the flap limits as hard
//! constraints and the capture conditions (closing speed and capture radius) as a softened
//! terminal set from the boom's predicted arrival on.
//!
//! # Problem (condensed, over `N` agent steps)
//! On the deviation from the LQR's offset-free reference, `e = dx - dx_ss`, `v = u - u_ss`
//! (`dx_ss`, `u_ss` of the current estimate of `w_y, w_z, r_y, r_z`; [`crate::control::lqr`]),
//! the plant is `e+ = A e + B v`, and
//!
//! ```text
//! min_{V, s_v, s_p}  sum_{k=1}^{N-1} e_k^T Q e_k + e_N^T P e_N + sum_{k=0}^{N-1} v_k^T R v_k
//!                    + 2 w (s_v + s_v^2 / 2) + 2 w (s_p + s_p^2 / 2)
//! s.t.  -1 - u_ss <= v_k <= 1 - u_ss                          (hard: the flap limits)
//!       |n_f . (V_cp x_k - r'_yz)| <= b_k + s_v,  f = 1..4     (speed rows, step k in S_v)
//!       |n_f . (P_cp x_k - r_yz - k T r'_yz)| <= rho + s_p     (position rows, step k in S_p)
//!       s_v, s_p >= 0
//! ```
//!
//! with `Q`, `R` the LQR's weights and `P` its Riccati solution: without active constraints the
//! first command is the LQR's `u_ss - K e_0` (the same law up to rounding). `x_k = e_k + dx_ss`;
//! `V_cp`, `P_cp`: the capture point's y, z velocity and position per state; `r`, `r'` the boom
//! tip relative to the trim capture point and its velocity (the estimate's, held over the
//! horizon); `w` = `slack_weight`. The capture conditions are a disk each (relative speed under
//! `boom.max_closing_speed` = `c`, distance under `boom.capture_radius` = `R`), kept on the y-z
//! plane by the regular octagon inscribed in the disk: the facet normals `n_f` at 0, 45, 90 and
//! 135 degrees, the bounds `b_k = margin sqrt(c^2 - a_k^2) cos(pi/8)` and
//! `rho = margin R cos(pi/8)` (`a_k`: the along-track closing speed, the estimate's `|r'_x|` capped
//! at `boom.approach_speed` before the predicted arrival, 0 from it on, since the boom then keeps
//! station with the capture point). The predicted along-track distance is
//! `d_k = r_x + k T r'_x - P_x dx_0`; the arrival is the first step where it changes sign or
//! comes within the capture radius (the boom then keeps station: every later step counts). The
//! speed rows hold at the steps with `|d_k| <= window` and from the arrival on (`S_v`), the
//! position rows from the arrival on (`S_p`), both only from step `lead` on: a terminal set the
//! capture lies in, asked of the steps the flaps can still shape. The one slack per
//! condition (the largest violation over the horizon) keeps the problem feasible when the state
//! cannot reach the set in time, at the exact-penalty price `w` per unit: where the set can be
//! reached and the multipliers are under `w`, the slacks are zero.
//!
//! # Solver
//! The unconstrained optimum `V* = -H^-1 f` is one precomputed product (`n` x `4N`); when it keeps
//! every row in use (with zero slacks) it is the answer. Otherwise the exact dual active-set
//! method ([`crate::control::qp`], Goldfarb-Idnani) starts from it, with `G = diag(H, w, w)`
//! factored once per design; it ends at the optimum up to rounding (no tolerance to tune). The
//! command is the first step's `u_ss + v_0`, clamped to [-1, 1].
//! **Fallback**: a solve that reaches `iterations` active-set steps ([`MpcStats::inexact`]) or
//! meets a non-finite estimate, an infeasible problem or a non-finite iterate
//! ([`MpcStats::fallbacks`]) returns the LQR's command instead, and is counted.
//!
//! Every sum runs in one fixed order with separate multiplications and additions, and each row
//! depends on nothing but its own estimate: the same bits whatever the batch, its size, the
//! threads or the CPU. No allocation per step ([`MpcScratch`] holds the work space).

use crate::control::filter::{FilterState, LqrFilter};
use crate::control::lqr::{EXTRA_STATES, MEASURED};
use crate::control::matrix::{dot, Lu, Matrix};
use crate::control::qp::{self, QpEnd, QpFactor, QpWork, Row, Rows};
use crate::error::{Result, SimError};
use crate::task::linearize::WIND_DIM;
use crate::task::observation::{observation_index, ACT_DIM, OBSERVATION, OBS_DIM};

/// The facets of the regular octagon inscribed in a disk: unit normals at 0, 45, 90, 135 deg.
const FACETS: [[f64; 2]; 4] = [
    [1.0, 0.0],
    [
        std::f64::consts::FRAC_1_SQRT_2,
        std::f64::consts::FRAC_1_SQRT_2,
    ],
    [0.0, 1.0],
    [
        -std::f64::consts::FRAC_1_SQRT_2,
        std::f64::consts::FRAC_1_SQRT_2,
    ],
];

/// `cos(pi/8)`, the inscribed octagon's apothem per unit radius, `sqrt(2 + sqrt 2) / 2`.
fn apothem() -> f64 {
    (2.0 + std::f64::consts::SQRT_2).sqrt() * 0.5
}

/// The MPC's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcTuning {
    /// Horizon `N` in agent steps.
    pub horizon: usize,
    /// The first step `k_0` of the horizon the capture conditions hold at (1..=N): the steps
    /// before it are left to the flaps' authority to change the state.
    pub lead: usize,
    /// Fraction of the closing-speed limit and of the capture radius the prediction keeps (-).
    pub margin: f64,
    /// Along-track distance to the boom under which a step's speed rows hold before the
    /// predicted arrival, m.
    pub window: f64,
    /// The exact-penalty weight `w` of the slacks (per m/s of speed, per m of position; half of
    /// it again per unit squared).
    pub slack_weight: f64,
    /// The active-set step limit of one solve.
    pub iterations: usize,
}

impl MpcTuning {
    /// The largest horizon accepted.
    pub const MAX_HORIZON: usize = 200;

    /// The settings, each checked: an error naming the field, the value and the allowed range.
    pub fn new(
        horizon: usize,
        lead: usize,
        margin: f64,
        window: f64,
        slack_weight: f64,
        iterations: usize,
    ) -> Result<Self> {
        if !(1..=Self::MAX_HORIZON).contains(&horizon) {
            return Err(SimError::invalid_config(
                "mpc.horizon",
                horizon,
                &format!("[1, {}]", Self::MAX_HORIZON),
            ));
        }
        if !(1..=horizon).contains(&lead) {
            return Err(SimError::invalid_config(
                "mpc.lead",
                lead,
                &format!("[1, horizon = {horizon}]"),
            ));
        }
        if !(margin.is_finite() && margin > 0.0 && margin <= 1.0) {
            return Err(SimError::invalid_config("mpc.margin", margin, "(0, 1]"));
        }
        for (name, v) in [("window", window), ("slack_weight", slack_weight)] {
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
            lead,
            margin,
            window,
            slack_weight,
            iterations,
        })
    }
}

/// The capture conditions the MPC keeps (`boom.max_closing_speed`, `boom.capture_radius`,
/// `boom.approach_speed`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureLimits {
    /// Largest relative speed at capture, m/s.
    pub max_closing_speed: f64,
    /// Largest distance at capture, m.
    pub capture_radius: f64,
    /// The boom's largest along-track approach speed, m/s.
    pub approach_speed: f64,
}

/// How the steps went (counts over every row stepped).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MpcStats {
    /// Rows stepped.
    pub steps: u64,
    /// Rows whose unconstrained optimum broke a row in use and that were solved exactly.
    pub constrained: u64,
    /// Rows whose solve reached the active-set step limit and that got the LQR's command.
    pub inexact: u64,
    /// Rows whose solve failed (a non-finite value, an infeasible problem) and that got the
    /// LQR's command.
    pub fallbacks: u64,
}

/// How one solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// The unconstrained optimum kept every row in use.
    Unconstrained,
    /// The active-set method reached the optimum.
    Constrained,
    /// The active-set method reached its step limit: the fallback command is used.
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
    limits: CaptureLimits,
    /// `dx_ss^T` per unit of `w_y, w_z, r_y, r_z` (4 x n).
    x_ss_t: Matrix,
    /// `u_ss` per unit of `w_y, w_z, r_y, r_z` (4 x 4).
    u_ss: Matrix,
    /// The capture point's along-track position per state (n).
    cp_x: Vec<f64>,
    /// The facets' capture-point velocity and position per unit of `w_y, w_z, r_y, r_z`
    /// (8 x 4: speed facets 0..4, position facets 4..8) through `dx_ss`.
    facet_ss: Matrix,
    /// The unconstrained optimum per `e_0` (4N x n).
    kall: Matrix,
    /// The QP's Hessian `G = diag(H, w, w)` ((4N + 2) x (4N + 2)).
    hessian: Matrix,
    /// `G`'s factor.
    factor: QpFactor,
    /// The linear term of `V` per `e_0` (4N x n): `f = M e_0`.
    linear: Matrix,
    /// The facet rows per `V`: step k's speed facet f at row 8(k-1) + f, position facet f at
    /// 8(k-1) + 4 + f (8N x 4N).
    rows_v: Matrix,
    /// The facet rows per `e_0` (8N x n).
    rows_e: Matrix,
}

/// The work space of [`MpcPlan::solve`] (no allocation per step).
#[derive(Debug, Clone)]
pub struct MpcScratch {
    e0: Vec<f64>,
    x: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    used: Vec<bool>,
    work: QpWork,
}

impl MpcScratch {
    /// The plan `V` of the last solve (4N: step by step, four commands each, as deviations
    /// `v_k = u_k - u_ss`).
    pub fn plan(&self) -> &[f64] {
        &self.x[..self.x.len() - 2]
    }

    /// The slacks `(s_v, s_p)` of the last solve (m/s, m).
    pub fn slacks(&self) -> (f64, f64) {
        let n = self.x.len();
        (self.x[n - 2], self.x[n - 1])
    }
}

/// The rows of one solve: the flap rows, the two slack bounds, then each facet row twice (its
/// upper bound `n . y - s <= b`, then its lower bound as `-n . y - s <= b`, each loosened by its
/// condition's slack).
struct PlanRows<'a> {
    plan: &'a MpcPlan,
    lo: &'a [f64],
    hi: &'a [f64],
    used: &'a [bool],
}

impl Rows for PlanRows<'_> {
    fn len(&self) -> usize {
        self.lo.len()
    }

    fn bounds(&self, i: usize) -> Option<(f64, f64)> {
        self.used[i].then(|| (self.lo[i], self.hi[i]))
    }

    fn row(&self, i: usize) -> Row<'_> {
        let nv = ACT_DIM * self.plan.horizon;
        if i < nv + 2 {
            Row::Unit(i)
        } else {
            let facet = (i - nv - 2) / 2;
            Row::Relaxed {
                coef: self.plan.rows_v.row(facet),
                sign: if (i - nv - 2) % 2 == 0 { 1.0 } else { -1.0 },
                slack: nv + usize::from(facet % 8 >= 4),
            }
        }
    }
}

impl MpcPlan {
    /// The plan for a plant `e+ = A e + B v` (`a` n x n, `b` n x 4) with the stage weights `q`
    /// (n x n), `r` (4 x 4), terminal weight `p` (n x n), the capture point's along-track
    /// position `cp_x` (n), its y, z position `cp_yz` (2 x n) and y, z velocity `cpv_yz`
    /// (2 x n) per state, the reference `x_ss` (n x 4) and `u_ss` (4 x 4) per unit of
    /// `w_y, w_z, r_y, r_z`, the agent step `dt`, the settings and the capture limits.
    /// [`SimError::Design`] when the QP's Hessian is not positive definite.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        a: &Matrix,
        b: &Matrix,
        q: &Matrix,
        r: &Matrix,
        p: &Matrix,
        cp_x: &[f64],
        cp_yz: &Matrix,
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
        // The facets' rows per state: speed facets on the velocity, position facets on the
        // position (8 x n).
        let facet_state = Matrix::from_fn(8, n, |f, j| {
            let (m, normal) = if f < 4 {
                (cpv_yz, FACETS[f])
            } else {
                (cp_yz, FACETS[f - 4])
            };
            normal[0] * m[(0, j)] + normal[1] * m[(1, j)]
        });
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
        let mut rows_v = Matrix::zeros(8 * horizon, nv);
        let mut rows_e = Matrix::zeros(8 * horizon, n);
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
            rows_v.set_block(8 * (k - 1), 0, &facet_state.mul(&gamma));
            rows_e.set_block(8 * (k - 1), 0, &facet_state.mul(&phi));
        }
        let hessian = hessian.symmetric_part();
        let singular = || SimError::Design {
            what: "MPC".into(),
            reason: "the condensed QP's Hessian is not positive definite".into(),
        };
        let kall = Lu::new(&hessian)
            .ok_or_else(singular)?
            .solve(&m)
            .scale(-1.0);
        let w = tuning.slack_weight;
        let mut g = Matrix::zeros(nv + 2, nv + 2);
        g.set_block(0, 0, &hessian);
        g[(nv, nv)] = w;
        g[(nv + 1, nv + 1)] = w;
        let factor = QpFactor::new(&g).ok_or_else(singular)?;
        let plan = Self {
            n,
            horizon,
            dt,
            tuning,
            limits,
            x_ss_t: x_ss.transpose(),
            u_ss: u_ss.clone(),
            cp_x: cp_x.to_vec(),
            facet_ss: facet_state.mul(x_ss),
            kall,
            hessian: g,
            factor,
            linear: m,
            rows_v,
            rows_e,
        };
        if !(plan.kall.is_finite() && plan.rows_v.is_finite() && plan.facet_ss.is_finite()) {
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

    /// The position facets' bound `rho` (m).
    pub fn radius_bound(&self) -> f64 {
        self.tuning.margin * self.limits.capture_radius * apothem()
    }

    /// The speed facets' bound `b` for an along-track closing speed `a` (m/s).
    pub fn speed_bound(&self, a: f64) -> f64 {
        let c = self.limits.max_closing_speed;
        self.tuning.margin * (c * c - a * a).max(0.0).sqrt() * apothem()
    }

    /// The unconstrained optimum's gain (4N x n; its first four rows are the first command's).
    pub fn unconstrained_gain(&self) -> &Matrix {
        &self.kall
    }

    /// A work space for [`Self::solve`].
    pub fn new_scratch(&self) -> MpcScratch {
        let nv = ACT_DIM * self.horizon;
        let rows = nv + 2 + 16 * self.horizon;
        MpcScratch {
            e0: vec![0.0; self.n],
            x: vec![0.0; nv + 2],
            lo: vec![0.0; rows],
            hi: vec![0.0; rows],
            used: vec![false; rows],
            work: QpWork::new(nv + 2, rows),
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
        if !(s.e0.iter().all(|e| e.is_finite())
            && u_ss.iter().all(|u| u.is_finite())
            && z[ir..].iter().all(|v| v.is_finite()))
        {
            return (fallback, Outcome::Fallback);
        }
        let (v, slacks) = s.x.split_at_mut(nv);
        self.kall.mul_vec_into(&s.e0, v);
        slacks.fill(0.0);
        // The flap rows, the slack bounds.
        for k in 0..self.horizon {
            for (j, u) in u_ss.iter().enumerate() {
                let i = ACT_DIM * k + j;
                s.lo[i] = -1.0 - u;
                s.hi[i] = 1.0 - u;
                s.used[i] = true;
            }
        }
        for i in nv..nv + 2 {
            s.lo[i] = 0.0;
            s.hi[i] = f64::INFINITY;
            s.used[i] = true;
        }
        // The facet rows (offsets moved into the bounds).
        let along0 = z[ir] - dot(&self.cp_x, &z[..n]);
        let approach = z[iv].abs().min(self.limits.approach_speed);
        let radius = self.radius_bound();
        let mut arrived = false;
        for k in 1..=self.horizon {
            let along = along0 + (k as f64 * self.dt) * z[iv];
            arrived = arrived || along * along0 <= 0.0 || along.abs() <= self.limits.capture_radius;
            let lead = k >= self.tuning.lead;
            let speed_rows = lead && (arrived || along.abs() <= self.tuning.window);
            let position_rows = lead && arrived;
            let bound = self.speed_bound(if arrived { 0.0 } else { approach });
            let t = k as f64 * self.dt;
            for f in 0..8 {
                let row = 8 * (k - 1) + f;
                let i = nv + 2 + 2 * row;
                let on = if f < 4 { speed_rows } else { position_rows };
                s.used[i] = on;
                s.used[i + 1] = on;
                if !on {
                    continue;
                }
                let mut ss = 0.0;
                for (j, rj) in reference.iter().enumerate() {
                    ss += self.facet_ss[(f, j)] * rj;
                }
                let normal = FACETS[f % 4];
                let boom = if f < 4 {
                    normal[0] * z[iv + 1] + normal[1] * z[iv + 2]
                } else {
                    normal[0] * (z[ir + 1] + t * z[iv + 1])
                        + normal[1] * (z[ir + 2] + t * z[iv + 2])
                };
                let offset = dot(self.rows_e.row(row), &s.e0) + ss - boom;
                let b = if f < 4 { bound } else { radius };
                s.lo[i] = f64::NEG_INFINITY;
                s.hi[i] = b - offset;
                s.lo[i + 1] = f64::NEG_INFINITY;
                s.hi[i + 1] = b + offset;
            }
        }
        if !s.x.iter().all(|v| v.is_finite()) {
            return (fallback, Outcome::Fallback);
        }
        let rows = PlanRows {
            plan: self,
            lo: &s.lo,
            hi: &s.hi,
            used: &s.used,
        };
        let keeps = (0..rows.len()).all(|i| match rows.bounds(i) {
            None => true,
            Some((lo, hi)) => {
                let v = qp::row_dot(rows.row(i), &s.x);
                lo <= v && v <= hi
            }
        });
        if keeps {
            return (self.command(&s.x, u_ss), Outcome::Unconstrained);
        }
        // The unconstrained optimum of the slacks is -1 (the linear term w against w s^2 / 2).
        let nx = nv + 2;
        s.x[nv] = -1.0;
        s.x[nv + 1] = -1.0;
        match qp::solve(
            &self.factor,
            &rows,
            &mut s.x[..nx],
            self.tuning.iterations,
            &mut s.work,
        ) {
            QpEnd::Solved(_) => (self.command(&s.x, u_ss), Outcome::Constrained),
            QpEnd::Limit => (fallback, Outcome::Inexact),
            QpEnd::Infeasible | QpEnd::NotFinite => (fallback, Outcome::Fallback),
        }
    }

    /// The KKT residuals `(stationarity, primal)` of the last solve in `s` for the estimate `z`
    /// (see [`qp::kkt_residuals`]; for tests and checks).
    pub fn kkt_residuals(&self, z: &[f64], s: &MpcScratch) -> (f64, f64) {
        let n = self.n;
        let nv = ACT_DIM * self.horizon;
        let (ir, _) = (n + WIND_DIM, 0);
        let reference = [z[n], z[n + 1], z[ir + 1], z[ir + 2]];
        let e0: Vec<f64> = (0..n)
            .map(|i| {
                let mut e = 0.0;
                for (j, rj) in reference.iter().enumerate() {
                    e += rj * self.x_ss_t[(j, i)];
                }
                z[i] - e
            })
            .collect();
        let mut g = vec![0.0; nv + 2];
        self.linear.mul_vec_into(&e0, &mut g[..nv]);
        g[nv] = self.tuning.slack_weight;
        g[nv + 1] = self.tuning.slack_weight;
        let rows = PlanRows {
            plan: self,
            lo: &s.lo,
            hi: &s.hi,
            used: &s.used,
        };
        qp::kkt_residuals(&self.hessian, &g, &rows, &s.x, &s.work)
    }

    fn command(&self, x: &[f64], u_ss: [f64; ACT_DIM]) -> [f64; ACT_DIM] {
        std::array::from_fn(|j| (u_ss[j] + x[j]).clamp(-1.0, 1.0))
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
            ("capture_radius", limits.capture_radius),
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
        let (py, spy) = row("boom_rel_y");
        let (pz, spz) = row("boom_rel_z");
        let cp_yz = Matrix::from_fn(2, n, |i, j| {
            if i == 0 {
                -h[(py, j)] / spy
            } else {
                -h[(pz, j)] / spz
            }
        });
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
            &a, &b, q, &r, p, &cp_x, &cp_yz, &cpv_yz, x_ss, u_ss, dt, tuning, limits,
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
    /// nothing and cost `r`): `p` is the capture point's y position, `v` its y velocity.
    fn double_integrator(
        horizon: usize,
        margin: f64,
        window: f64,
        r: f64,
        radius: f64,
    ) -> (MpcPlan, Matrix) {
        let a = Matrix::from_row_major(2, 2, vec![1.0, DT, 0.0, 1.0]);
        let b = Matrix::from_fn(2, ACT_DIM, |i, j| match (i, j) {
            (0, 0) => 0.5 * DT * DT,
            (1, 0) => DT,
            _ => 0.0,
        });
        let q = Matrix::diagonal(&[10.0, 1.0]);
        let r = Matrix::identity(ACT_DIM).scale(r);
        let p = solve_dare(&a, &b, &q, &r, "test").unwrap();
        let cp = Matrix::from_row_major(2, 2, vec![1.0, 0.0, 0.0, 0.0]);
        let cpv = Matrix::from_row_major(2, 2, vec![0.0, 1.0, 0.0, 0.0]);
        let tuning = MpcTuning::new(horizon, 1, margin, window, 1e6, 1000).unwrap();
        let limits = CaptureLimits {
            max_closing_speed: 1.0,
            capture_radius: radius,
            approach_speed: 0.5,
        };
        let plan = MpcPlan::new(
            &a,
            &b,
            &q,
            &r,
            &p.x,
            &[0.0, 0.0],
            &cp,
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

    /// The estimate `z` of the test plant: `(p, v)`, no wind, the boom tip at `boom_x` along
    /// track and y = 0, closing at `boom_vx`.
    fn estimate(p0: f64, v0: f64, boom_x: f64, boom_vx: f64) -> Vec<f64> {
        let mut z = vec![0.0; 2 + EXTRA_STATES];
        z[0] = p0;
        z[1] = v0;
        z[2 + WIND_DIM] = boom_x;
        z[2 + WIND_DIM + 3] = boom_vx;
        z
    }

    /// The predicted trajectory `(p_k, v_k)`, k = 1..N, of a plan `V`.
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

    fn assert_kkt(plan: &MpcPlan, z: &[f64], s: &MpcScratch) {
        let (stationarity, primal) = plan.kkt_residuals(z, s);
        assert!(
            stationarity < 1e-6 && primal < 1e-9,
            "KKT residuals {stationarity} {primal}"
        );
    }

    #[test]
    fn without_active_constraints_the_first_command_is_the_lqr_s() {
        let (plan, k) = double_integrator(30, 1.0, 1.0, 0.01, 0.5);
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
        // Far from the boom (no capture rows) and close to the target: nothing is active.
        let (u, outcome) = plan.solve(&estimate(0.01, 0.0, 100.0, 0.0), [9.0; 4], &mut s);
        assert_eq!(outcome, Outcome::Unconstrained);
        assert!((u[0] - (-k[(0, 0)] * 0.01)).abs() < 1e-12);
    }

    #[test]
    fn the_flap_limits_hold_where_the_unconstrained_optimum_breaks_them() {
        let (plan, k) = double_integrator(30, 1.0, 1.0, 0.01, 0.5);
        let mut s = plan.new_scratch();
        // 5 m off: the LQR asks for -K (5, 0), far beyond the flap limit.
        assert!(k[(0, 0)] * 5.0 > 1.0);
        let z = estimate(5.0, 0.0, 100.0, 0.0);
        let (u, outcome) = plan.solve(&z, [9.0; 4], &mut s);
        assert_eq!(outcome, Outcome::Constrained);
        assert_eq!(u[0], -1.0);
        for v in s.plan() {
            assert!(v.abs() <= 1.0 + 1e-12, "{v}");
        }
        assert_kkt(&plan, &z, &s);
    }

    #[test]
    fn the_speed_bound_holds_exactly_on_the_prediction_near_the_boom() {
        // The window covers the whole horizon (the boom 100 m off, at rest): every step's speed
        // rows hold, with b = margin * 1 m/s * cos(pi/8) (no along-track closing).
        let (plan, _) = double_integrator(40, 0.5, 1000.0, 0.01, 0.5);
        let b = plan.speed_bound(0.0);
        assert!((b - 0.5 * (0.5 + 0.5 * std::f64::consts::FRAC_1_SQRT_2).sqrt()).abs() < 1e-15);
        let mut s = plan.new_scratch();
        // Unconstrained, the velocity from 1 m off peaks well above b.
        let (_, free) = double_integrator(40, 0.5, 1e-9, 0.01, 0.5).0.solve(
            &estimate(1.0, 0.0, 100.0, 0.0),
            [9.0; 4],
            &mut s,
        );
        assert_ne!(free, Outcome::Fallback);
        let peak_free = simulate(1.0, 0.0, s.plan())
            .iter()
            .fold(0.0_f64, |m, x| m.max(x.1.abs()));
        assert!(peak_free > 1.5 * b, "{peak_free} vs {b}");
        let mut s = plan.new_scratch();
        let z = estimate(1.0, 0.0, 100.0, 0.0);
        let (u, outcome) = plan.solve(&z, [9.0; 4], &mut s);
        assert_eq!(outcome, Outcome::Constrained);
        // Feasible from rest: the exact penalty leaves no slack, and the bound holds exactly.
        assert_eq!(s.slacks(), (0.0, 0.0));
        for (k, (_, v)) in simulate(1.0, 0.0, s.plan()).iter().enumerate() {
            assert!(v.abs() <= b + 1e-9, "step {k}: {v} vs {b}");
        }
        assert!(u[0] < 0.0, "it still moves towards the target");
        assert_kkt(&plan, &z, &s);
    }

    #[test]
    fn the_prediction_is_in_the_terminal_set_from_the_arrival_on() {
        // The boom 1 m behind, closing at 0.5 m/s: the predicted along-track distance is within
        // the capture radius (0.5 m) from step 10 (1 s) on, the arrival. A slow LQR (r = 100)
        // from 0.8 m off is still outside the capture radius then. The window (0.6 m) adds the
        // speed rows of step 9 (0.55 m), with the bound the boom's closing leaves.
        let (plan, _) = double_integrator(40, 1.0, 0.6, 100.0, 0.5);
        let rho = plan.radius_bound();
        let (b_closing, b_station) = (plan.speed_bound(0.5), plan.speed_bound(0.0));
        let z = estimate(0.8, 0.0, 1.0, -0.5);
        let mut s = plan.new_scratch();
        let v_free: Vec<f64> = {
            let mut v = vec![0.0; ACT_DIM * 40];
            plan.unconstrained_gain().mul_vec_into(&z[..2], &mut v);
            v
        };
        let free = simulate(0.8, 0.0, &v_free);
        assert!(free[9].0.abs() > rho, "{} vs {rho}", free[9].0);
        let (_, outcome) = plan.solve(&z, [9.0; 4], &mut s);
        assert_eq!(outcome, Outcome::Constrained);
        assert_eq!(s.slacks(), (0.0, 0.0));
        let path = simulate(0.8, 0.0, s.plan());
        for (i, (p, v)) in path.iter().enumerate() {
            let k = i + 1;
            if k >= 10 {
                assert!(p.abs() <= rho + 1e-9, "step {k}: {p} vs {rho}");
                assert!(v.abs() <= b_station + 1e-9, "step {k}: {v} vs {b_station}");
            }
        }
        assert!(path[8].1.abs() <= b_closing + 1e-9);
        assert_kkt(&plan, &z, &s);
    }

    #[test]
    fn an_infeasible_start_is_softened_and_never_nan() {
        // Already at 3 m/s at the boom: v_1 >= 3 - T = 2.9 m/s whatever the flaps, so the speed
        // slack is at least 2.9 - b, and exactly that with full braking (a capture radius of
        // 100 m keeps the position rows out of the way).
        let (plan, _) = double_integrator(20, 0.5, 1.0, 0.01, 100.0);
        let b = plan.speed_bound(0.0);
        let mut s = plan.new_scratch();
        let z = estimate(0.0, 3.0, 0.0, 0.0);
        let (u, outcome) = plan.solve(&z, [0.25; 4], &mut s);
        assert_eq!(outcome, Outcome::Constrained);
        assert_eq!(u[0], -1.0, "full braking");
        let (sv, sp) = s.slacks();
        assert!((sv - (2.9 - b)).abs() < 1e-9, "{sv} vs {}", 2.9 - b);
        assert_eq!(sp, 0.0);
        assert!(s.plan().iter().all(|v| v.is_finite()));
        assert_kkt(&plan, &z, &s);
        // A non-finite estimate gives the fallback.
        let (u, outcome) = plan.solve(&estimate(f64::NAN, 0.0, 0.0, 0.0), [0.25; 4], &mut s);
        assert_eq!((u, outcome), ([0.25; 4], Outcome::Fallback));
    }

    #[test]
    fn a_step_limit_gives_the_fallback_command() {
        let (mut plan, _) = double_integrator(20, 0.5, 1.0, 0.01, 100.0);
        plan.tuning.iterations = 1;
        let mut s = plan.new_scratch();
        let (u, outcome) = plan.solve(&estimate(0.0, 3.0, 0.0, 0.0), [0.25; 4], &mut s);
        assert_eq!((u, outcome), ([0.25; 4], Outcome::Inexact));
    }

    #[test]
    fn a_solve_is_the_same_bits_whatever_came_before() {
        let (plan, _) = double_integrator(30, 0.8, 0.5, 0.01, 0.5);
        let z = estimate(0.7, -0.3, 0.2, -0.5);
        let mut fresh = plan.new_scratch();
        let first = plan.solve(&z, [0.0; 4], &mut fresh);
        let mut used = plan.new_scratch();
        plan.solve(&estimate(5.0, 2.0, 0.0, 0.0), [0.0; 4], &mut used);
        let again = plan.solve(&z, [0.0; 4], &mut used);
        assert_eq!(first.1, Outcome::Constrained);
        assert_eq!(first.0.map(f64::to_bits), again.0.map(f64::to_bits));
        assert_eq!(fresh.plan(), used.plan());
    }

    #[test]
    fn a_zero_horizon_is_a_config_error_naming_the_field() {
        let err = MpcTuning::new(0, 1, 1.0, 1.0, 1.0, 10).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("mpc.horizon") && text.contains("[1, 200]"),
            "{text}"
        );
        let text = MpcTuning::new(10, 11, 1.0, 1.0, 1.0, 10)
            .unwrap_err()
            .to_string();
        assert!(text.contains("mpc.lead") && text.contains("11"), "{text}");
    }
}
