//! The one integrator: classical fixed-step fourth-order Runge-Kutta for a [`System`] of
//! second-order coordinates q and first-order states x,
//!
//! ```text
//! q'' = a(t, q, q', x),    x' = f(t, q, q', x),
//! ```
//!
//! used by the tether alone ([`crate::Tether`], x empty) and by the capture simulation (x the
//! capturing device's attitude quaternion and body rates) alike. One step of length dt may be
//! split into equal substeps (for the chain's fastest mode, [`crate::TetherConfig::substeps_for`]):
//! substep j starts at `t + j dt / k`. The stepper never keeps time: callers hold the clock
//! (`origin + steps dt`, free of the drift of summing dt). Stage buffers are allocated once.

use crate::dynamics::TetherModel;
use crate::error::{Result, TetherError};
use crate::surroundings::Surroundings;

/// The largest magnitude a coordinate (m, rad), rate (m/s, rad/s) or first-order state may reach:
/// beyond it a state is a divergence, even where it is still finite (a state of 1e63 gives
/// infinite energies).
pub const STATE_BOUND: f64 = 1e6;

/// A system the integrator advances: second-order coordinates q with rates q', and first-order
/// states x.
pub trait System {
    /// Number of second-order coordinates (the length of q, q' and q'').
    fn dofs(&self) -> usize;

    /// Number of first-order states (the length of x); none by default.
    fn first_order_states(&self) -> usize {
        0
    }

    /// The derivatives at `(time, q, q', x)`: q'' into `qdd` and x' into `xd`.
    fn derivatives(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        x: &[f64],
        qdd: &mut [f64],
        xd: &mut [f64],
    ) -> Result<()>;

    /// Maps the first-order states at the end of a (sub)step back onto their manifold (e.g.
    /// renormalises a quaternion); errors if that is impossible. Nothing by default.
    fn project(&self, _time: f64, _x: &mut [f64]) -> Result<()> {
        Ok(())
    }
}

/// The tether model in its surroundings, as a [`System`] without first-order states.
pub struct InSurroundings<'a, S: Surroundings + ?Sized> {
    /// The equations of motion.
    pub model: &'a mut TetherModel,
    /// What the tether meets: air, frame acceleration, tip force.
    pub surroundings: &'a S,
}

impl<S: Surroundings + ?Sized> System for InSurroundings<'_, S> {
    fn dofs(&self) -> usize {
        self.model.dofs()
    }

    fn derivatives(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        _x: &[f64],
        qdd: &mut [f64],
        _xd: &mut [f64],
    ) -> Result<()> {
        self.model
            .accelerations(time, q, qd, self.surroundings, qdd)
            .map(|_| ())
    }
}

/// Whether any entry is NaN or beyond `bound` in magnitude (for positive `bound`, the bits of
/// `|x|` compare as the values do; NaN and infinity compare above every finite bound).
#[inline]
fn any_beyond(v: &[f64], bound: f64) -> bool {
    const MAGNITUDE: u64 = 0x7FFF_FFFF_FFFF_FFFF;
    let limit = bound.to_bits();
    let mut any = 0u64;
    for x in v {
        any |= u64::from(x.to_bits() & MAGNITUDE > limit);
    }
    any != 0
}

/// One RK4 stage's state: `q = q0 + h rate`, `qd = qd0 + h acc` (slices of one length; the
/// equal lengths let the compiler drop the bounds checks).
#[inline(always)]
fn stage_state(
    q: &mut [f64],
    qd: &mut [f64],
    q0: &[f64],
    qd0: &[f64],
    rate: &[f64],
    acc: &[f64],
    h: f64,
) {
    let n = q.len();
    let (qd, q0, qd0, rate, acc) = (&mut qd[..n], &q0[..n], &qd0[..n], &rate[..n], &acc[..n]);
    for i in 0..n {
        q[i] = q0[i] + h * rate[i];
        qd[i] = qd0[i] + h * acc[i];
    }
}

/// A first-order stage state `x = x0 + h rate`.
#[inline(always)]
fn stage_first_order(x: &mut [f64], x0: &[f64], rate: &[f64], h: f64) {
    let n = x.len();
    let (x0, rate) = (&x0[..n], &rate[..n]);
    for i in 0..n {
        x[i] = x0[i] + h * rate[i];
    }
}

