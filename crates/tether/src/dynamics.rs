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
//! * `Q = sum_i J_ci^T (F_i - m c_i''|_{q''=0}) - I J_ei^T e_i''|_{q''=0} + J_t^T (F_t - M_t p_t''|_{q''=0})
//!   + Q_M + Q_D - [k s + c_s s', 0, ...]`: external forces `F_i` on the segment centres
//!   (gravity, the apparent force -m a_TA of Eq. 10, aerodynamics of section 2.3.4), the tip force
//!   `F_t` (Eq. 8), the convective inertia terms (the paper's `f`), bending (Eq. 5) and damping
//!   (Eq. 7) in the coordinate-free forms below, and the axial element.
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
//! `v = v_air(c_i) - c_i'`, split into `v_t = (v . e_i) e_i` and `v_n = v - v_t`:
//! `F = 1/2 rho d l (C_n |v_n| v_n + pi C_t |v_t| v_t)`.
//!
//! All of `Q` costs O(n) through suffix sums; the dense solve of `M` costs O(n^3) and is the
//! reference formulation ([`Solver::Dense`]). The hot path ([`Solver::Recursive`], the default)
//! solves the same equations in O(n) by the articulated-body recursion of [`crate::recursive`].

use nalgebra::{DMatrix, Vector3};

use crate::arith::{axpy, cross, dot, Madd, Plain};
use crate::config::TetherConfig;
use crate::direction::DirectionJet;
use crate::error::{Result, TetherError};
use crate::recursive::{self, Articulated, Chain, ChainConstants};
use crate::surroundings::Surroundings;

type V3 = Vector3<f64>;

/// Below this |cos psi| a segment is taken to have reached the coordinate singularity.
const SINGULAR_COS_PSI: f64 = 1e-6;
/// Below this 1 + cos(theta) a joint is taken to have folded back on itself.
const FOLDED_JOINT: f64 = 1e-12;

/// Energy of the tether and tip body, J, in the towing-aircraft frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Energy {
    /// Translational and rotational kinetic energy.
    pub kinetic: f64,
    /// Gravitational potential, zero at the attachment's height (z down, so it is negative below).
    pub gravity: f64,
    /// Strain energy of the axial element, k s^2 / 2.
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
    solver: Solver,
    ws: Workspace,
}

/// The geometry of one segment at the current state: its direction and partials.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Geometry {
    /// Unit direction e.
    pub e: V3,
    /// de/dphi (length cos psi, its y component is zero).
    pub e_phi: V3,
    /// de/dpsi (unit).
    pub e_psi: V3,
    /// cos psi.
    pub cos_psi: f64,
}

/// The motion of one segment at the current state.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Motion {
    /// Convective acceleration of e (with zero angle accelerations).
    pub w: V3,
    /// Angular velocity e x e'.
    pub omega: V3,
    /// Centre and its velocity.
    pub com: V3,
    pub com_vel: V3,
}

/// The loads on one segment (dense path).
#[derive(Debug, Clone, Copy, Default)]
struct SegmentLoads {
    force: V3,
    extra: V3,
}

/// The loads on the segments, evaluated one segment at a time from the tip to the root
/// ([`Loads::next`]), so that the recursive solver can eliminate each segment as soon as its loads
/// are known. Both solvers use it.
pub(crate) struct Loads<'a, S: ?Sized> {
    time: f64,
    geom: &'a [Geometry],
    motion: &'a [Motion],
    surroundings: &'a S,
    p: LoadParameters,
    /// Segment k's share of the joint between k and k+1, from the previous call.
    carry: V3,
}

/// The constants of the loads at one time.
#[derive(Debug, Clone, Copy)]
struct LoadParameters {
    weight: V3,
    bend_gain: f64,
    c_b: f64,
    rod_inertia: f64,
    normal_drag: f64,
    tangential_drag: f64,
}

