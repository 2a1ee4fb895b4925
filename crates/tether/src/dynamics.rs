//! Equations of motion of the tether (paper section 3.1, Eq. 12), derived from the kinematics
//! (Eq. 3) by the projection (Kane / Lagrange) method rather than transcribed from the Appendix.
//!
//! # Coordinates
//! `q = [s, phi_1, psi_1, ..., phi_n, psi_n]` (2n + 1 entries): the elongation `s` of the axial
//! visco-elastic element at the attachment point (section 2.3.6), then the two angles of each
//! segment (see [`crate::direction`]), segment 1 at the aircraft.
//!
//! # Kinematics
//! The axial element lies along segment 1, so segment 1 starts at `s e_1` and
//!
//! ```text
//! c_i = s e_1 + l sum_{j<i} e_j + (l/2) e_i        centre of segment i
//! p_t = s e_1 + l sum_{j<=n} e_j                    tip body (centre of gravity of the ACCD)
//! ```
//!
//! # Equations
//! With kinetic energy `T = sum_i (m/2 |c_i'|^2 + I/2 |e_i'|^2) + M_t/2 |p_t'|^2`, `I = m l^2/12`,
//! Lagrange's equations read `M(q) q'' = Q(t, q, q')`, where
//!
//! * `M = sum_i m J_ci^T J_ci + I J_ei^T J_ei + M_t J_t^T J_t`. Writing `a_ik` for the coefficient
//!   of `e_k` in `c_i`, the angle block is `M_(j,a)(k,b) = W_jk (de_j/da . de_k/db)` with the scalar
//!   `W_jk = sum_i m a_ij a_ik + M_t a_tj a_tk + I delta_jk`, which has the closed forms used below
//!   (the Appendix's `b_i`, `c_i` factors are the special cases s = 0).
//! * the generalized forces are
//!   ```text
//!   Q = sum_i J_ci^T (F_i - m c_i''|q''=0) - I J_ei^T e_i''|q''=0 + J_t^T (F_t - M_t p_t''|q''=0)
//!       + Q_M + Q_D - (k s + c_s s') d/ds
//!   ```
//!   with the external forces `F_i` on the segment centres (gravity, the apparent force -m a_TA of
//!   Eq. 10, aerodynamics of section 2.3.4), the tip force `F_t` (Eq. 8), the convective inertia
//!   terms (the paper's `f`), bending (Eq. 5) and damping (Eq. 7) in the coordinate-free forms
//!   below, and the axial element.
//!
//! **Bending.** A joint between segments j and j+1 at angle theta stores
//! `U = -(4 EI / l) ln cos(theta/2) = -(2 EI / l) ln((1 + e_j . e_{j+1}) / 2)`, whose moment
//! `dU/dtheta = EI (2/l) tan(theta/2) = EI kappa` is section 2.3.1's nonlinear spring; it grows
//! without bound as theta -> pi. For small angles `U = EI theta^2 / (2 l)`.
//!
//! **Damping.** Rayleigh's function `R = c_b/2 sum_j |w_{j+1} - w_j|^2` over the relative angular
//! velocities of adjacent segments, `w_i = e_i x e_i'` (Eq. 6 without reference to a coordinate
//! chart), and `c_s s'` on the axial element.
//!
//! **Aerodynamics.** Per segment, from the air velocity relative to its centre,
//! `v = v_air(c_i) - c_i'` (or `v_air(c_i)` alone with [`crate::DragVelocity::FreeStream`]), split into `v_t = (v . e_i) e_i` and `v_n = v - v_t`:
//! `F = 1/2 rho d l (C_n |v_n| v_n + pi C_t |v_t| v_t)`.
//!
//! The distributed elasticity ([`crate::Elasticity::Distributed`]: an element in every segment,
//! 3n coordinates) has its own kinematics and both solvers in [`crate::distributed`]; every method
//! here takes either layout.
//!
//! All of `Q` costs O(n) through suffix sums; the dense solve of `M` costs O(n^3) and is the
//! reference formulation ([`Solver::Dense`]). The hot path ([`Solver::Recursive`], the default)
//! solves the same equations in O(n) by the articulated-body recursion of [`crate::recursive`].

use nalgebra::{DMatrix, Vector3};

use crate::arith::{Madd, Plain};
use crate::chain::{ChainState, LoadConstants};
use crate::config::TetherConfig;
use crate::direction::DirectionJet;
use crate::distributed::{self, stretch_index};
use crate::error::{Result, TetherError};
use crate::recursive::{self, Articulated, ChainConstants, Held};
use crate::surroundings::Surroundings;

type V3 = Vector3<f64>;

/// Energy of the tether and tip body, J, in the towing-aircraft frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Energy {
    /// Translational and rotational kinetic energy.
    pub kinetic: f64,
    /// Gravitational potential, zero at the attachment's height (z down, so it is negative below).
    pub gravity: f64,
    /// Strain energy of the axial element, k s^2 / 2 (the sum over the elements when distributed).
    pub axial: f64,
    /// Strain energy of the bending springs.
    pub bending: f64,
}

impl Energy {
    /// Sum of all parts.
    pub fn total(&self) -> f64 {
        self.kinetic + self.gravity + self.axial + self.bending
    }
}

/// How [`TetherModel::accelerations`] solves `M(q) q'' = Q`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Solver {
    /// O(n) articulated-body recursion ([`crate::recursive`]): the hot path.
    #[default]
    Recursive,
    /// Assemble the dense mass matrix and solve it by Cholesky, O(n^3): the reference.
    Dense,
}

