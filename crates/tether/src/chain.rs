//! The state of the chain at one right-hand-side evaluation (directions, rates, positions, loads
//! of every segment), computed in passes over structure-of-arrays buffers so that the compiler
//! vectorizes them across segments. Shared by the recursive and the dense solver.
//!
//! * [`ChainState::kinematics`]: sin and cos of all angles ([`crate::trig`]); per segment the
//!   direction `e`, its partials `E_phi`, `E_psi`, its rate `e'`, its convective acceleration `w`
//!   (with zero angle accelerations) and the angular velocity `e x e'` (independent per segment);
//!   then the centres and their velocities and the tip (prefix sums from the root).
//! * [`ChainState::loads`]: per joint the bending spring and the damper; per segment the external
//!   force `F_k` on its centre (gravity, apparent force of the accelerating frame, aerodynamics)
//!   and the vector `X_k` (bending, joint damping, rotational convective inertia `-I w_k`) whose
//!   projections `E_kb . X_k` are generalized forces; the force on the tip body.
//!
//! The formulas are those of [`crate::dynamics`]'s module documentation.

use nalgebra::Vector3;

use crate::arith::{axpy, cross, dot, madd};
use crate::direction::DirectionJet;
use crate::error::{Result, TetherError};
use crate::surroundings::Surroundings;

type V3 = Vector3<f64>;

/// Below this |cos psi| a segment is taken to have reached the coordinate singularity.
const SINGULAR_COS_PSI: f64 = 1e-6;
/// Below this 1 + cos(theta) a joint is taken to have folded back on itself.
const FOLDED_JOINT: f64 = 1e-12;

/// Three components in three arrays.
#[derive(Debug, Clone, Default)]
pub(crate) struct Lanes {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub z: Vec<f64>,
}

impl Lanes {
    fn new(len: usize) -> Self {
        Lanes {
            x: vec![0.0; len],
            y: vec![0.0; len],
            z: vec![0.0; len],
        }
    }

    #[inline(always)]
    pub fn get(&self, k: usize) -> V3 {
        V3::new(self.x[k], self.y[k], self.z[k])
    }

    #[inline(always)]
    pub fn set(&mut self, k: usize, v: V3) {
        self.x[k] = v.x;
        self.y[k] = v.y;
        self.z[k] = v.z;
    }

    /// The first `len` entries, read-only (bounds known to the compiler).
    #[inline(always)]
    pub fn view(&self, len: usize) -> View<'_> {
        View {
            x: &self.x[..len],
            y: &self.y[..len],
            z: &self.z[..len],
        }
    }

    /// The three arrays cut to `len`, for loops the compiler can vectorize.
    #[inline(always)]
    fn slices(&mut self, len: usize) -> (&mut [f64], &mut [f64], &mut [f64]) {
        (&mut self.x[..len], &mut self.y[..len], &mut self.z[..len])
    }
}

/// Read-only [`Lanes`] of known length.
#[derive(Debug, Clone, Copy)]
pub(crate) struct View<'a> {
    pub x: &'a [f64],
    pub y: &'a [f64],
    pub z: &'a [f64],
}

impl View<'_> {
    #[inline(always)]
    pub fn get(&self, k: usize) -> V3 {
        V3::new(self.x[k], self.y[k], self.z[k])
    }
}

/// Physical constants of the loads.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LoadConstants {
    /// Segment mass m and tip mass M_t, kg.
    pub m: f64,
    pub tip_mass: f64,
    /// Rod inertia I = m l^2 / 12, kg m^2.
    pub rod_inertia: f64,
    /// 2 EI / l, N m.
    pub bend_gain: f64,
    /// Joint damping c_b, N m s.
    pub c_b: f64,
    /// 1/2 d l C_n and 1/2 pi d l C_t, m^2.
    pub normal_drag: f64,
    pub tangential_drag: f64,
    /// Weight of the segment's own velocity in its drag: 1 (relative velocity, the default) or
    /// 0 (free stream, [`crate::DragVelocity`]).
    pub segment_velocity_weight: f64,
    /// Gravity, m/s^2 (along +z).
    pub gravity: f64,
    /// Segment length l, m.
    pub l: f64,
}

