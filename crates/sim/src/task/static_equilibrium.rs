//! The open-loop equilibrium solved directly: the state `x*` at which one physics step with
//! neutral flaps, the mean wake and no turbulence changes nothing, `f(x*) = x*`, found by Newton's
//! method from a nearby equilibrium instead of settled in time.
//!
//! # Why
//! Randomized physics gives every episode its own equilibrium. Settling it in time costs
//! `initial.settle_time / tether.time_step` physics steps (4000 by default, about 300 agent
//! steps of CPU per reset), and even then the chain's slowest modes (a time constant of about
//! 7 s) leave it 0.01-0.4 m from rest. The static equilibrium is where that settling converges.
//!
//! # The problem solved
//! Without flaps, turbulence or a side wind the system is symmetric about the TA frame's x-z
//! plane, and so is its equilibrium: the lateral angles `psi_k`, the ACCD's roll and yaw and every
//! lateral rate are exactly zero (the time settle keeps them at zero to the bit). The unknowns are
//! the in-plane coordinates: the elongations and the angles `phi_k`, their rates, the ACCD's pitch
//! (about the guess's attitude) and pitch rate, `n = 2 (segments + elongations) + 2` of them (64
//! with 30 segments). The ACCD's roll is neutral (it hangs from a swivel at its centre of
//! gravity), which leaves the full problem singular; the plane removes that freedom.
//!
//! `g(x) = f(x) - x` (one physics step, the integrator's own, so that `x*` is exactly the settle's
//! limit) is zeroed by Newton's method with the Jacobian by forward differences once, at the
//! guess (`n` physics steps; the steps of [`crate::task::state_steps::state_step`]), then Broyden's
//! rank-one updates of its inverse, each step halved until `max |g|` decreases (the step of the
//! [`MAX_HALVINGS`]-th halving is taken whatever it gives).
//! It stops when `max |g|` is below [`TOLERANCE`] or the budget of [`MAX_STEPS`] physics steps is
//! spent, and the result is checked on the whole state (every coordinate, one more step):
//! accepted when `max |f(x) - x|` is below [`ACCEPT`]. Otherwise there is no solution (the caller
//! settles in time instead). Every operation is in a fixed order, so the same inputs give the
//! same bits.
//!
//! # The guess
//! The equilibrium of another configuration of the same system (the env's base configuration
//! for its randomized episodes): its in-plane coordinates, its elongations scaled by the ratio of
//! the axial stiffnesses (the same tension), at rest.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector, Quaternion, UnitQuaternion, Vector3};

use crate::error::Result;
use crate::physics::accd::AccdState;
use crate::physics::aero::AeroModel;
use crate::physics::capture::{CaptureSim, CaptureState, Snapshot};
use crate::physics::turbulence::AmbientTurbulence;
use crate::physics::wake::Wake;
use crate::rng::Seeds;
use crate::task::config::EnvConfig;
use crate::task::state_steps::{state_step, Component};
use crate::valid::Valid;
use accd_tether::TetherState;

type V3 = Vector3<f64>;

/// Newton stops when `max |f(x) - x|` over the in-plane state is below this (m, rad, m/s, rad/s
/// per physics step).
pub const TOLERANCE: f64 = 1e-12;

/// A solution is accepted when `max |f(x) - x|` over the whole state is below this: the
/// equilibrium is then within about 1e-7 m of rest (the 40 s time settle: 0.01-0.4 m).
pub const ACCEPT: f64 = 1e-9;

/// The physics steps the solve may spend (the Jacobian's included): 20 agent steps' worth at the
/// default 10 physics steps per agent step.
pub const MAX_STEPS: usize = 200;

/// Halvings of a Newton step at most.
pub const MAX_HALVINGS: usize = 10;

/// A solved equilibrium: the tether, the ACCD and the snapshot there, with what it cost.
pub(crate) struct Solved {
    pub tether: TetherState,
    pub accd: AccdState,
    pub snapshot: Snapshot,
    /// Physics steps spent.
    pub steps: usize,
}

/// The in-plane problem: one physics step of `config`'s system without turbulence from the
/// in-plane state `x`.
struct Plane {
    sim: CaptureSim,
    template: CaptureState,
    /// The state indices of `x` into `(q, qd)`: coordinates, then rates.
    coords: Vec<usize>,
    dofs: usize,
    attitude: UnitQuaternion<f64>,
    steps: usize,
}

impl Plane {
    fn dim(&self) -> usize {
        2 * self.coords.len() + 2
    }