impl<S: Surroundings + ?Sized> Loads<'_, S> {
    /// External force `F_k` on the centre of segment k (gravity, apparent, aerodynamics) and its
    /// vector `X_k` (bending, joint damping, rotational convective inertia -I w), whose
    /// projections `E_kb . X_k` are generalized forces. Call for k = n-1, n-2, ..., 0 in order.
    ///
    /// Errors if the joint between k-1 and k has folded back completely.
    #[inline(always)]
    pub(crate) fn next<M: Madd>(&mut self, k: usize) -> Result<(V3, V3)> {
        let (g, mo) = (&self.geom[k], &self.motion[k]);
        let e = g.e;
        let rho = self.surroundings.air_density(self.time, &mo.com);
        let mut force = self.p.weight;
        if rho != 0.0 {
            let rel = self.surroundings.air_velocity(self.time, &mo.com) - mo.com_vel;
            let vt = dot::<M>(&rel, &e);
            let vn = axpy::<M>(&e, -vt, &rel);
            let vn_abs = dot::<M>(&vn, &vn).sqrt();
            force = axpy::<M>(&e, rho * self.p.tangential_drag * vt * vt.abs(), &force);
            force = axpy::<M>(&vn, rho * self.p.normal_drag * vn_abs, &force);
        }
        let mut extra = axpy::<M>(&mo.w, -self.p.rod_inertia, &self.carry);
        if k > 0 {
            // Bending spring and joint damper between segments k-1 and k.
            let prev = &self.geom[k - 1];
            let one_plus_cos = 1.0 + dot::<M>(&prev.e, &e);
            if !(one_plus_cos >= FOLDED_JOINT && one_plus_cos < f64::INFINITY) {
                return Err(TetherError::Diverged {
                    time: self.time,
                    reason: format!(
                        "joint {k} between segments {k} and {} folded back on itself",
                        k + 1
                    ),
                });
            }
            let coef = self.p.bend_gain / one_plus_cos;
            // Damping torque of this joint: on segment k it is -c_b (w_k - w_{k-1}), on segment
            // k-1 the opposite; Q_(k,b) = E_kb . (tau_k x e_k).
            let tau = (mo.omega - self.motion[k - 1].omega) * self.p.c_b;
            extra = axpy::<M>(&prev.e, coef, &extra) - cross::<M>(&tau, &e);
            self.carry = axpy::<M>(&e, coef, &cross::<M>(&tau, &prev.e));
        }
        Ok((force, extra))
    }
}

#[derive(Debug, Clone)]
struct Workspace {
    geom: Vec<Geometry>,
    motion: Vec<Motion>,
    /// Loads per segment (dense path only).
    loads: Vec<SegmentLoads>,
    /// sin and cos of the 2n angles.
    sin: Vec<f64>,
    cos: Vec<f64>,
    /// Rate of e_1.
    e_dot0: V3,
    tip: V3,
    tip_vel: V3,
    tip_force: V3,
    /// Convective accelerations of the segment centres (dense path only; sized on first use).
    com_acc0: Vec<V3>,
    tip_acc0: V3,
    /// Lower triangle of the mass matrix, row-major, dim x dim; overwritten by its Cholesky factor.
    /// Allocated on the first dense solve only.
    mass: Vec<f64>,
    /// Per-segment results of the recursive solver's backward sweep.
    articulated: Vec<Articulated>,
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
            ws: Workspace {
                geom: vec![Geometry::default(); n],
                motion: vec![Motion::default(); n],
                loads: vec![SegmentLoads::default(); n],
                sin: vec![0.0; 2 * n],
                cos: vec![0.0; 2 * n],
                e_dot0: V3::zeros(),
                tip: V3::zeros(),
                tip_vel: V3::zeros(),
                tip_force: V3::zeros(),
                com_acc0: Vec::new(),
                tip_acc0: V3::zeros(),
                mass: Vec::new(),
                articulated: vec![Articulated::default(); n],
            },
            solver: Solver::default(),
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