/// Per-segment state of the chain (see the module documentation).
#[derive(Debug, Clone)]
pub(crate) struct ChainState {
    n: usize,
    /// The angles phi and psi, padded with zeros to a multiple of four segments so that the
    /// vectorized sin/cos loop has no scalar remainder.
    phi: Vec<f64>,
    psi: Vec<f64>,
    sin_phi: Vec<f64>,
    cos_phi: Vec<f64>,
    sin_psi: Vec<f64>,
    /// cos psi per segment.
    pub cos_psi: Vec<f64>,
    pub e: Lanes,
    /// de/dphi; its y component is zero (not stored: `e_phi.y` stays zero).
    pub e_phi: Lanes,
    pub e_psi: Lanes,
    pub e_dot: Lanes,
    pub w: Lanes,
    pub omega: Lanes,
    pub com: Lanes,
    pub com_vel: Lanes,
    /// Per joint j (between segments j-1 and j; entries 0 and n are zero): its contribution to
    /// `X_j` (outboard segment) and to `X_{j-1}` (inboard segment).
    to_outboard: Lanes,
    to_inboard: Lanes,
    pub force: Lanes,
    pub extra: Lanes,
    /// `r_k = F_k / (2 l) + X_k / l^2 + (m/4) w_k`, the part of the recursive solver's bias term
    /// that does not depend on the outboard chain (see [`crate::recursive`]).
    pub reduced: Lanes,
    pub tip: V3,
    pub tip_vel: V3,
    pub tip_force: V3,
    /// Which inputs the kinematics fields hold (see [`ChainState::kinematics`]).
    held: HeldKinematics,
}

/// The inputs of the kinematics a [`ChainState`] holds: the bits of `q` and `q'` (their first
/// 2n + 1 entries, all the pass reads), or nothing.
#[derive(Debug, Clone)]
struct HeldKinematics {
    /// Whether `inputs` holds the inputs of the kinematics fields.
    valid: bool,
    /// `q` then `q'`, as bits (so that -0 and +0 differ, and NaN never matches).
    inputs: Vec<u64>,
}

impl HeldKinematics {
    /// Whether the held kinematics are those of `(q, qd)`.
    #[inline(always)]
    fn holds(&self, q: &[f64], qd: &[f64]) -> bool {
        if !self.valid {
            return false;
        }
        let (held_q, held_qd) = self.inputs.split_at(q.len());
        q.iter().zip(held_q).all(|(a, b)| a.to_bits() == *b)
            && qd.iter().zip(held_qd).all(|(a, b)| a.to_bits() == *b)
    }

    #[inline(always)]
    fn hold(&mut self, q: &[f64], qd: &[f64]) {
        let (held_q, held_qd) = self.inputs.split_at_mut(q.len());
        for (h, v) in held_q.iter_mut().zip(q) {
            *h = v.to_bits();
        }
        for (h, v) in held_qd.iter_mut().zip(qd) {
            *h = v.to_bits();
        }
        self.valid = true;
    }
}

impl ChainState {
    pub fn new(n: usize) -> Self {
        let padded = n.div_ceil(4) * 4;
        ChainState {
            n,
            phi: vec![0.0; padded],
            psi: vec![0.0; padded],
            sin_phi: vec![0.0; padded],
            cos_phi: vec![0.0; padded],
            sin_psi: vec![0.0; padded],
            cos_psi: vec![0.0; padded],
            e: Lanes::new(n),
            e_phi: Lanes::new(n),
            e_psi: Lanes::new(n),
            e_dot: Lanes::new(n),
            w: Lanes::new(n),
            omega: Lanes::new(n),
            com: Lanes::new(n),
            com_vel: Lanes::new(n),
            to_outboard: Lanes::new(n + 1),
            to_inboard: Lanes::new(n + 1),
            force: Lanes::new(n),
            extra: Lanes::new(n),
            reduced: Lanes::new(n),
            tip: V3::zeros(),
            tip_vel: V3::zeros(),
            tip_force: V3::zeros(),
            held: HeldKinematics {
                valid: false,
                inputs: vec![0; 2 * (2 * n + 1)],
            },
        }
    }

    /// Number of segments n.
    pub fn segments(&self) -> usize {
        self.n
    }

    /// Directions and their partials only, from libm's sin and cos (for the mass matrix).
    pub fn directions(&mut self, q: &[f64]) {
        self.held.valid = false;
        for k in 0..self.n {
            let jet = DirectionJet::new(q[1 + 2 * k], q[2 + 2 * k]);
            self.e.set(k, jet.e);
            self.e_phi.set(k, jet.e_phi);
            self.e_psi.set(k, jet.e_psi);
            self.cos_psi[k] = jet.cos_psi;
        }
    }