/// RK4's combination `out = x0 + sixth (k1 + 2 (k2 + k3) + k4)`.
#[inline(always)]
fn combine(
    out: &mut [f64],
    x0: &[f64],
    k1: &[f64],
    k2: &[f64],
    k3: &[f64],
    k4: &[f64],
    sixth: f64,
) {
    let n = out.len();
    let (x0, k1, k2, k3, k4) = (&x0[..n], &k1[..n], &k2[..n], &k3[..n], &k4[..n]);
    for i in 0..n {
        out[i] = x0[i] + sixth * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
    }
}

/// A state (q, q', x) the stepper writes: the end of a substep.
#[derive(Debug, Clone)]
struct Slot {
    q: Vec<f64>,
    qd: Vec<f64>,
    x: Vec<f64>,
}

impl Slot {
    fn new(dofs: usize, first_order: usize) -> Self {
        Slot {
            q: vec![0.0; dofs],
            qd: vec![0.0; dofs],
            x: vec![0.0; first_order],
        }
    }
}

/// RK4 stage buffers for one system size.
#[derive(Debug, Clone)]
pub struct Rk4 {
    /// The stage state's coordinates (the stage rates are in `qd_k`).
    q_stage: Vec<f64>,
    qd_k: [Vec<f64>; 3],
    a_k: [Vec<f64>; 4],
    x_stage: Vec<f64>,
    xd_k: [Vec<f64>; 4],
    /// Two end-of-substep states, written alternately so the input is never overwritten.
    slots: [Slot; 2],
}

impl Rk4 {
    /// Buffers for `dofs` second-order coordinates and `first_order` first-order states.
    pub fn new(dofs: usize, first_order: usize) -> Self {
        let z = || vec![0.0; dofs];
        let x = || vec![0.0; first_order];
        Rk4 {
            q_stage: z(),
            qd_k: [z(), z(), z()],
            a_k: [z(), z(), z(), z()],
            x_stage: x(),
            xd_k: [x(), x(), x(), x()],
            slots: [Slot::new(dofs, first_order), Slot::new(dofs, first_order)],
        }
    }

    /// Buffers sized for `system`.
    pub fn for_system<Y: System + ?Sized>(system: &Y) -> Self {
        Rk4::new(system.dofs(), system.first_order_states())
    }

    /// Advances `(q, qd, x)` from `time` by `dt` in `substeps` equal RK4 steps (at least one),
    /// checking after each that no value is NaN or beyond [`STATE_BOUND`] and projecting x
    /// ([`System::project`]). On error `(q, qd, x)` are left unchanged. Allocates nothing.
    #[allow(clippy::too_many_arguments)]
    pub fn advance<Y: System + ?Sized>(
        &mut self,
        system: &mut Y,
        time: f64,
        dt: f64,
        substeps: usize,
        q: &mut Vec<f64>,
        qd: &mut Vec<f64>,
        x: &mut [f64],
    ) -> Result<()> {
        self.advance_choosing(system, time, dt, q, qd, x, false, |_, _, _| Ok(substeps))
            .map(|_| ())
    }

    /// [`Rk4::advance`] with the number of substeps chosen from the state: the first stage's
    /// derivatives at `(time, q, qd, x)` do not depend on the step length, so they are evaluated
    /// first, then `substeps(system, q, qd)` (which may read what that evaluation left in the
    /// system, e.g. [`TetherModel::axial_mass`]) gives the substeps or an error, and the step
    /// goes on from that stage. The result is bitwise that of [`Rk4::advance`] with the same
    /// number. Returns the substeps taken. Allocates nothing.
    #[allow(clippy::too_many_arguments)]
    pub fn advance_adaptive<Y, F>(
        &mut self,
        system: &mut Y,
        time: f64,
        dt: f64,
        q: &mut Vec<f64>,
        qd: &mut Vec<f64>,
        x: &mut [f64],
        substeps: F,
    ) -> Result<usize>
    where
        Y: System + ?Sized,
        F: FnOnce(&Y, &[f64], &[f64]) -> Result<usize>,
    {
        self.advance_choosing(system, time, dt, q, qd, x, true, substeps)
    }

    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn advance_choosing<Y, F>(
        &mut self,
        system: &mut Y,
        time: f64,
        dt: f64,
        q: &mut Vec<f64>,
        qd: &mut Vec<f64>,
        x: &mut [f64],
        evaluate_first: bool,
        substeps: F,
    ) -> Result<usize>
    where
        Y: System + ?Sized,
        F: FnOnce(&Y, &[f64], &[f64]) -> Result<usize>,
    {
        self.check_sizes(system, q, qd, x)?;
        if evaluate_first {
            system.derivatives(time, q, qd, x, &mut self.a_k[0], &mut self.xd_k[0])?;
        }
        let substeps = substeps(system, q, qd)?.max(1);
        self.run_substeps(system, time, dt, substeps, q, qd, x, evaluate_first)?;
        Ok(substeps)
    }