/// The axial part of one stage of a linearly implicit step ([`crate::implicit`]): where the
/// axial elements' springs and dampers are evaluated, and the step-scaled stiffness and damping
/// added to their rows of the mass matrix.
///
/// [`TetherModel::accelerations_axial`] solves
///
/// ```text
/// (M(q) + (gamma_h c + gamma_h^2 k) P^T P) x = Q(t, q, q')  with every element's force
///                                                            -k s~ - c s~' in place of -k s - c s'
/// ```
///
/// where `P` picks the stretch coordinates, `(k, c)` are one element's stiffness and damping
/// ([`TetherConfig::element_stiffness`], [`TetherConfig::element_damping`]) and `(s~, s~')` are
/// the stretch entries of `stretch` and `stretch_rate`. The kinematics (lever arms, drift) use
/// `q` and `q'` as always. With `gamma_h = 0` and `(s~, s~') = (s, s')` this is `M q'' = Q`.
#[derive(Debug, Clone, Copy)]
pub struct AxialStage<'a> {
    /// Full-length (dofs) array whose stretch entries the springs are evaluated at, m.
    pub stretch: &'a [f64],
    /// Full-length (dofs) array whose stretch entries the dampers are evaluated at, m/s.
    pub stretch_rate: &'a [f64],
    /// The step-scaled factor `gamma h`, s.
    pub gamma_h: f64,
}

/// The axial stage as the solvers read it: the springs' arguments and the added mass, kg.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AxialSolve<'a> {
    pub stretch: &'a [f64],
    pub stretch_rate: &'a [f64],
    pub added_mass: f64,
}

/// The tether's equations of motion, with the constants derived from a [`TetherConfig`] and
/// preallocated work buffers: evaluating the right-hand side allocates nothing.
#[derive(Debug, Clone)]
pub struct TetherModel {
    config: TetherConfig,
    n: usize,
    l: f64,
    m: f64,
    rod_inertia: f64,
    tip_mass: f64,
    k: f64,
    c_s: f64,
    c_b: f64,
    ei: f64,
    gravity: f64,
    /// 1/2 d l C_n, m^2: times rho |v_n| v_n gives the cross-flow drag.
    normal_drag: f64,
    /// 1/2 pi d l C_t, m^2: times rho |v_t| v_t gives the skin friction.
    tangential_drag: f64,
    /// Weight of a segment's own velocity in its drag ([`crate::DragVelocity`]): 1 or 0.
    segment_velocity_weight: f64,
    solver: Solver,
    /// Whether the elasticity is distributed ([`crate::distributed`]).
    distributed: bool,
    /// Stiffness and damping of one distributed element, n k and n c_s.
    element_k: f64,
    element_c: f64,
    /// The effective axial mass at the last state the accelerations were evaluated at, kg
    /// ([`TetherModel::axial_mass`]).
    axial_mass: f64,
    ws: Workspace,
}

#[cfg(feature = "lockstep")]
/// The work space of [`TetherModel::accelerations_four`]: the sweeps' inputs of four chains
/// side by side and what the backward sweep leaves per segment. Sized on first use (per number
/// of segments); one per thread that steps models four at a time.
#[derive(Debug, Clone, Default)]
pub struct LockstepWork {
    #[cfg(target_arch = "x86_64")]
    lanes: recursive::lockstep::Work4,
}

#[derive(Debug, Clone)]
struct Workspace {
    /// Kinematics and loads of every segment.
    chain: ChainState,
    /// Convective accelerations of the segment centres (dense path only; sized on first use).
    com_acc0: Vec<V3>,
    tip_acc0: V3,
    /// Lower triangle of the mass matrix, row-major, dim x dim; overwritten by its Cholesky factor.
    /// Allocated on the first dense solve only.
    mass: Vec<f64>,
    /// Per-segment results of the recursive solver's backward sweep.
    articulated: Vec<Articulated<f64>>,
    /// What the tensions need of the backward sweep, per segment.
    held: Vec<Held>,
    /// The same for the distributed elasticity (empty otherwise).
    axial: Vec<distributed::Articulated>,
    /// `L^-1 e_0` of the dense solve's Cholesky factor (sized on first use).
    unit: Vec<f64>,
}

impl TetherModel {
    /// Builds the model, validating the config.
    pub fn new(config: &TetherConfig) -> Result<Self> {
        config.validate()?;
        let n = config.segments;
        let l = config.segment_length();
        let m = config.segment_mass();
        Ok(TetherModel {
            n,
            l,
            m,
            rod_inertia: m * l * l / 12.0,
            tip_mass: config.tip_mass,
            k: config.axial_stiffness,
            c_s: config.axial_damping(),
            c_b: config.joint_damping(),
            ei: config.flexural_rigidity,
            gravity: config.gravity,
            normal_drag: 0.5 * config.diameter * l * config.normal_drag_coefficient,
            tangential_drag: 0.5
                * std::f64::consts::PI
                * config.diameter
                * l
                * config.tangential_drag_coefficient,
            segment_velocity_weight: config.drag_velocity.segment_velocity_weight(),
            ws: Workspace {
                chain: ChainState::new(n),
                com_acc0: Vec::new(),
                tip_acc0: V3::zeros(),
                mass: Vec::new(),
                articulated: vec![Articulated::default(); n],
                held: vec![Held::default(); n],
                axial: if config.is_distributed() {
                    vec![distributed::Articulated::default(); n]
                } else {
                    Vec::new()
                },
                unit: Vec::new(),
            },
            axial_mass: config.total_mass() + config.tip_mass,
            solver: Solver::default(),
            distributed: config.is_distributed(),
            element_k: config.element_stiffness(),
            element_c: config.element_damping(),
            config: config.clone(),
        })
    }

    /// The configuration this model was built from.
    pub fn config(&self) -> &TetherConfig {
        &self.config
    }

    /// Number of segments n.
    pub fn segments(&self) -> usize {
        self.n
    }

    /// Number of generalized coordinates: 2n + 1, or 3n with the distributed elasticity.
    pub fn dofs(&self) -> usize {
        if self.distributed {
            3 * self.n
        } else {
            2 * self.n + 1
        }
    }

    /// Whether the elasticity is distributed over the segments ([`crate::distributed`]).
    pub fn is_distributed(&self) -> bool {
        self.distributed
    }

    /// Whether coordinate `i` of q is an axial element's stretch (the attachment element's
    /// `s`, or with the distributed elasticity every segment's): the coordinates whose
    /// spring-dampers [`crate::Scheme::ImplicitAxial`] treats implicitly.
    pub fn is_stretch_coordinate(&self, i: usize) -> bool {
        if self.distributed {
            i == 0 || (i > 2 * self.n && i < 3 * self.n)
        } else {
            i == 0
        }
    }