    /// The kinematics pass (see the module documentation). Errors at the coordinate singularity.
    ///
    /// A pure function of `(q, q')` (their first 2n + 1 entries; `l` is the model's): when the
    /// fields hold the pass of the same inputs, bit for bit and with the same multiply-adds, as
    /// [`ChainState::kinematics_held`] left them, it returns at once. That is the first RK4
    /// stage of a capture step, whose state the step before has just walked through
    /// ([`crate::TetherModel::centres_and_tip_batch`]).
    #[inline(always)]
    pub fn kinematics(&mut self, time: f64, l: f64, q: &[f64], qd: &[f64]) -> Result<()> {
        let n = self.n;
        let (q, qd) = (&q[..2 * n + 1], &qd[..2 * n + 1]);
        if self.held.holds(q, qd) {
            return Ok(());
        }
        self.held.valid = false;
        self.kinematics_pass(time, l, q, qd)
    }

    /// Whether the kinematics fields hold the pass of `(q, qd)` (for tests).
    #[cfg(test)]
    pub fn holds_kinematics_of(&self, q: &[f64], qd: &[f64]) -> bool {
        let n = self.n;
        self.held.holds(&q[..2 * n + 1], &qd[..2 * n + 1])
    }

    /// [`ChainState::kinematics`], then remembers its inputs, so that the next pass of the same
    /// inputs is skipped (for a walk through a state that a step will start from).
    #[inline(always)]
    pub fn kinematics_held(&mut self, time: f64, l: f64, q: &[f64], qd: &[f64]) -> Result<()> {
        self.kinematics(time, l, q, qd)?;
        let n = self.n;
        self.held.hold(&q[..2 * n + 1], &qd[..2 * n + 1]);
        Ok(())
    }

    #[inline(always)]
    fn kinematics_pass(&mut self, time: f64, l: f64, q: &[f64], qd: &[f64]) -> Result<()> {
        let n = self.n;
        let (s, sd) = (q[0], qd[0]);
        let (phi, psi) = (&mut self.phi[..n], &mut self.psi[..n]);
        for (k, angles) in q[1..1 + 2 * n].chunks_exact(2).enumerate() {
            (phi[k], psi[k]) = (angles[0], angles[1]);
        }
        crate::trig::sin_cos_batch(&self.phi, &mut self.sin_phi, &mut self.cos_phi);
        crate::trig::sin_cos_batch(&self.psi, &mut self.sin_psi, &mut self.cos_psi);
        let rates = &qd[1..1 + 2 * n];
        let (ex, ey, ez) = self.e.slices(n);
        let (epx, _, epz) = self.e_phi.slices(n);
        let (esx, esy, esz) = self.e_psi.slices(n);
        let (edx, edy, edz) = self.e_dot.slices(n);
        let (wx, wy, wz) = self.w.slices(n);
        let (ox, oy, oz) = self.omega.slices(n);
        let singular = directions_and_rates(
            &self.sin_phi[..n],
            &self.cos_phi[..n],
            &self.sin_psi[..n],
            &self.cos_psi[..n],
            rates,
            ex,
            ey,
            ez,
            epx,
            epz,
            esx,
            esy,
            esz,
            edx,
            edy,
            edz,
            wx,
            wy,
            wz,
            ox,
            oy,
            oz,
        );
        if singular > 0 {
            let k = (0..n)
                .find(|&k| !(SINGULAR_COS_PSI..=f64::INFINITY).contains(&self.cos_psi[k].abs()))
                .unwrap_or(0);
            return Err(TetherError::Diverged {
                time,
                reason: format!(
                    "segment {} points along the lateral axis (cos psi = {:.3e}), the coordinate singularity",
                    k + 1,
                    self.cos_psi[k]
                ),
            });
        }

        // Centres, their velocities and the tip: prefix sums from the attachment point.
        let half = 0.5 * l;
        let (e, e_dot) = (self.e.view(n), self.e_dot.view(n));
        let (cx, cy, cz) = self.com.slices(n);
        let (vx, vy, vz) = self.com_vel.slices(n);
        let e0 = e.get(0);
        let mut p = e0 * s;
        let mut pv = axpy(&e_dot.get(0), s, &(e0 * sd));
        for k in 0..n {
            let (e, e_dot) = (e.get(k), e_dot.get(k));
            let (c, v) = (axpy(&e, half, &p), axpy(&e_dot, half, &pv));
            (cx[k], cy[k], cz[k]) = (c.x, c.y, c.z);
            (vx[k], vy[k], vz[k]) = (v.x, v.y, v.z);
            p = axpy(&e, l, &p);
            pv = axpy(&e_dot, l, &pv);
        }
        self.tip = p;
        self.tip_vel = pv;
        Ok(())
    }