    /// The sizes [`Rk4::advance`] checks: the state's and these buffers' against the system's.
    fn check_sizes<Y: System + ?Sized>(
        &self,
        system: &Y,
        q: &[f64],
        qd: &[f64],
        x: &[f64],
    ) -> Result<()> {
        check_state_sizes(system, q, qd, x, self.q_stage.len(), self.x_stage.len())
    }

    /// `substeps` RK4 steps of `dt / substeps` from `(q, qd, x)` at `time`, the result written
    /// back into them; with `evaluated` the first stage's derivatives are already in place.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn run_substeps<Y: System + ?Sized>(
        &mut self,
        system: &mut Y,
        time: f64,
        dt: f64,
        substeps: usize,
        q: &mut Vec<f64>,
        qd: &mut Vec<f64>,
        x: &mut [f64],
        evaluated: bool,
    ) -> Result<()> {
        let h = dt / substeps as f64;
        let (mut stages, first_slot, second_slot) = self.parts();
        stages.step(system, time, h, q, qd, x, first_slot, evaluated)?;
        let (mut done, mut spare) = (first_slot, second_slot);
        for j in 1..substeps {
            let t = time + j as f64 * h;
            stages.step(system, t, h, &done.q, &done.qd, &done.x, spare, false)?;
            std::mem::swap(&mut done, &mut spare);
        }
        // The new state is in `done`; the old vectors become its buffers.
        std::mem::swap(q, &mut done.q);
        std::mem::swap(qd, &mut done.qd);
        x.copy_from_slice(&done.x);
        Ok(())
    }

    /// The stage buffers and the two end-of-substep slots, borrowed apart.
    fn parts(&mut self) -> (Stages<'_>, &mut Slot, &mut Slot) {
        let [first_slot, second_slot] = &mut self.slots;
        let stages = Stages {
            q_stage: &mut self.q_stage,
            qd_k: &mut self.qd_k,
            a_k: &mut self.a_k,
            x_stage: &mut self.x_stage,
            xd_k: &mut self.xd_k,
        };
        (stages, first_slot, second_slot)
    }
}

/// The stage buffers, borrowed apart from the end-of-substep slots.
struct Stages<'a> {
    q_stage: &'a mut [f64],
    qd_k: &'a mut [Vec<f64>; 3],
    a_k: &'a mut [Vec<f64>; 4],
    x_stage: &'a mut [f64],
    xd_k: &'a mut [Vec<f64>; 4],
}

impl<'a> Stages<'a> {
    /// The time of RK4 stage `stage` (0 to 3) of a step of length `dt` from `t`.
    #[inline(always)]
    fn stage_time(t: f64, stage: usize, dt: f64) -> f64 {
        match stage {
            0 => t,
            1 | 2 => t + 0.5 * dt,
            _ => t + dt,
        }
    }

    /// The state of stage `stage` (1 to 3) of a step of length `dt` from `(q0, qd0, x0)`, from
    /// the previous stage's derivatives: into `q_stage`, `qd_k[stage - 1]`, `x_stage`.
    #[inline(always)]
    fn set_input(&mut self, stage: usize, q0: &[f64], qd0: &[f64], x0: &[f64], dt: f64) {
        let h = if stage == 3 { dt } else { 0.5 * dt };
        let (q, qd_k, a_k) = (&mut *self.q_stage, &mut *self.qd_k, &*self.a_k);
        let [k0, k1, k2] = qd_k;
        match stage {
            1 => stage_state(q, k0, q0, qd0, qd0, &a_k[0], h),
            2 => stage_state(q, k1, q0, qd0, k0, &a_k[1], h),
            _ => stage_state(q, k2, q0, qd0, k1, &a_k[2], h),
        }
        stage_first_order(self.x_stage, x0, &self.xd_k[stage - 1], h);
    }