    /// Number of generalized coordinates 2n + 1.
    pub fn dofs(&self) -> usize {
        2 * self.n + 1
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

    fn singular_chart(time: f64, k: usize, cos_psi: f64) -> TetherError {
        TetherError::Diverged {
            time,
            reason: format!(
                "segment {} points along the lateral axis (cos psi = {:.3e}), the coordinate singularity",
                k + 1,
                cos_psi
            ),
        }
    }

    /// First pass, root to tip: directions and their partials (sin and cos of all angles in one
    /// vectorized batch, [`crate::trig`]), rates, convective accelerations, angular velocities,
    /// the centres and their velocities, the tip and its velocity, and the force on the tip.
    /// Errors at the coordinate singularity.
    #[inline(always)]
    fn kinematics<M: Madd, S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
    ) -> Result<()> {
        let (s, sd) = (q[0], qd[0]);
        let (l, half) = (self.l, 0.5 * self.l);
        let tip_weight = self.effective_gravity(time, surroundings) * self.tip_mass;
        let ws = &mut self.ws;
        crate::trig::sin_cos_batch(&q[1..], &mut ws.sin, &mut ws.cos);
        let mut p = V3::zeros();
        let mut pv = V3::zeros();
        for k in 0..self.n {
            let (sf, cf) = (ws.sin[2 * k], ws.cos[2 * k]);
            let (sp, cp) = (ws.sin[2 * k + 1], ws.cos[2 * k + 1]);
            if !(cp.abs() >= SINGULAR_COS_PSI) {
                return Err(Self::singular_chart(time, k, cp));
            }
            // See DirectionJet: d2e/dphi2 = cp (cf, 0, -sf), d2e/dphidpsi = -sp (sf, 0, cf),
            // d2e/dpsi2 = -e.
            let e = V3::new(-cp * cf, sp, cp * sf);
            let e_phi = V3::new(cp * sf, 0.0, cp * cf);
            let e_psi = V3::new(sp * cf, cp, -sp * sf);
            let (phi_d, psi_d) = (qd[1 + 2 * k], qd[2 + 2 * k]);
            let e_dot = axpy::<M>(&e_psi, psi_d, &(e_phi * phi_d));
            let (pp, ps2, ss) = (phi_d * phi_d, 2.0 * phi_d * psi_d, psi_d * psi_d);
            let w = V3::new(
                M::madd(e_phi.z, pp, e_psi.z * ps2),
                0.0,
                -M::madd(e_phi.x, pp, e_psi.x * ps2),
            );
            let w = axpy::<M>(&e, -ss, &w);
            if k == 0 {
                p = e * s;
                pv = axpy::<M>(&e_dot, s, &(e * sd));
                ws.e_dot0 = e_dot;
            }
            ws.geom[k] = Geometry {
                e,
                e_phi,
                e_psi,
                cos_psi: cp,
            };
            ws.motion[k] = Motion {
                w,
                omega: cross::<M>(&e, &e_dot),
                com: axpy::<M>(&e, half, &p),
                com_vel: axpy::<M>(&e_dot, half, &pv),
            };
            p = axpy::<M>(&e, l, &p);
            pv = axpy::<M>(&e_dot, l, &pv);
        }
        ws.tip = p;
        ws.tip_vel = pv;
        ws.tip_force = tip_weight + surroundings.tip_force(time, &p, &pv);
        Ok(())
    }

    /// Gravity plus the apparent acceleration of the accelerating frame.
    #[inline(always)]
    fn effective_gravity<S: Surroundings + ?Sized>(&self, time: f64, surroundings: &S) -> V3 {
        V3::new(0.0, 0.0, self.gravity) - surroundings.frame_acceleration(time)
    }

    /// The constants of the loads at `time`.
    #[inline(always)]
    fn load_parameters<S: Surroundings + ?Sized>(
        &self,
        time: f64,
        surroundings: &S,
    ) -> LoadParameters {
        LoadParameters {
            weight: self.effective_gravity(time, surroundings) * self.m,
            bend_gain: 2.0 * self.ei / self.l,
            c_b: self.c_b,
            rod_inertia: self.rod_inertia,
            normal_drag: self.normal_drag,
            tangential_drag: self.tangential_drag,
        }
    }