    /// The distributed elasticity's centres, their velocities and the tip, after
    /// [`ChainState::kinematics`] (whose prefix sums carry segment 1's stretch only): segment k's
    /// rod starts `s_k e_k` beyond its joint, with `s_k` and `s_k'` from `stretch(k)`.
    pub fn stretch_centres(&mut self, l: f64, stretch: impl Fn(usize) -> (f64, f64)) {
        // The centres and the tip are no longer the kinematics pass's alone.
        self.held.valid = false;
        let n = self.n;
        let half = 0.5 * l;
        let mut p = V3::zeros();
        let mut pv = V3::zeros();
        for k in 0..n {
            let (e, e_dot) = (self.e.get(k), self.e_dot.get(k));
            let (s, sd) = stretch(k);
            p += e * s;
            pv += e * sd + e_dot * s;
            self.com.set(k, p + e * half);
            self.com_vel.set(k, pv + e_dot * half);
            p += e * l;
            pv += e_dot * l;
        }
        self.tip = p;
        self.tip_vel = pv;
    }

    /// The loads pass (see the module documentation), after [`ChainState::kinematics`]. Errors if
    /// a joint has folded back on itself.
    #[inline(always)]
    pub fn loads<S: Surroundings + ?Sized>(
        &mut self,
        time: f64,
        c: &LoadConstants,
        surroundings: &S,
    ) -> Result<S::TipReport> {
        let n = self.n;
        let g_eff = V3::new(0.0, 0.0, c.gravity) - surroundings.frame_acceleration(time);
        let (tip_force, report) = surroundings.tip_loads(time, &self.tip, &self.tip_vel);
        self.tip_force = g_eff * c.tip_mass + tip_force;

        // Joints j = 1 .. n-1, between segments j-1 and j. The spring stores
        // U = -(2 EI / l) ln((1 + e_{j-1} . e_j) / 2); the damper's torque on segment j is
        // tau = -c_b (w_j - w_{j-1}), on segment j-1 the opposite; Q_(k,b) = E_kb . (tau_k x e_k).
        let mut folded = 0usize;
        {
            let (ex, ey, ez) = (&self.e.x[..n], &self.e.y[..n], &self.e.z[..n]);
            let (ox, oy, oz) = (&self.omega.x[..n], &self.omega.y[..n], &self.omega.z[..n]);
            let (tox, toy, toz) = self.to_outboard.slices(n);
            let (tix, tiy, tiz) = self.to_inboard.slices(n);
            for j in 1..n {
                let prev = V3::new(ex[j - 1], ey[j - 1], ez[j - 1]);
                let e = V3::new(ex[j], ey[j], ez[j]);
                let one_plus_cos = 1.0 + dot(&prev, &e);
                folded += usize::from(!(FOLDED_JOINT..f64::INFINITY).contains(&one_plus_cos));
                let coef = c.bend_gain / one_plus_cos;
                let tau = V3::new(ox[j] - ox[j - 1], oy[j] - oy[j - 1], oz[j] - oz[j - 1]) * c.c_b;
                let out = axpy(&prev, coef, &(-cross(&tau, &e)));
                let inb = axpy(&e, coef, &cross(&tau, &prev));
                (tox[j], toy[j], toz[j]) = (out.x, out.y, out.z);
                (tix[j], tiy[j], tiz[j]) = (inb.x, inb.y, inb.z);
            }
        }
        if folded > 0 {
            let j = (1..n)
                .find(|&j| {
                    let v = 1.0 + self.e.get(j - 1).dot(&self.e.get(j));
                    !(FOLDED_JOINT..f64::INFINITY).contains(&v)
                })
                .unwrap_or(1);
            return Err(TetherError::Diverged {
                time,
                reason: format!(
                    "joint {j} between segments {j} and {} folded back on itself",
                    j + 1
                ),
            });
        }

        // Segments: external force on the centre and the vector X.
        let (fx, fy, fz) = self.force.slices(n);
        let (xx, xy, xz) = self.extra.slices(n);
        let (rx, ry, rz) = self.reduced.slices(n);
        segment_loads::<S>(
            time,
            c,
            surroundings,
            g_eff * c.m,
            &self.e.x[..n],
            &self.e.y[..n],
            &self.e.z[..n],
            &self.com.x[..n],
            &self.com.y[..n],
            &self.com.z[..n],
            &self.com_vel.x[..n],
            &self.com_vel.y[..n],
            &self.com_vel.z[..n],
            &self.w.x[..n],
            &self.w.y[..n],
            &self.w.z[..n],
            &self.to_outboard.x[..n + 1],
            &self.to_outboard.y[..n + 1],
            &self.to_outboard.z[..n + 1],
            &self.to_inboard.x[..n + 1],
            &self.to_inboard.y[..n + 1],
            &self.to_inboard.z[..n + 1],
            fx,
            fy,
            fz,
            xx,
            xy,
            xz,
            rx,
            ry,
            rz,
        )?;
        Ok(report)
    }
}