    /// Sets the sim to the in-plane state `x` (everything else zero, time 0).
    fn set(&mut self, x: &[f64]) -> Result<()> {
        let m = self.coords.len();
        let mut s = self.template.clone();
        s.q.fill(0.0);
        s.qd.fill(0.0);
        for (j, &i) in self.coords.iter().enumerate() {
            s.q[i] = x[j];
            s.qd[i] = x[m + j];
        }
        let a = self.attitude * UnitQuaternion::from_scaled_axis(V3::new(0.0, x[2 * m], 0.0));
        let c = a.coords;
        s.attitude = [c[0], c[1], c[2], c[3]];
        s.omega = [0.0, x[2 * m + 1], 0.0];
        self.sim.apply_state(s)
    }

    /// `g(x) = f(x) - x` into `g`; false when the step fails (the state diverges).
    fn residual(&mut self, x: &[f64], g: &mut [f64]) -> bool {
        self.steps += 1;
        if self.set(x).is_err() || self.sim.step([0.0; 4]).is_err() {
            return false;
        }
        let m = self.coords.len();
        let t = self.sim.tether_state();
        for (j, &i) in self.coords.iter().enumerate() {
            g[j] = t.q[i] - x[j];
            g[m + j] = t.qd[i] - x[m + j];
        }
        let accd = self.sim.accd_state();
        let theta = (self.attitude.inverse() * accd.attitude).scaled_axis();
        g[2 * m] = theta.y - x[2 * m];
        g[2 * m + 1] = accd.omega.y - x[2 * m + 1];
        g.iter().all(|v| v.is_finite())
    }