    /// Stretch of segment k's element and its rate, (m, m/s): segment 1's is the attachment
    /// element's `s`; the other segments have none unless the elasticity is distributed.
    #[inline(always)]
    fn stretch(&self, q: &[f64], qd: &[f64], k: usize) -> (f64, f64) {
        if k == 0 {
            (q[0], qd[0])
        } else if self.distributed {
            let i = stretch_index(self.n, k);
            (q[i], qd[i])
        } else {
            (0.0, 0.0)
        }
    }

    fn distributed_constants(&self) -> distributed::Constants {
        distributed::Constants {
            l: self.l,
            m: self.m,
            rod_inertia: self.rod_inertia,
            tip_mass: self.tip_mass,
            k: self.element_k,
            c: self.element_c,
        }
    }

    fn check_len(&self, what: &'static str, v: &[f64]) -> Result<()> {
        if v.len() == self.dofs() {
            Ok(())
        } else {
            Err(TetherError::WrongSize {
                what,
                expected: self.dofs(),
                found: v.len(),
            })
        }
    }

    /// Constants of the loads.
    fn load_constants(&self) -> LoadConstants {
        LoadConstants {
            m: self.m,
            tip_mass: self.tip_mass,
            rod_inertia: self.rod_inertia,
            bend_gain: 2.0 * self.ei / self.l,
            c_b: self.c_b,
            normal_drag: self.normal_drag,
            tangential_drag: self.tangential_drag,
            segment_velocity_weight: self.segment_velocity_weight,
            gravity: self.gravity,
            l: self.l,
        }
    }

    /// The constants of the lumped chain the recursion needs.
    fn chain_constants(&self) -> ChainConstants {
        ChainConstants {
            l: self.l,
            m: self.m,
            rod_inertia: self.rod_inertia,
            tip_mass: self.tip_mass,
            k: self.k,
            c_s: self.c_s,
        }
    }