/// Per segment: direction, partials, rate, convective acceleration and angular velocity from the
/// sines and cosines of its angles and their rates (`rates` interleaved). Returns how many segments
/// are at the coordinate singularity. The slices are separate arguments so that the compiler knows
/// they do not overlap and vectorizes the loop.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn directions_and_rates(
    sf: &[f64],
    cf: &[f64],
    sp: &[f64],
    cps: &[f64],
    rates: &[f64],
    ex: &mut [f64],
    ey: &mut [f64],
    ez: &mut [f64],
    epx: &mut [f64],
    epz: &mut [f64],
    esx: &mut [f64],
    esy: &mut [f64],
    esz: &mut [f64],
    edx: &mut [f64],
    edy: &mut [f64],
    edz: &mut [f64],
    wx: &mut [f64],
    wy: &mut [f64],
    wz: &mut [f64],
    ox: &mut [f64],
    oy: &mut [f64],
    oz: &mut [f64],
) -> usize {
    let n = sf.len();
    let (cf, sp, cps, rates) = (&cf[..n], &sp[..n], &cps[..n], &rates[..2 * n]);
    let (ex, ey, ez, epx, epz) = (
        &mut ex[..n],
        &mut ey[..n],
        &mut ez[..n],
        &mut epx[..n],
        &mut epz[..n],
    );
    let (esx, esy, esz) = (&mut esx[..n], &mut esy[..n], &mut esz[..n]);
    let (edx, edy, edz) = (&mut edx[..n], &mut edy[..n], &mut edz[..n]);
    let (wx, wy, wz) = (&mut wx[..n], &mut wy[..n], &mut wz[..n]);
    let (ox, oy, oz) = (&mut ox[..n], &mut oy[..n], &mut oz[..n]);
    let mut singular = 0usize;
    for k in 0..n {
        let (sf, cf, sp, cp) = (sf[k], cf[k], sp[k], cps[k]);
        singular += usize::from(!(SINGULAR_COS_PSI..=f64::INFINITY).contains(&cp.abs()));
        // See DirectionJet: d2e/dphi2 = cp (cf, 0, -sf), d2e/dphidpsi = -sp (sf, 0, cf),
        // d2e/dpsi2 = -e.
        let e = V3::new(-cp * cf, sp, cp * sf);
        let e_phi = V3::new(cp * sf, 0.0, cp * cf);
        let e_psi = V3::new(sp * cf, cp, -sp * sf);
        let (phi_d, psi_d) = (rates[2 * k], rates[2 * k + 1]);
        let e_dot = axpy(&e_psi, psi_d, &(e_phi * phi_d));
        let (pp, ps2, ss) = (phi_d * phi_d, 2.0 * phi_d * psi_d, psi_d * psi_d);
        let w = V3::new(
            madd(e_phi.z, pp, e_psi.z * ps2),
            0.0,
            -madd(e_phi.x, pp, e_psi.x * ps2),
        );
        let w = axpy(&e, -ss, &w);
        let omega = cross(&e, &e_dot);
        (ex[k], ey[k], ez[k]) = (e.x, e.y, e.z);
        (epx[k], epz[k]) = (e_phi.x, e_phi.z);
        (esx[k], esy[k], esz[k]) = (e_psi.x, e_psi.y, e_psi.z);
        (edx[k], edy[k], edz[k]) = (e_dot.x, e_dot.y, e_dot.z);
        (wx[k], wy[k], wz[k]) = (w.x, w.y, w.z);
        (ox[k], oy[k], oz[k]) = (omega.x, omega.y, omega.z);
    }
    singular
}