    /// `max |f(x) - x|` over the whole state (lateral coordinates, roll and yaw included).
    fn full_residual(&mut self, x: &[f64]) -> Result<f64> {
        self.set(x)?;
        let before = self.sim.state();
        self.sim.step([0.0; 4])?;
        self.steps += 1;
        let after = self.sim.state();
        let mut r: f64 = 0.0;
        for (a, b) in after.q.iter().zip(&before.q) {
            r = r.max((a - b).abs());
        }
        for (a, b) in after.qd.iter().zip(&before.qd) {
            r = r.max((a - b).abs());
        }
        let quat =
            |a: [f64; 4]| UnitQuaternion::from_quaternion(Quaternion::new(a[3], a[0], a[1], a[2]));
        let (qa, qb) = (quat(before.attitude), quat(after.attitude));
        r = r.max(qa.angle_to(&qb));
        for k in 0..3 {
            r = r.max((after.omega[k] - before.omega[k]).abs());
        }
        Ok(if r.is_finite() { r } else { f64::INFINITY })
    }
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// Whether `eq`'s tether and ACCD lie in the x-z plane exactly (lateral angles, roll and yaw 0).
fn in_plane(tether: &TetherState, accd: &AccdState, segments: usize) -> bool {
    let (roll, _, yaw) = accd.attitude.euler_angles();
    roll == 0.0 && yaw == 0.0 && (0..segments).all(|k| tether.q[2 + 2 * k] == 0.0)
}

/// The open-loop equilibrium of `config` (neutral flaps, mean wake, no turbulence) solved from
/// the equilibrium `(tether, accd)` of `guess_config` (module docs), with `model`, the
/// aerodynamic model and mean wake of `config` when the caller has them built; `Ok(None)` when the solve
/// does not reach [`ACCEPT`] within [`MAX_STEPS`] physics steps or the guess is not in the
/// plane.
pub(crate) fn solve(
    config: &Valid<EnvConfig>,
    guess_config: &EnvConfig,
    tether: &TetherState,
    accd: &AccdState,
    model: Option<(Arc<AeroModel>, Wake)>,
) -> Result<Option<Solved>> {
    let mut capture = config.capture().into_inner();
    capture.turbulence.wake_turbulence = false;
    capture.turbulence.ambient = AmbientTurbulence::None;
    // Switching the turbulence off keeps every rule (as in the time settle).
    let capture = Valid::trusted(capture);
    // The turbulence changes neither the aerodynamic model nor the mean wake: the same
    // simulation as `CaptureSim::new` of `capture`.
    let sim = match model {
        Some((aero, wake)) => CaptureSim::with_model(&capture, Seeds::default(), aero, wake)?,
        None => CaptureSim::new(&capture, Seeds::default())?,
    };
    let segments = config.physics.tether.segments;
    let dofs = sim.tether_state().q.len();
    if tether.q.len() != dofs
        || guess_config.physics.tether.segments != segments
        || !in_plane(tether, accd, segments)
    {
        return Ok(None);
    }
    // q = [s, phi_1, psi_1, ..., phi_n, psi_n, s_2, ..., s_n]: all but the psi_k.
    let elongation = |i: usize| i == 0 || i > 2 * segments;
    let coords: Vec<usize> = (0..dofs).filter(|&i| elongation(i) || i % 2 == 1).collect();
    let m = coords.len();
    let stretch =
        guess_config.physics.tether.axial_stiffness / config.physics.tether.axial_stiffness;
    let mut x = vec![0.0; 2 * m + 2];
    for (j, &i) in coords.iter().enumerate() {
        x[j] = if elongation(i) {
            tether.q[i] * stretch
        } else {
            tether.q[i]
        };
    }
    let h: Vec<f64> = (0..x.len())
        .map(|j| {
            state_step(if j < m {
                if elongation(coords[j]) {
                    Component::Elongation
                } else {
                    Component::Angle
                }
            } else if j < 2 * m {
                if elongation(coords[j - m]) {
                    Component::ElongationRate
                } else {
                    Component::AngleRate
                }
            } else if j == 2 * m {
                Component::Attitude
            } else {
                Component::BodyRate
            })
        })
        .collect();
    let mut plane = Plane {
        template: sim.state(),
        sim,
        coords,
        dofs,
        attitude: accd.attitude,
        steps: 0,
    };
    let n = plane.dim();
    let mut g = vec![0.0; n];
    if !plane.residual(&x, &mut g) {
        return Ok(None);
    }
    let mut r = max_abs(&g);
    // The Jacobian of g by forward differences, column by column.
    let mut jac = DMatrix::zeros(n, n);
    let mut xp = x.clone();
    let mut gp = vec![0.0; n];
    for c in 0..n {
        xp[c] = x[c] + h[c];
        if !plane.residual(&xp, &mut gp) {
            return Ok(None);
        }
        xp[c] = x[c];
        for i in 0..n {
            jac[(i, c)] = (gp[i] - g[i]) / h[c];
        }
    }
    // Broyden's update of the inverse (Sherman-Morrison), O(n^2) per step.
    let Some(mut inv) = jac.try_inverse() else {
        return Ok(None);
    };
    let mut xt = vec![0.0; n];
    let mut gt = vec![0.0; n];
    while r > TOLERANCE && plane.steps < MAX_STEPS {
        let step = &inv * DVector::from_column_slice(&g);
        let mut lambda = 1.0;
        let mut halvings = 0;
        let rt = loop {
            for i in 0..n {
                xt[i] = x[i] - lambda * step[i];
            }
            if plane.residual(&xt, &mut gt) {
                let rt = max_abs(&gt);
                // The last halving is taken even without a decrease: the residual's components
                // have different units, and its maximum may grow on the way to the solution.
                if rt < r || halvings == MAX_HALVINGS {
                    break rt;
                }
            }
            halvings += 1;
            if halvings > MAX_HALVINGS || plane.steps >= MAX_STEPS {
                return Ok(None);
            }
            lambda *= 0.5;
        };
        // Broyden: J += (dg - J dx) dx^T / (dx^T dx), as H = J^-1:
        // H += (dx - H dg) (dx^T H) / (dx^T H dg).
        let dx = DVector::from_iterator(n, (0..n).map(|i| xt[i] - x[i]));
        let dg = DVector::from_iterator(n, (0..n).map(|i| gt[i] - g[i]));
        let h_dg = &inv * &dg;
        let denom = dx.dot(&h_dg);
        if denom == 0.0 || !denom.is_finite() {
            return Ok(None);
        }
        let row = dx.transpose() * &inv;
        inv.ger(1.0 / denom, &(&dx - &h_dg), &row.transpose(), 1.0);
        x.copy_from_slice(&xt);
        g.copy_from_slice(&gt);
        r = rt;
    }
    if plane.full_residual(&x)? > ACCEPT {
        return Ok(None);
    }
    plane.set(&x)?;
    let snapshot = plane.sim.snapshot()?;
    let mut tether = plane.sim.tether_state().clone();
    tether.time = 0.0;
    debug_assert_eq!(tether.q.len(), plane.dofs);
    Ok(Some(Solved {
        tether,
        accd: *plane.sim.accd_state(),
        snapshot,
        steps: plane.steps,
    }))
}