    /// Kinematics and loads of every segment and the tip ([`ChainState`]).
    ///
    /// Errors at the coordinate singularity or at a completely folded joint.
    #[inline(always)]
    fn prepare<M: Madd, S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
    ) -> Result<S::TipReport> {
        let constants = self.load_constants();
        let distributed = self.distributed;
        prepare_in::<M, S>(
            &constants,
            distributed,
            &mut self.ws.chain,
            time,
            q,
            qd,
            surroundings,
        )
    }

    /// Walks the chain with the state's positions and velocities: calls `visit(e, e_dot, centre,
    /// centre velocity)` per segment and returns the tip's position and velocity.
    fn walk(&self, q: &[f64], qd: &[f64], mut visit: impl FnMut(V3, V3, V3, V3)) -> (V3, V3) {
        if self.distributed {
            let mut p = V3::zeros();
            let mut pv = V3::zeros();
            for k in 0..self.n {
                let jet = DirectionJet::new(q[1 + 2 * k], q[2 + 2 * k]);
                let e_dot = jet.rate(qd[1 + 2 * k], qd[2 + 2 * k]);
                let (s, sd) = self.stretch(q, qd, k);
                p += jet.e * s;
                pv += jet.e * sd + e_dot * s;
                visit(
                    jet.e,
                    e_dot,
                    p + jet.e * (0.5 * self.l),
                    pv + e_dot * (0.5 * self.l),
                );
                p += jet.e * self.l;
                pv += e_dot * self.l;
            }
            return (p, pv);
        }
        let (s, sd) = (q[0], qd[0]);
        let mut p = V3::zeros();
        let mut pv = V3::zeros();
        for k in 0..self.n {
            let jet = DirectionJet::new(q[1 + 2 * k], q[2 + 2 * k]);
            let e_dot = jet.rate(qd[1 + 2 * k], qd[2 + 2 * k]);
            if k == 0 {
                p = jet.e * s;
                pv = jet.e * sd + e_dot * s;
            }
            visit(
                jet.e,
                e_dot,
                p + jet.e * (0.5 * self.l),
                pv + e_dot * (0.5 * self.l),
            );
            p += jet.e * self.l;
            pv += e_dot * self.l;
        }
        (p, pv)
    }

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

    /// The solver [`TetherModel::accelerations`] and [`TetherModel::tensions`] use.
    pub fn solver(&self) -> Solver {
        self.solver
    }

    /// Chooses the solver of [`TetherModel::accelerations`] and [`TetherModel::tensions`]
    /// (default [`Solver::Recursive`]; [`Solver::Dense`] is the O(n^3) reference).
    pub fn set_solver(&mut self, solver: Solver) {
        self.solver = solver;
    }

    /// Generalized accelerations q'' = M(q)^-1 Q(t, q, q') (paper Eq. 12) into `qdd`, by the
    /// configured [`Solver`] (the O(n) recursion unless set otherwise).
    ///
    /// Errors if the state reaches the coordinate singularity, folds a joint completely, or makes
    /// the mass matrix numerically singular.
    pub fn accelerations<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
    ) -> Result<S::TipReport> {
        match self.solver {
            Solver::Recursive => self.solve_recursive(time, q, qd, surroundings, qdd, None),
            Solver::Dense => self.accelerations_dense(time, q, qd, surroundings, qdd),
        }
    }

    /// The solve of one linearly implicit stage ([`AxialStage`]): the accelerations with the
    /// axial elements' forces at the stage's arguments and their rows of the mass matrix
    /// augmented by `gamma_h c + gamma_h^2 k`, by the configured [`Solver`]. Leaves
    /// [`TetherModel::axial_mass`] that of `M` itself. Allocates nothing (the dense solver on
    /// first use).
    pub fn accelerations_axial<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        stage: &AxialStage<'_>,
        surroundings: &S,
        qdd: &mut [f64],
    ) -> Result<S::TipReport> {
        self.check_len("stretch", stage.stretch)?;
        self.check_len("stretch_rate", stage.stretch_rate)?;
        let (k, c) = if self.distributed {
            (self.element_k, self.element_c)
        } else {
            (self.k, self.c_s)
        };
        let gh = stage.gamma_h;
        let axial = AxialSolve {
            stretch: stage.stretch,
            stretch_rate: stage.stretch_rate,
            added_mass: gh * c + gh * gh * k,
        };
        match self.solver {
            Solver::Recursive => {
                self.solve_recursive_axial(time, q, qd, surroundings, qdd, None, Some(axial))
            }
            Solver::Dense => self.dense_axial(time, q, qd, surroundings, qdd, &axial),
        }
    }

    /// [`TetherModel::accelerations_axial`] by the dense formulation: `M` and `Q` as
    /// [`TetherModel::accelerations_dense`] assembles them, the stretch rows' forces moved to
    /// the stage's arguments and their diagonal augmented, solved by Cholesky.
    fn dense_axial<S: Surroundings + ?Sized>(
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
        let report = self.prepare::<Plain, S>(time, q, qd, surroundings)?;
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

    /// [`TetherModel::accelerations`] by the O(n) articulated-body recursion, whatever the
    /// configured solver.
    pub fn accelerations_recursive<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
    ) -> Result<S::TipReport> {
        self.solve_recursive(time, q, qd, surroundings, qdd, None)
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
        let report = self.prepare::<Plain, S>(time, q, qd, surroundings)?;
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

    /// The effective mass the axial element moves, `1 / (M^-1)_00` (kg), at the state the
    /// accelerations were last evaluated at (by either solver); before the first evaluation, and
    /// always for the distributed elasticity, the straight chain's `m_tot + M_t`.
    ///
    /// The axial damping `c_s` acts on the elongation alone, so `c_s (M^-1)_00` is exactly the rate
    /// of its damping mode ([`crate::config::StepLoad::axial_mass`]). A straight chain moves all of
    /// its mass; a bent one much less (the chain beyond a kink swings instead of following): a
    /// towed 10 kg/m tether falls to about a quarter. The recursion reads it from its root
    /// system at a few operations; the dense solve from its Cholesky factor, O(n^2).
    pub fn axial_mass(&self) -> f64 {
        self.axial_mass
    }

    fn solve_recursive<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        tensions: Option<&mut [f64]>,
    ) -> Result<S::TipReport> {
        self.solve_recursive_axial(time, q, qd, surroundings, qdd, tensions, None)
    }

    /// [`TetherModel::solve_recursive`], with the axial stage of a linearly implicit step if
    /// given ([`TetherModel::accelerations_axial`]).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn solve_recursive_axial<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        tensions: Option<&mut [f64]>,
        axial: Option<AxialSolve<'_>>,
    ) -> Result<S::TipReport> {
        #[cfg(target_arch = "x86_64")]
        if crate::arith::has_avx2_fma() {
            // SAFETY: the processor has AVX2 and FMA, checked just above.
            return unsafe {
                self.solve_recursive_avx2(time, q, qd, surroundings, qdd, tensions, axial)
            };
        }
        self.solve_recursive_body::<Plain, S>(time, q, qd, surroundings, qdd, tensions, axial)
    }

    /// [`TetherModel::solve_recursive_body`] compiled for AVX2 and FMA, with fused multiply-adds.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn solve_recursive_avx2<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        tensions: Option<&mut [f64]>,
        axial: Option<AxialSolve<'_>>,
    ) -> Result<S::TipReport> {
        self.solve_recursive_body::<crate::arith::Fused, S>(
            time,
            q,
            qd,
            surroundings,
            qdd,
            tensions,
            axial,
        )
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn solve_recursive_body<M: Madd, S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        tensions: Option<&mut [f64]>,
        axial: Option<AxialSolve<'_>>,
    ) -> Result<S::TipReport> {
        self.check_len("q", q)?;
        self.check_len("qd", qd)?;
        self.check_len("qdd", qdd)?;
        if self.distributed {
            let c = self.distributed_constants();
            let report = self.prepare::<M, S>(time, q, qd, surroundings)?;
            let ws = &mut self.ws;
            distributed::solve::<M>(
                time,
                &c,
                &ws.chain,
                q,
                qd,
                &mut ws.axial,
                qdd,
                tensions,
                axial,
            )?;
            return Ok(report);
        }
        let constants = self.chain_constants();
        let report = self.prepare::<M, S>(time, q, qd, surroundings)?;
        let ws = &mut self.ws;
        // The spring's arguments and the added mass: the state's and none, or the stage's.
        let spring = match axial {
            None => recursive::Spring {
                s: q[0],
                sd: qd[0],
                added_mass: 0.0,
            },
            Some(a) => recursive::Spring {
                s: a.stretch[0],
                sd: a.stretch_rate[0],
                added_mass: a.added_mass,
            },
        };
        self.axial_mass = recursive::solve::<M>(
            time,
            &constants,
            &ws.chain,
            q[0],
            qd[0],
            spring,
            &mut ws.articulated,
            &mut ws.held,
            qdd,
            tensions,
        )?;
        Ok(report)
    }

    #[cfg(feature = "lockstep")]
    /// Whether four models can have their right-hand sides evaluated in lockstep
    /// ([`TetherModel::accelerations_four`] runs them four lanes wide): the processor has AVX2
    /// and FMA, and all four use the recursive solver on the lumped elasticity with the same
    /// number of segments. Their other constants may differ.
    pub fn lockstep_eligible(models: [&TetherModel; 4]) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            let n = models[0].n;
            crate::arith::has_avx2_fma()
                && models
                    .iter()
                    .all(|m| m.n == n && !m.distributed && m.solver == Solver::Recursive)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = models;
            false
        }
    }

    /// [`TetherModel::accelerations`] of four models at once: lane j is model j at
    /// `(time[j], q[j], qd[j])` in `surroundings[j]`, bit for bit what `accelerations` gives for
    /// it alone. Where [`TetherModel::lockstep_eligible`] holds, the kinematics and loads run per
    /// model and the recursion's sweeps run for the four together, one per AVX2 lane
    /// ([`crate::recursive`]'s `lockstep`); otherwise one after another.
    /// A model's error leaves the other lanes' results unchanged. Allocates nothing once `work`
    /// has been used at this number of segments.
    #[cfg(feature = "lockstep")]
    #[allow(clippy::too_many_arguments)]
    pub fn accelerations_four<S: Surroundings + ?Sized>(
        models: [&mut TetherModel; 4],
        time: [f64; 4],
        q: [&[f64]; 4],
        qd: [&[f64]; 4],
        surroundings: [&S; 4],
        qdd: [&mut [f64]; 4],
        work: &mut LockstepWork,
    ) -> [Result<S::TipReport>; 4] {
        #[cfg(target_arch = "x86_64")]
        if TetherModel::lockstep_eligible([&*models[0], &*models[1], &*models[2], &*models[3]])
            && (0..4).all(|j| {
                let dim = models[j].dofs();
                q[j].len() == dim && qd[j].len() == dim && qdd[j].len() == dim
            })
        {
            // SAFETY: eligibility includes the processor's AVX2 and FMA.
            return unsafe {
                TetherModel::accelerations_four_avx2(models, time, q, qd, surroundings, qdd, work)
            };
        }
        let _ = work;
        let mut qdd = qdd.into_iter();
        let mut models = models.into_iter();
        std::array::from_fn(|j| {
            let (model, out) = (models.next().unwrap(), qdd.next().unwrap());
            model.accelerations(time[j], q[j], qd[j], surroundings[j], out)
        })
    }

    /// [`TetherModel::accelerations_four`] for eligible models with inputs of the right sizes.
    #[cfg(all(feature = "lockstep", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn accelerations_four_avx2<S: Surroundings + ?Sized>(
        models: [&mut TetherModel; 4],
        time: [f64; 4],
        q: [&[f64]; 4],
        qd: [&[f64]; 4],
        surroundings: [&S; 4],
        qdd: [&mut [f64]; 4],
        work: &mut LockstepWork,
    ) -> [Result<S::TipReport>; 4] {
        let mut models = models;
        let n = models[0].n;
        work.lanes.ensure(n);
        // Kinematics and loads per model, then the sweeps' inputs of the four into the lanes.
        // A model whose kinematics fail still has a chain of the right size: its lane runs on
        // whatever it holds and its result is dropped.
        let mut reports: [Option<Result<S::TipReport>>; 4] = Default::default();
        for (j, model) in models.iter_mut().enumerate() {
            let constants = model.load_constants();
            let chain = &mut model.ws.chain;
            reports[j] = Some(prepare_fused(
                &constants,
                chain,
                time[j],
                q[j],
                qd[j],
                surroundings[j],
            ));
        }
        recursive::lockstep::load_lanes(
            std::array::from_fn(|j| &models[j].ws.chain),
            &mut work.lanes,
        );
        let constants: [ChainConstants; 4] = std::array::from_fn(|j| models[j].chain_constants());
        let solved = recursive::lockstep::solve4(
            time,
            std::array::from_fn(|j| &constants[j]),
            n,
            std::array::from_fn(|j| q[j][0]),
            std::array::from_fn(|j| qd[j][0]),
            &mut work.lanes,
            qdd,
        );
        let mut solved = solved.into_iter();
        std::array::from_fn(|j| {
            let axial_mass = solved.next().unwrap();
            let report = reports[j].take().unwrap()?;
            models[j].axial_mass = axial_mass?;
            Ok(report)
        })
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

    /// Energy of the state (no allocation).
    pub fn energy(&mut self, q: &[f64], qd: &[f64]) -> Result<Energy> {
        self.check_len("q", q)?;
        self.check_len("qd", qd)?;
        let (m, inertia) = (self.m, self.rod_inertia);
        let mut kinetic = 0.0;
        let mut height = 0.0;
        let mut bending = 0.0;
        let mut prev_e: Option<V3> = None;
        let bend_gain = 2.0 * self.ei / self.l;
        let (tip, tip_vel) = self.walk(q, qd, |e, e_dot, c, cv| {
            kinetic += 0.5 * (m * cv.norm_squared() + inertia * e_dot.norm_squared());
            height += m * c.z;
            if let Some(p) = prev_e {
                bending -= bend_gain * (0.5 * (1.0 + p.dot(&e))).ln();
            }
            prev_e = Some(e);
        });
        kinetic += 0.5 * self.tip_mass * tip_vel.norm_squared();
        height += self.tip_mass * tip.z;
        let axial = if self.distributed {
            (0..self.n)
                .map(|k| {
                    let s = self.stretch(q, qd, k).0;
                    0.5 * self.element_k * s * s
                })
                .sum()
        } else {
            0.5 * self.k * q[0] * q[0]
        };
        Ok(Energy {
            kinetic,
            gravity: -self.gravity * height,
            axial,
            bending,
        })
    }

    /// Tension along the chain (N, positive when pulling) into `tensions` (n + 1 values): entry k < n
    /// is the axial force at the inboard end of segment k + 1, entry n the force the tip body pulls
    /// with on the last segment. Entry 0 equals the axial element's k s + c_s s'. Computed from
    /// Newton's law for everything outboard of each joint with the accelerations of this state
    /// (which are written into `qdd`), by the configured [`Solver`].
    pub fn tensions<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        tensions: &mut [f64],
    ) -> Result<()> {
        if tensions.len() != self.n + 1 {
            return Err(TetherError::WrongSize {
                what: "tensions",
                expected: self.n + 1,
                found: tensions.len(),
            });
        }
        if self.solver == Solver::Recursive {
            return self
                .solve_recursive(time, q, qd, surroundings, qdd, Some(tensions))
                .map(|_| ());
        }
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

    /// Joint positions into `out` (n + 1 points, m): the inboard end of each segment (the first at
    /// `s e_1`, the outboard end of the axial element) and then the tip. The attachment point itself
    /// is the origin.
    pub fn joint_positions(&self, q: &[f64], out: &mut [V3]) -> Result<()> {
        self.check_len("q", q)?;
        if out.len() != self.n + 1 {
            return Err(TetherError::WrongSize {
                what: "joint positions",
                expected: self.n + 1,
                found: out.len(),
            });
        }
        if self.distributed {
            // Here entry k is the inboard end of segment k's rod, past its element.
            let mut p = V3::zeros();
            for k in 0..self.n {
                let e = crate::direction::direction(q[1 + 2 * k], q[2 + 2 * k]);
                p += e * self.stretch(q, q, k).0;
                out[k] = p;
                p += e * self.l;
            }
            out[self.n] = p;
            return Ok(());
        }
        let mut p = crate::direction::direction(q[1], q[2]) * q[0];
        out[0] = p;
        for k in 0..self.n {
            p += crate::direction::direction(q[1 + 2 * k], q[2 + 2 * k]) * self.l;
            out[k + 1] = p;
        }
        Ok(())
    }

    /// Segment centres (n, m) into `centres`, and the tip position (m) and velocity (m/s), in the
    /// TA frame; the tip is exactly [`TetherModel::tip_state`]'s.
    pub fn centres_and_tip(
        &mut self,
        q: &[f64],
        qd: &[f64],
        centres: &mut [V3],
    ) -> Result<(V3, V3)> {
        self.check_walk(q, qd, centres)?;
        let mut k = 0;
        Ok(self.walk(q, qd, |_, _, centre, _| {
            centres[k] = centre;
            k += 1;
        }))
    }

    /// [`TetherModel::centres_and_tip`] through the kinematics pass of the right-hand side
    /// (vectorised sin/cos, FMA where the processor has it): equal to it within rounding (a few
    /// ulps), about 4x cheaper. Errors at the coordinate singularity.
    pub fn centres_and_tip_batch(
        &mut self,
        q: &[f64],
        qd: &[f64],
        centres: &mut [V3],
    ) -> Result<(V3, V3)> {
        self.check_walk(q, qd, centres)?;
        #[cfg(target_arch = "x86_64")]
        if crate::arith::has_avx2_fma() {
            // SAFETY: the processor has AVX2 and FMA, checked just above.
            unsafe { self.kinematics_avx2(q, qd)? };
            self.stretch_batch(q, qd);
            return Ok(self.copy_centres(centres));
        }
        let l = self.l;
        self.ws.chain.kinematics_held::<Plain>(0.0, l, q, qd)?;
        self.stretch_batch(q, qd);
        Ok(self.copy_centres(centres))
    }

    /// The distributed elasticity's centres after the kinematics pass (nothing otherwise).
    fn stretch_batch(&mut self, q: &[f64], qd: &[f64]) {
        if self.distributed {
            let n = self.n;
            self.ws.chain.stretch_centres(self.l, |k| {
                let i = stretch_index(n, k);
                (q[i], qd[i])
            });
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn kinematics_avx2(&mut self, q: &[f64], qd: &[f64]) -> Result<()> {
        let l = self.l;
        self.ws
            .chain
            .kinematics_held::<crate::arith::Fused>(0.0, l, q, qd)
    }

    fn copy_centres(&self, centres: &mut [V3]) -> (V3, V3) {
        let ch = &self.ws.chain;
        for (k, c) in centres.iter_mut().enumerate() {
            *c = ch.com.get(k);
        }
        (ch.tip, ch.tip_vel)
    }

    /// The argument checks of the walks that fill segment centres.
    fn check_walk(&self, q: &[f64], qd: &[f64], centres: &[V3]) -> Result<()> {
        self.check_len("q", q)?;
        self.check_len("qd", qd)?;
        if centres.len() != self.n {
            return Err(TetherError::WrongSize {
                what: "segment centres",
                expected: self.n,
                found: centres.len(),
            });
        }
        Ok(())
    }

    /// Tip position (m) and velocity (m/s) in the TA frame.
    pub fn tip_state(&mut self, q: &[f64], qd: &[f64]) -> Result<(V3, V3)> {
        self.check_len("q", q)?;
        self.check_len("qd", qd)?;
        Ok(self.walk(q, qd, |_, _, _, _| {}))
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

/// [`TetherModel::prepare`] into a given chain: kinematics and loads of every segment and the tip.
#[inline(always)]
fn prepare_in<M: Madd, S: Surroundings + ?Sized>(
    constants: &LoadConstants,
    distributed: bool,
    chain: &mut ChainState,
    time: f64,
    q: &[f64],
    qd: &[f64],
    surroundings: &S,
) -> Result<S::TipReport> {
    let (n, l) = (chain.segments(), constants.l);
    chain.kinematics::<M>(time, l, q, qd)?;
    if distributed {
        chain.stretch_centres(l, |k| {
            let i = stretch_index(n, k);
            (q[i], qd[i])
        });
    }
    chain.loads::<M, S>(time, constants, surroundings)
}

/// [`prepare_in`] with fused multiply-adds, compiled for AVX2 and FMA as a function of its
/// own: inlined into the lockstep loop, its passes were not vectorized as they are in the single
/// solve (a plain function boundary, since the compiler inlines a `target_feature` function into
/// a caller with the same features whatever it is told).
///
/// # Safety
/// The processor must have AVX2 and FMA.
#[cfg(all(feature = "lockstep", target_arch = "x86_64"))]
#[inline(never)]
unsafe fn prepare_fused<S: Surroundings + ?Sized>(
    constants: &LoadConstants,
    chain: &mut ChainState,
    time: f64,
    q: &[f64],
    qd: &[f64],
    surroundings: &S,
) -> Result<S::TipReport> {
    #[target_feature(enable = "avx2,fma")]
    unsafe fn fused<S: Surroundings + ?Sized>(
        constants: &LoadConstants,
        chain: &mut ChainState,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
    ) -> Result<S::TipReport> {
        prepare_in::<crate::arith::Fused, S>(constants, false, chain, time, q, qd, surroundings)
    }
    fused(constants, chain, time, q, qd, surroundings)
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

    /// SplitMix64 as uniform numbers in `[lo, hi)`, for reproducible states.
    #[cfg(feature = "lockstep")]
    fn splitmix(mut seed: u64) -> impl FnMut(f64, f64) -> f64 {
        move |lo: f64, hi: f64| {
            seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = seed;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            lo + (hi - lo) * ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A random bent, spinning, out-of-plane state of `n` segments; in every third case a third
    /// of the joints folded close to back on themselves.
    #[cfg(feature = "lockstep")]
    fn random_state(
        n: usize,
        case: usize,
        uniform: &mut impl FnMut(f64, f64) -> f64,
    ) -> (Vec<f64>, Vec<f64>) {
        let mut q = vec![uniform(-0.05, 0.2)];
        let mut qd = vec![uniform(-2.0, 2.0)];
        let (mut phi, mut psi) = (uniform(0.0, 1.5), uniform(-0.5, 0.5));
        for k in 0..n {
            if k > 0 && case % 3 == 0 && k % 3 == 0 {
                phi += std::f64::consts::PI - uniform(0.02, 0.2);
            } else {
                phi += uniform(-0.6, 0.6);
                psi = (psi + uniform(-0.4, 0.4)).clamp(-1.2, 1.2);
            }
            q.extend([phi, psi]);
            qd.extend([uniform(-1.5, 1.5), uniform(-1.5, 1.5)]);
        }
        (q, qd)
    }

    /// A smoothly bent, moving state of `n` segments (q, q'; attachment layout).
    fn wavy_state(n: usize) -> (Vec<f64>, Vec<f64>) {
        let mut q = vec![0.05];
        let mut qd = vec![0.3];
        for k in 0..n {
            let f = k as f64;
            q.extend([0.3 + 0.4 * (0.7 * f).sin(), 0.2 * (1.3 * f).cos()]);
            qd.extend([0.5 * (0.4 * f).cos(), -0.3 * (0.9 * f).sin()]);
        }
        (q, qd)
    }

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

    /// A walk through a state (`centres_and_tip_batch`) leaves its kinematics for the next
    /// right-hand side of the same state to reuse: the reuse gives a fresh model's results bit
    /// for bit, a state that differs in one bit (here -0 for +0) or a pass in between that
    /// writes the directions another way (the mass matrix's) is computed afresh.
    #[test]
    fn kinematics_held_by_a_walk_are_reused_only_for_the_same_state() {
        use crate::reference;
        let n = 12;
        let cfg = TetherConfig {
            segments: n,
            ..TetherConfig::table3()
        };
        let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
        let dim = cfg.dofs();
        let (mut q, qd) = wavy_state(n);
        q[4] = 0.0; // psi of segment 2: +0
        let fresh = |q: &[f64], qd: &[f64]| {
            let mut model = TetherModel::new(&cfg).unwrap();
            let mut out = vec![0.0; dim];
            model.accelerations(0.5, q, qd, &flow, &mut out).unwrap();
            out.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        };
        let mut model = TetherModel::new(&cfg).unwrap();
        let mut centres = vec![V3::zeros(); n];
        let mut out = vec![0.0; dim];
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        // Reused: the same state.
        model.centres_and_tip_batch(&q, &qd, &mut centres).unwrap();
        model.accelerations(0.5, &q, &qd, &flow, &mut out).unwrap();
        assert_eq!(bits(&out), fresh(&q, &qd));
        // One bit apart: an angle one ulp larger, whose accelerations differ from the held
        // state's (so that reusing the held pass would show), and -0 for +0.
        let mut other = q.clone();
        other[3] = f64::from_bits(q[3].to_bits() + 1);
        assert_ne!(fresh(&other, &qd), fresh(&q, &qd));
        model.centres_and_tip_batch(&q, &qd, &mut centres).unwrap();
        model
            .accelerations(0.5, &other, &qd, &flow, &mut out)
            .unwrap();
        assert_eq!(bits(&out), fresh(&other, &qd));
        let mut signed = q.clone();
        signed[4] = -0.0;
        model.centres_and_tip_batch(&q, &qd, &mut centres).unwrap();
        assert!(!model
            .ws
            .chain
            .holds_kinematics_of::<crate::arith::Fused>(&signed, &qd));
        assert!(!model.ws.chain.holds_kinematics_of::<Plain>(&signed, &qd));
        model
            .accelerations(0.5, &signed, &qd, &flow, &mut out)
            .unwrap();
        assert_eq!(bits(&out), fresh(&signed, &qd));
        // The mass matrix's directions in between.
        model.centres_and_tip_batch(&q, &qd, &mut centres).unwrap();
        model.mass_matrix(&other).unwrap();
        model.accelerations(0.5, &q, &qd, &flow, &mut out).unwrap();
        assert_eq!(bits(&out), fresh(&q, &qd));
        // A right-hand side does not hold its inputs: only walks do.
        model
            .accelerations(0.5, &other, &qd, &flow, &mut out)
            .unwrap();
        assert!(!model
            .ws
            .chain
            .holds_kinematics_of::<crate::arith::Fused>(&other, &qd));
        model
            .centres_and_tip_batch(&other, &qd, &mut centres)
            .unwrap();
        let held_fused = model
            .ws
            .chain
            .holds_kinematics_of::<crate::arith::Fused>(&other, &qd);
        let held_plain = model.ws.chain.holds_kinematics_of::<Plain>(&other, &qd);
        assert!(
            held_fused ^ held_plain,
            "the walk holds its state in its own flavour"
        );
    }

    /// Four models in lockstep (`accelerations_four`, the sweeps four lanes wide) give each
    /// model's own `accelerations` bit for bit: the accelerations, the axial mass and the tip
    /// report, for four different configurations (tip mass, length, stiffness) in four different
    /// flows, on random bent, folded and spinning states; a lane whose state fails (a NaN
    /// angle, a folded chain) returns the error its single solve returns and leaves the other
    /// lanes' results as they are alone.
    #[cfg(feature = "lockstep")]
    #[test]
    fn lockstep_solve_is_bitwise_four_single_solves() {
        use crate::reference;
        use crate::surroundings::UniformFlow;
        let mut uniform = splitmix(0x10C5);
        let mut work = LockstepWork::default();
        let (mut compared, mut failures) = (0, 0);
        for n in [1usize, 2, 5, 30, 61] {
            let lanes: Vec<(TetherConfig, UniformFlow)> = (0..4)
                .map(|j| {
                    let cfg = TetherConfig {
                        segments: n,
                        length: 250.0 - 20.0 * j as f64,
                        tip_mass: 50.0 + 7.0 * j as f64,
                        axial_stiffness: TetherConfig::table3().axial_stiffness
                            * (1.0 + 0.1 * j as f64),
                        ..TetherConfig::table3()
                    };
                    let (cfg, towed) =
                        reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
                    let flow = UniformFlow {
                        velocity: towed.velocity + Vector3::new(0.0, 7.0 - 3.0 * j as f64, -3.0),
                        tip_force: Vector3::new(40.0, -25.0 + 10.0 * j as f64, 310.0),
                        frame_acceleration: Vector3::new(0.4, -0.2, 0.1 * j as f64),
                        ..towed
                    };
                    (cfg, flow)
                })
                .collect();
            let mut models: Vec<TetherModel> = lanes
                .iter()
                .map(|(c, _)| TetherModel::new(c).unwrap())
                .collect();
            let mut alone: Vec<TetherModel> = models.clone();
            assert_eq!(
                TetherModel::lockstep_eligible(std::array::from_fn(|j| &models[j])),
                cfg!(target_arch = "x86_64") && {
                    #[cfg(target_arch = "x86_64")]
                    {
                        crate::arith::has_avx2_fma()
                    }
                    #[cfg(not(target_arch = "x86_64"))]
                    {
                        false
                    }
                }
            );
            let dim = 2 * n + 1;
            for case in 0..30 {
                let mut states: Vec<(Vec<f64>, Vec<f64>)> = (0..4)
                    .map(|j| random_state(n, case + j, &mut uniform))
                    .collect();
                // Every fifth case one lane's state is broken.
                if case % 5 == 4 {
                    states[case % 4].0[dim - 1] = f64::NAN;
                }
                let times: [f64; 4] = std::array::from_fn(|j| 0.5 + j as f64);
                let mut four = vec![vec![0.0; dim]; 4];
                let results = {
                    let [a, b, c, d] = &mut four[..] else {
                        unreachable!()
                    };
                    let [m0, m1, m2, m3] = &mut models[..] else {
                        unreachable!()
                    };
                    TetherModel::accelerations_four(
                        [m0, m1, m2, m3],
                        times,
                        std::array::from_fn(|j| &states[j].0[..]),
                        std::array::from_fn(|j| &states[j].1[..]),
                        std::array::from_fn(|j| &lanes[j].1),
                        [a, b, c, d],
                        &mut work,
                    )
                };
                for (j, result) in results.into_iter().enumerate() {
                    let mut single = vec![0.0; dim];
                    let reference = alone[j].accelerations(
                        times[j],
                        &states[j].0,
                        &states[j].1,
                        &lanes[j].1,
                        &mut single,
                    );
                    let what = format!("n = {n}, case {case}, lane {j}");
                    match (&result, &reference) {
                        (Ok(a), Ok(b)) => {
                            assert_eq!(format!("{a:?}"), format!("{b:?}"), "{what}");
                            let bits =
                                |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                            assert_eq!(bits(&four[j]), bits(&single), "{what}");
                            compared += 1;
                        }
                        (Err(a), Err(b)) => {
                            assert_eq!(a.to_string(), b.to_string(), "{what}");
                            failures += 1;
                        }
                        _ => panic!("{what}: lockstep {result:?}, alone {reference:?}"),
                    }
                    assert_eq!(
                        models[j].axial_mass().to_bits(),
                        alone[j].axial_mass().to_bits(),
                        "{what}"
                    );
                }
            }
        }
        assert!(compared >= 400, "only {compared} lanes compared");
        assert!(failures >= 25, "only {failures} failing lanes");
    }

    /// Both builds of the recursive solver (plain multiply-adds, used where the processor has no
    /// FMA, and fused ones) agree with the dense solver, for both elasticities; the public entry
    /// points pick one of them at run time, so the other is checked here.
    #[test]
    fn plain_and_fused_recursive_builds_match_dense() {
        use crate::{reference, Elasticity};
        for elasticity in [Elasticity::Attachment, Elasticity::Distributed] {
            for n in [1usize, 2, 7, 30] {
                let cfg = TetherConfig {
                    segments: n,
                    elasticity,
                    ..TetherConfig::table3()
                };
                let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
                let mut model = TetherModel::new(&cfg).unwrap();
                let dim = cfg.dofs();
                let (mut q, mut qd) = wavy_state(n);
                // The distributed model's stretches of segments 2 ... n, small and varied.
                for k in (1..n).filter(|_| elasticity == Elasticity::Distributed) {
                    q.push(0.01 * (0.5 * k as f64).sin());
                    qd.push(0.02 * (0.8 * k as f64).cos());
                }
                assert_eq!(q.len(), dim);
                let mut dense = vec![0.0; dim];
                model
                    .accelerations_dense(0.5, &q, &qd, &flow, &mut dense)
                    .unwrap();
                let scale = dense.iter().fold(0.0f64, |a, b| a.max(b.abs()));
                let check = |a: &[f64], what: &str| {
                    let err = a
                        .iter()
                        .zip(&dense)
                        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
                    assert!(
                        err <= 1e-10 * scale,
                        "{elasticity:?}, n = {n}, {what}: {err:e} of {scale:e}"
                    );
                };
                let mut plain = vec![0.0; dim];
                model
                    .solve_recursive_body::<Plain, _>(0.5, &q, &qd, &flow, &mut plain, None, None)
                    .unwrap();
                check(&plain, "plain");
                let mut fused = vec![0.0; dim];
                model
                    .solve_recursive_body::<crate::arith::Fused, _>(
                        0.5, &q, &qd, &flow, &mut fused, None, None,
                    )
                    .unwrap();
                check(&fused, "fused");
            }
        }
    }
}