/// Per segment: the external force on the centre and the vector X (see [`ChainState::loads`]),
/// from the joints' contributions `to_out[j]` (to segment j) and `to_in[j]` (to segment j-1),
/// entries 0 and n zero. Separate slices for the vectorizer, as [`directions_and_rates`].
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn segment_loads<S: Surroundings + ?Sized>(
    time: f64,
    c: &LoadConstants,
    surroundings: &S,
    weight: V3,
    ex: &[f64],
    ey: &[f64],
    ez: &[f64],
    cx: &[f64],
    cy: &[f64],
    cz: &[f64],
    vx: &[f64],
    vy: &[f64],
    vz: &[f64],
    wx: &[f64],
    wy: &[f64],
    wz: &[f64],
    tox: &[f64],
    toy: &[f64],
    toz: &[f64],
    tix: &[f64],
    tiy: &[f64],
    tiz: &[f64],
    fx: &mut [f64],
    fy: &mut [f64],
    fz: &mut [f64],
    xx: &mut [f64],
    xy: &mut [f64],
    xz: &mut [f64],
    rx: &mut [f64],
    ry: &mut [f64],
    rz: &mut [f64],
) -> Result<()> {
    let n = ex.len();
    let (ey, ez, cx, cy, cz) = (&ey[..n], &ez[..n], &cx[..n], &cy[..n], &cz[..n]);
    let (vx, vy, vz, wx, wy, wz) = (&vx[..n], &vy[..n], &vz[..n], &wx[..n], &wy[..n], &wz[..n]);
    let (tox, toy, toz) = (&tox[..n + 1], &toy[..n + 1], &toz[..n + 1]);
    let (tix, tiy, tiz) = (&tix[..n + 1], &tiy[..n + 1], &tiz[..n + 1]);
    let (fx, fy, fz) = (&mut fx[..n], &mut fy[..n], &mut fz[..n]);
    let (xx, xy, xz) = (&mut xx[..n], &mut xy[..n], &mut xz[..n]);
    let (rx, ry, rz) = (&mut rx[..n], &mut ry[..n], &mut rz[..n]);
    let (half_inv_l, inv_l2, m4) = (0.5 / c.l, 1.0 / (c.l * c.l), 0.25 * c.m);
    // The pass over the segments, for the held samples (vectorized) or for a field asked at
    // each centre; `$air(k, com)` is segment k's air. A macro, not a closure: the body must
    // inline into the target-feature caller.
    macro_rules! segments {
        ($air:expr) => {
            for k in 0..n {
                let e = V3::new(ex[k], ey[k], ez[k]);
                let com = V3::new(cx[k], cy[k], cz[k]);
                let rho = surroundings.air_density(time, &com);
                // x * 1.0 == x exactly: the default (relative) drag is bit for bit the plain difference.
                let rel = ($air)(k, &com) - V3::new(vx[k], vy[k], vz[k]) * c.segment_velocity_weight;
                let vt = dot(&rel, &e);
                let vn = axpy(&e, -vt, &rel);
                let vn_abs = dot(&vn, &vn).sqrt();
                let force = axpy(&e, rho * c.tangential_drag * vt * vt.abs(), &weight);
                let force = axpy(&vn, rho * c.normal_drag * vn_abs, &force);
                let joints = V3::new(
                    tox[k] + tix[k + 1],
                    toy[k] + tiy[k + 1],
                    toz[k] + tiz[k + 1],
                );
                let w = V3::new(wx[k], wy[k], wz[k]);
                let extra = axpy(&w, -c.rod_inertia, &joints);
                let r = axpy(&force, half_inv_l, &axpy(&extra, inv_l2, &(w * m4)));
                (fx[k], fy[k], fz[k]) = (force.x, force.y, force.z);
                (xx[k], xy[k], xz[k]) = (extra.x, extra.y, extra.z);
                (rx[k], ry[k], rz[k]) = (r.x, r.y, r.z);
            }
        };
    }
    match surroundings.held_segment_air(time) {
        Some((_, held)) if held.len() != n => {
            return Err(TetherError::WrongSize {
                what: "held segment air",
                expected: n,
                found: held.len(),
            })
        }
        Some((uniform, held)) => {
            let held = &held[..n]; // of length n (above): tells the compiler, no bounds checks
            segments!(|k: usize, _: &V3| uniform + held[k]);
        }
        None => segments!(|_: usize, com: &V3| surroundings.air_velocity(time, com)),
    }
    Ok(())
}