    /// Kinematics and loads of every segment and the tip, stored, for the dense solver.
    ///
    /// Errors at the coordinate singularity or at a completely folded joint.
    fn prepare<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
    ) -> Result<()> {
        self.kinematics::<Plain, S>(time, q, qd, surroundings)?;
        let params = self.load_parameters(time, surroundings);
        let ws = &mut self.ws;
        let mut loads = Loads {
            time,
            geom: &ws.geom,
            motion: &ws.motion,
            surroundings,
            p: params,
            carry: V3::zeros(),
        };
        for k in (0..self.n).rev() {
            let (force, extra) = loads.next::<Plain>(k)?;
            ws.loads[k] = SegmentLoads { force, extra };
        }
        Ok(())
    }

    /// Directions and their partials only (for the mass matrix).
    fn directions(&mut self, q: &[f64]) {
        for k in 0..self.n {
            let jet = DirectionJet::new(q[1 + 2 * k], q[2 + 2 * k]);
            self.ws.geom[k] = Geometry {
                e: jet.e,
                e_phi: jet.e_phi,
                e_psi: jet.e_psi,
                cos_psi: jet.cos_psi,
            };
        }
    }

    /// Walks the chain with the state's positions and velocities: calls `visit(e, e_dot, centre,
    /// centre velocity)` per segment and returns the tip's position and velocity.
    fn walk(&self, q: &[f64], qd: &[f64], mut visit: impl FnMut(V3, V3, V3, V3)) -> (V3, V3) {
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
        let mut pa = ws.e_dot0 * (2.0 * sd) + ws.motion[0].w * s;
        for k in 0..self.n {
            ws.com_acc0[k] = pa + ws.motion[k].w * half;
            pa += ws.motion[k].w * self.l;
        }
        ws.tip_acc0 = pa;
        let mut suffix = ws.tip_force - ws.tip_acc0 * self.tip_mass;
        let mut total = suffix;
        for k in (0..self.n).rev() {
            let (geo, seg) = (&ws.geom[k], &ws.loads[k]);
            let h = seg.force - ws.com_acc0[k] * self.m;
            let (a_kk, l_k) = if k == 0 {
                (half + s, self.l + s)
            } else {
                (half, self.l)
            };
            let g = h * a_kk + suffix * l_k + seg.extra;
            rhs[1 + 2 * k] = geo.e_phi.dot(&g);
            rhs[2 + 2 * k] = geo.e_psi.dot(&g);
            suffix += h;
            total += h;
        }
        rhs[0] = ws.geom[0].e.dot(&total) - self.k * s - self.c_s * sd;
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
        let e1 = ws.geom[0].e;
        for k in 0..n {
            let (a_kk, l_k) = if k == 0 { (half + s, l + s) } else { (half, l) };
            let beyond = m * (n - 1 - k) as f64 + tip;
            let v_k = m * a_kk + beyond * l_k;
            let w_kk = m * a_kk * a_kk + beyond * l_k * l_k + self.rod_inertia;
            let jk = ws.geom[k];
            let (rp, rs) = (1 + 2 * k, 2 + 2 * k);
            ws.mass[rp * dim] = v_k * e1.dot(&jk.e_phi);
            ws.mass[rs * dim] = v_k * e1.dot(&jk.e_psi);
            // Rows of segment k against segments j < k: W_jk = l_j V_k.
            for j in 0..k {
                let l_j = if j == 0 { l + s } else { l };
                let w = l_j * v_k;
                let jj = ws.geom[j];
                let (cp, cs) = (1 + 2 * j, 2 + 2 * j);
                ws.mass[rp * dim + cp] = w * jk.e_phi.dot(&jj.e_phi);
                ws.mass[rp * dim + cs] = w * jk.e_phi.dot(&jj.e_psi);
                ws.mass[rs * dim + cp] = w * jk.e_psi.dot(&jj.e_phi);
                ws.mass[rs * dim + cs] = w * jk.e_psi.dot(&jj.e_psi);
            }
            ws.mass[rp * dim + rp] = w_kk * jk.cos_psi * jk.cos_psi;
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
    ) -> Result<()> {
        match self.solver {
            Solver::Recursive => self.solve_recursive(time, q, qd, surroundings, qdd, None),
            Solver::Dense => self.accelerations_dense(time, q, qd, surroundings, qdd),
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
    ) -> Result<()> {
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
    ) -> Result<()> {
        self.check_len("q", q)?;
        self.check_len("qd", qd)?;
        self.check_len("qdd", qdd)?;
        self.prepare(time, q, qd, surroundings)?;
        self.generalized_forces(q, qd, qdd);
        self.assemble_mass(q[0]);
        let dim = self.dofs();
        cholesky_in_place(&mut self.ws.mass, dim).map_err(|col| TetherError::Diverged {
            time,
            reason: format!("mass matrix lost positive definiteness at column {col}"),
        })?;
        cholesky_solve(&self.ws.mass, dim, qdd);
        Ok(())
    }

    fn solve_recursive<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        tensions: Option<&mut [f64]>,
    ) -> Result<()> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the processor has AVX2 and FMA, checked just above.
            return unsafe { self.solve_recursive_avx2(time, q, qd, surroundings, qdd, tensions) };
        }
        self.solve_recursive_body::<Plain, S>(time, q, qd, surroundings, qdd, tensions)
    }

    /// [`TetherModel::solve_recursive_body`] compiled for AVX2 and FMA, with fused multiply-adds.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn solve_recursive_avx2<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        tensions: Option<&mut [f64]>,
    ) -> Result<()> {
        self.solve_recursive_body::<crate::arith::Fused, S>(
            time,
            q,
            qd,
            surroundings,
            qdd,
            tensions,
        )
    }

    #[inline(always)]
    fn solve_recursive_body<M: Madd, S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        surroundings: &S,
        qdd: &mut [f64],
        tensions: Option<&mut [f64]>,
    ) -> Result<()> {
        self.check_len("q", q)?;
        self.check_len("qd", qd)?;
        self.check_len("qdd", qdd)?;
        let constants = ChainConstants {
            l: self.l,
            m: self.m,
            rod_inertia: self.rod_inertia,
            tip_mass: self.tip_mass,
            k: self.k,
            c_s: self.c_s,
        };
        self.kinematics::<M, S>(time, q, qd, surroundings)?;
        let params = self.load_parameters(time, surroundings);
        let ws = &mut self.ws;
        let loads = Loads {
            time,
            geom: &ws.geom,
            motion: &ws.motion,
            surroundings,
            p: params,
            carry: V3::zeros(),
        };
        let chain = Chain {
            geom: &ws.geom,
            motion: &ws.motion,
            e_dot0: ws.e_dot0,
            tip_force: ws.tip_force,
        };
        recursive::solve::<M, S>(
            time,
            &constants,
            &chain,
            loads,
            q[0],
            qd[0],
            &mut ws.articulated,
            qdd,
            tensions,
        )
    }

    /// The mass matrix M(q) (symmetric, dim x dim). Allocates; for analysis and tests.
    pub fn mass_matrix(&mut self, q: &[f64]) -> Result<DMatrix<f64>> {
        self.check_len("q", q)?;
        self.directions(q);
        self.assemble_mass(q[0]);
        let dim = self.dofs();
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
        Ok(Energy {
            kinetic,
            gravity: -self.gravity * height,
            axial: 0.5 * self.k * q[0] * q[0],
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
            return self.solve_recursive(time, q, qd, surroundings, qdd, Some(tensions));
        }
        self.accelerations_dense(time, q, qd, surroundings, qdd)?;
        let ws = &self.ws;
        let (s, sd, sdd) = (q[0], qd[0], qdd[0]);
        let acc_dir = |k: usize| {
            let geo = &ws.geom[k];
            ws.motion[k].w + geo.e_phi * qdd[1 + 2 * k] + geo.e_psi * qdd[2 + 2 * k]
        };
        let e1dd = acc_dir(0);
        let mut pa = ws.geom[0].e * sdd + ws.e_dot0 * (2.0 * sd) + e1dd * s;
        // Accelerations of centres, stored in place of nothing: accumulate forward, then sum backward.
        // Two passes keep it allocation-free: first the tip acceleration, then walk inward.
        for k in 0..self.n {
            pa += acc_dir(k) * self.l;
        }
        let mut pull = ws.tip_force - pa * self.tip_mass;
        tensions[self.n] = pull.dot(&ws.geom[self.n - 1].e);
        // Walk inward: the base of segment k is the tip position minus l e_j for j >= k.
        let mut base_acc = pa;
        for k in (0..self.n).rev() {
            let ek_dd = acc_dir(k);
            base_acc -= ek_dd * self.l;
            let com_acc = base_acc + ek_dd * (0.5 * self.l);
            pull += ws.loads[k].force - com_acc * self.m;
            tensions[k] = pull.dot(&ws.geom[k].e);
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
        let mut p = crate::direction::direction(q[1], q[2]) * q[0];
        out[0] = p;
        for k in 0..self.n {
            p += crate::direction::direction(q[1 + 2 * k], q[2 + 2 * k]) * self.l;
            out[k + 1] = p;
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
        if !(d > 0.0) || !d.is_finite() {
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