    /// The inputs `(q, q', x)` of stage `stage` (those of the step's start for stage 0) and
    /// where its derivatives go.
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    fn args(
        self,
        stage: usize,
        start: [&'a [f64]; 3],
    ) -> ([&'a [f64]; 3], &'a mut [f64], &'a mut [f64]) {
        let Stages {
            q_stage,
            qd_k,
            a_k,
            x_stage,
            xd_k,
        } = self;
        let inputs = if stage == 0 {
            start
        } else {
            [&*q_stage, &qd_k[stage - 1][..], &*x_stage]
        };
        (inputs, &mut a_k[stage][..], &mut xd_k[stage][..])
    }

    /// The same buffers, borrowed anew for a shorter time.
    #[inline(always)]
    fn reborrow(&mut self) -> Stages<'_> {
        Stages {
            q_stage: &mut *self.q_stage,
            qd_k: &mut *self.qd_k,
            a_k: &mut *self.a_k,
            x_stage: &mut *self.x_stage,
            xd_k: &mut *self.xd_k,
        }
    }

    /// RK4's combination of the four stages into `out`, its check for divergence and the
    /// projection of its first-order states.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn finish<Y: System + ?Sized>(
        &mut self,
        system: &Y,
        t: f64,
        dt: f64,
        q0: &[f64],
        qd0: &[f64],
        x0: &[f64],
        out: &mut Slot,
    ) -> Result<()> {
        let (qd_k, a_k, xd_k) = (&*self.qd_k, &*self.a_k, &*self.xd_k);
        let sixth = dt / 6.0;
        combine(&mut out.q, q0, qd0, &qd_k[0], &qd_k[1], &qd_k[2], sixth);
        combine(&mut out.qd, qd0, &a_k[0], &a_k[1], &a_k[2], &a_k[3], sixth);
        combine(
            &mut out.x, x0, &xd_k[0], &xd_k[1], &xd_k[2], &xd_k[3], sixth,
        );
        let end = t + dt;
        let parts = [("q", &out.q), ("qd", &out.qd), ("x", &out.x)];
        if let Some((what, v)) = parts.iter().find(|(_, v)| any_beyond(v, STATE_BOUND)) {
            let (i, value) = v
                .iter()
                .copied()
                .enumerate()
                .find(|(_, v)| v.is_nan() || v.abs() > STATE_BOUND)
                .unwrap_or((0, f64::NAN));
            return Err(TetherError::Diverged {
                time: end,
                reason: format!("{what}[{i}] = {value:e} is non-finite or beyond {STATE_BOUND:e}"),
            });
        }
        system.project(end, &mut out.x)
    }

    /// One RK4 step of length `dt` from `(q0, qd0, x0)` at `t` into `out`; with `evaluated` the
    /// first stage's derivatives at `(t, q0, qd0, x0)` are already in `a_k[0]`, `xd_k[0]`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn step<Y: System + ?Sized>(
        &mut self,
        system: &mut Y,
        t: f64,
        dt: f64,
        q0: &[f64],
        qd0: &[f64],
        x0: &[f64],
        out: &mut Slot,
        evaluated: bool,
    ) -> Result<()> {
        for stage in 0..4 {
            if stage > 0 {
                self.set_input(stage, q0, qd0, x0, dt);
            }
            if stage > 0 || !evaluated {
                let time = Self::stage_time(t, stage, dt);
                let ([q, qd, x], qdd, xd) = self.reborrow().args(stage, [q0, qd0, x0]);
                system.derivatives(time, q, qd, x, qdd, xd)?;
            }
        }
        self.finish(system, t, dt, q0, qd0, x0, out)
    }
}

/// The sizes an integrator checks before a step: the state's (`q`, `qd`, `x`) and its own
/// buffers' (`buffer_dofs`, `buffer_first_order` entries) against the system's.
pub(crate) fn check_state_sizes<Y: System + ?Sized>(
    system: &Y,
    q: &[f64],
    qd: &[f64],
    x: &[f64],
    buffer_dofs: usize,
    buffer_first_order: usize,
) -> Result<()> {
    let (dim, first) = (system.dofs(), system.first_order_states());
    let sizes = [
        ("q", q.len(), dim),
        ("qd", qd.len(), dim),
        ("x", x.len(), first),
        ("integrator buffers", buffer_dofs, dim),
        ("integrator first-order buffers", buffer_first_order, first),
    ];
    match sizes.iter().find(|(_, f, e)| f != e) {
        Some(&(what, found, expected)) => Err(TetherError::WrongSize {
            what,
            expected,
            found,
        }),
        None => Ok(()),
    }
}
