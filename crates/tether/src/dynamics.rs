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

use nalgebra::Vector3;

use crate::axial::{AxialSolve, AxialStage};
use crate::chain::{ChainState, LoadConstants};
use crate::config::TetherConfig;
use crate::direction::DirectionJet;
use crate::distributed::{self, stretch_index};
use crate::error::{Result, TetherError};
use crate::recursive::{self, Articulated, ChainConstants, Held};
use crate::surroundings::Surroundings;

mod dense;

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
    fn prepare<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
    ) -> Result<S::TipReport> {
        let constants = self.load_constants();
        let distributed = self.distributed;
        prepare_in::<S>(
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
        if crate::arith::native() {
            // SAFETY: the processor has AVX2 and FMA, checked just above.
            return unsafe {
                self.solve_recursive_avx2(time, q, qd, surroundings, qdd, tensions, axial)
            };
        }
        self.solve_recursive_body::<S>(time, q, qd, surroundings, qdd, tensions, axial)
    }

    /// [`TetherModel::solve_recursive_body`] compiled for AVX2 and FMA: its multiply-adds one
    /// instruction each and its passes vectorized; the same bits as the portable build.
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
        self.solve_recursive_body::<S>(time, q, qd, surroundings, qdd, tensions, axial)
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn solve_recursive_body<S: Surroundings + ?Sized>(
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
            let report = self.prepare::<S>(time, q, qd, surroundings)?;
            let ws = &mut self.ws;
            distributed::solve(
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
        let report = self.prepare::<S>(time, q, qd, surroundings)?;
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
        self.axial_mass = recursive::solve(
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
                bending -= bend_gain * libm::log(0.5 * (1.0 + p.dot(&e)));
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
        self.tensions_dense(time, q, qd, surroundings, qdd, tensions)
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
        if crate::arith::native() {
            // SAFETY: the processor has AVX2 and FMA, checked just above.
            unsafe { self.kinematics_avx2(q, qd)? };
            self.stretch_batch(q, qd);
            return Ok(self.copy_centres(centres));
        }
        let l = self.l;
        self.ws.chain.kinematics_held(0.0, l, q, qd)?;
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
        self.ws.chain.kinematics_held(0.0, l, q, qd)
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

/// [`TetherModel::prepare`] into a given chain: kinematics and loads of every segment and the tip.
#[inline(always)]
fn prepare_in<S: Surroundings + ?Sized>(
    constants: &LoadConstants,
    distributed: bool,
    chain: &mut ChainState,
    time: f64,
    q: &[f64],
    qd: &[f64],
    surroundings: &S,
) -> Result<S::TipReport> {
    let (n, l) = (chain.segments(), constants.l);
    chain.kinematics(time, l, q, qd)?;
    if distributed {
        chain.stretch_centres(l, |k| {
            let i = stretch_index(n, k);
            (q[i], qd[i])
        });
    }
    chain.loads::<S>(time, constants, surroundings)
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert!(!model.ws.chain.holds_kinematics_of(&signed, &qd));
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
        assert!(!model.ws.chain.holds_kinematics_of(&other, &qd));
        model
            .centres_and_tip_batch(&other, &qd, &mut centres)
            .unwrap();
        assert!(model.ws.chain.holds_kinematics_of(&other, &qd));
    }

    /// Both builds of the recursive solver (plain multiply-adds, used where the processor has no
    /// FMA, and fused ones) agree with the dense solver, for both elasticities; the public entry
    /// points pick one of them at run time, so the other is checked here.
    #[test]
    fn portable_and_native_builds_agree_bitwise_and_match_dense() {
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
                // The portable build (this function as compiled for any processor: `mul_add`
                // through the C library's `fma`) and, where the processor allows, the native
                // one (compiled for AVX2 and FMA): bit for bit the same, tensions included.
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                let mut portable = vec![0.0; dim];
                let mut portable_t = vec![0.0; n + 1];
                model
                    .solve_recursive_body(
                        0.5,
                        &q,
                        &qd,
                        &flow,
                        &mut portable,
                        Some(&mut portable_t),
                        None,
                    )
                    .unwrap();
                let portable_mass = model.axial_mass();
                check(&portable, "portable");
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    let mut native = vec![0.0; dim];
                    let mut native_t = vec![0.0; n + 1];
                    // SAFETY: the processor has AVX2 and FMA, checked just above.
                    unsafe {
                        model.solve_recursive_avx2(
                            0.5,
                            &q,
                            &qd,
                            &flow,
                            &mut native,
                            Some(&mut native_t),
                            None,
                        )
                    }
                    .unwrap();
                    assert_eq!(bits(&native), bits(&portable), "{elasticity:?}, n = {n}");
                    assert_eq!(
                        bits(&native_t),
                        bits(&portable_t),
                        "{elasticity:?}, n = {n}"
                    );
                    assert_eq!(model.axial_mass().to_bits(), portable_mass.to_bits());
                }
            }
        }
    }
}
