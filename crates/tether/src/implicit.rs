//! The linearly implicit integrator of [`crate::Scheme::ImplicitAxial`]: the Rosenbrock-W method
//! ROS34PW2 (Rang & Angermann, "New Rosenbrock W-methods of order 3 for partial
//! differential algebraic equations of index 1", BIT 45, 2005), with the axial spring-dampers
//! in its matrix.
//!
//! # The method
//! For `y' = f(y)`, `y = (q, v, x)`, a Rosenbrock-W step of length h is
//!
//! ```text
//! (I - gamma h T) k_i = h f(Y_i) + h T sum_{j<i} gamma_ij k_j,   Y_i = y_0 + sum_{j<i} alpha_ij k_j,
//! y_1 = y_0 + sum_i b_i k_i,
//! ```
//!
//! of order 3 whatever the matrix `T` (a W-method), L-stable (its stability function vanishes
//! at infinity) and stiffly accurate (`y_1` is the last stage's value) where `T` is the
//! Jacobian. Here `T` is the Jacobian of the axial spring-dampers alone, with the mass matrix of
//! the stage, `M_i = M(q_i)`:
//!
//! ```text
//! T = [[0, P^T P], [-M_i^-1 K, -M_i^-1 C]]   on (q, v);   zero on the first-order states x,
//! ```
//!
//! `K = k P^T P` and `C = c P^T P` with `P` picking the stretch coordinates and `(k, c)` one
//! element's stiffness and damping. The kinematic coupling `q' = v` is in `T` for the
//! stretches alone: with it on every coordinate, the swing and bending modes would see a
//! nilpotent `T = [[0, I], [0, 0]]` instead of zero, and the method's stability region for
//! them would no longer be the explicit one (an undamped zig-zag chain's energy then grows
//! at the 0.01 s step; `tests/integration/implicit_axial.rs`). The element's force `-k s - c s'` acts on its own
//! coordinate, so `K`, `C` are diagonal, and with `u = sum_{j<i} gamma_ij k_j` the stage
//! reduces to one solve with the mass matrix augmented on the stretch diagonal:
//!
//! ```text
//! (M_i + gamma h C + (gamma h)^2 K) k_v = h [Q(Y_i) - K (u_q + gamma h (v_i + u_v)) - C u_v]
//! k_q = h (v_i + u_v) + gamma h k_v  (stretches),   k_q = h v_i  (other coordinates),
//! k_x = h x'(Y_i)
//! ```
//!
//! i.e. the right-hand side of the stage with each element's spring evaluated at
//! `s~ = s_i + u_s + gamma h (s_i' + u_s')` and its damper at `s~' = s_i' + u_s'`, and
//! `gamma h c + (gamma h)^2 k` added to the stretch's diagonal entry of `M`: in the O(n)
//! recursion that is one entry of a segment's 3x3 block (the distributed elasticity) or of the
//! root's system (the attachment element) ([`crate::TetherModel::accelerations_axial`]), as
//! implicit integrators of joint springs and dampers add them to the joint inertia. Each stage
//! costs one right-hand side, as an RK4 stage does.
//!
//! # What it does to the modes
//! * The axial modes (`omega^2 ~ k / M_a`, rates `~ c / M_a`) enter through `T` exactly (the
//!   spring's generalized force is linear in the stretch; only `M(q)` varies, and it is taken
//!   at each stage): a stiff element is damped by the L-stable stability function, its stretch
//!   settling on the quasi-static `s = T / k` instead of ringing at a frequency the step cannot
//!   resolve. A resolved axial mode keeps order 3 and loses energy at the rate of the stability
//!   function's `|R(z)| < 1` (measured in `tests/integration/implicit_axial.rs`).
//! * Every other mode (swing, bending, zig-zag, aerodynamics, the capturing device's
//!   attitude) sees `T = 0`: the method is then an explicit four-stage method of order 3,
//!   stable to 1.50 on the imaginary axis and 1.99 on the negative real axis
//!   ([`crate::config::ROSENBROCK_STABILITY_LIMIT`]), and substeps are chosen for these modes
//!   alone ([`crate::TetherConfig::fastest_rate`] without the axial terms).
//!
//! Non-autonomous terms (the surroundings' time dependence) are evaluated at the stage times
//! `t + c_i h`, with no `df/dt` correction: a W-method keeps its order with any `T`, including
//! the zero time column. Stage buffers are allocated once; a step allocates nothing.

use crate::axial::AxialStage;
use crate::error::{Result, TetherError};
use crate::integrator::{InSurroundings, System, STATE_BOUND};
use crate::surroundings::Surroundings;

/// ROS34PW2's diagonal `gamma`.
pub const GAMMA: f64 = 0.435_866_521_508_459;
/// `alpha_ij`, i > j (row i, stage i's point).
const ALPHA: [[f64; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [0.871_733_043_016_918, 0.0, 0.0],
    [0.844_570_600_153_694_2, -0.112_990_642_364_841_85, 0.0],
    [0.0, 0.0, 1.0],
];
/// `gamma_ij`, i > j.
const GAMMAS: [[f64; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [-0.871_733_043_016_918, 0.0, 0.0],
    [-0.903_380_570_130_440_8, 0.054_180_672_388_095_326, 0.0],
    [
        0.242_123_807_060_953_46,
        -1.223_250_583_904_514_7,
        0.545_260_255_335_102_1,
    ],
];
/// The weights `b_i` (equal to `alpha_4j + gamma_4j`, and `gamma` for the last: stiffly
/// accurate).
const WEIGHTS: [f64; 4] = [
    0.242_123_807_060_953_46,
    -1.223_250_583_904_514_7,
    1.545_260_255_335_102,
    GAMMA,
];

/// Stage times `c_i = sum_j alpha_ij`.
#[inline(always)]
fn stage_fraction(i: usize) -> f64 {
    ALPHA[i].iter().sum()
}

/// Where a stage's point and the springs' arguments go.
struct StagePoint<'a> {
    q: &'a mut [f64],
    qd: &'a mut [f64],
    uv: &'a mut [f64],
    stretch: &'a mut [f64],
    stretch_rate: &'a mut [f64],
}

/// Stage `i`'s point `Y_i = y_0 + sum_{j<i} alpha_ij k_j`, `u = sum_{j<i} gamma_ij k_j`, and the
/// springs' arguments `s~ = q_i + u_q + gamma h (v_i + u_v)`, `s~' = v_i + u_v` (for every
/// coordinate; the model reads the stretches), from the `I = i` earlier stages.
#[inline(always)]
fn stage_point<const I: usize>(
    i: usize,
    q: &[f64],
    qd: &[f64],
    kq: [&[f64]; I],
    kv: [&[f64]; I],
    out: StagePoint<'_>,
    gh: f64,
) {
    let n = q.len();
    let (a, g) = (&ALPHA[i], &GAMMAS[i]);
    let qd = &qd[..n];
    let kq: [&[f64]; I] = kq.map(|k| &k[..n]);
    let kv: [&[f64]; I] = kv.map(|k| &k[..n]);
    let (sq, sqd, uv) = (&mut out.q[..n], &mut out.qd[..n], &mut out.uv[..n]);
    let (stretch, rate) = (&mut out.stretch[..n], &mut out.stretch_rate[..n]);
    for r in 0..n {
        let (mut yq, mut yv, mut uq, mut u) = (q[r], qd[r], 0.0, 0.0);
        for j in 0..I {
            yq += a[j] * kq[j][r];
            yv += a[j] * kv[j][r];
            uq += g[j] * kq[j][r];
            u += g[j] * kv[j][r];
        }
        sq[r] = yq;
        sqd[r] = yv;
        uv[r] = u;
        rate[r] = yv + u;
        stretch[r] = yq + uq + gh * (yv + u);
    }
}

/// A [`System`] whose second-order coordinates include axial spring-dampers the Rosenbrock
/// step treats implicitly: it solves a stage with them ([`AxialStage`]).
pub trait AxialSystem: System {
    /// Whether second-order coordinate `i` is an axial element's stretch: the coordinates whose
    /// kinematic coupling `q' = v` is in the Rosenbrock matrix with their spring-dampers.
    fn is_axial(&self, i: usize) -> bool;

    /// The stage's derivatives at `(time, q, q', x)`: `(M + gamma_h C + gamma_h^2 K)^-1` of the
    /// generalized forces with the springs and dampers at `stage`'s arguments into `qdd`
    /// ([`TetherModel::accelerations_axial`]), and `x'` into `xd` as
    /// [`System::derivatives`] gives it.
    #[allow(clippy::too_many_arguments)]
    fn derivatives_axial(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        x: &[f64],
        stage: &AxialStage<'_>,
        qdd: &mut [f64],
        xd: &mut [f64],
    ) -> Result<()>;
}

impl<S: Surroundings + ?Sized> AxialSystem for InSurroundings<'_, S> {
    fn is_axial(&self, i: usize) -> bool {
        self.model.is_stretch_coordinate(i)
    }

    fn derivatives_axial(
        &mut self,
        time: f64,
        q: &[f64],
        qd: &[f64],
        _x: &[f64],
        stage: &AxialStage<'_>,
        qdd: &mut [f64],
        _xd: &mut [f64],
    ) -> Result<()> {
        self.model
            .accelerations_axial(time, q, qd, stage, self.surroundings, qdd)
            .map(|_| ())
    }
}

/// The stage increments `k_i = (k_q, k_v, k_x)` and work vectors of [`Rosenbrock`].
#[derive(Debug, Clone)]
pub struct Rosenbrock {
    kq: [Vec<f64>; 4],
    kv: [Vec<f64>; 4],
    kx: [Vec<f64>; 4],
    /// The stage point.
    q: Vec<f64>,
    qd: Vec<f64>,
    x: Vec<f64>,
    /// The springs' and dampers' arguments of the stage.
    stretch: Vec<f64>,
    stretch_rate: Vec<f64>,
    /// `u_v = sum_{j<i} gamma_ij k_v,j`.
    uv: Vec<f64>,
    /// Which coordinates are stretches ([`AxialSystem::is_axial`]), set by
    /// [`Rosenbrock::advance`].
    axial: Vec<bool>,
    /// The state at the start of [`Rosenbrock::advance`].
    start_q: Vec<f64>,
    start_qd: Vec<f64>,
    start_x: Vec<f64>,
}

impl Rosenbrock {
    /// Buffers for `dofs` second-order coordinates and `first_order` first-order states.
    pub fn new(dofs: usize, first_order: usize) -> Self {
        let z = || vec![0.0; dofs];
        let x = || vec![0.0; first_order];
        Rosenbrock {
            kq: [z(), z(), z(), z()],
            kv: [z(), z(), z(), z()],
            kx: [x(), x(), x(), x()],
            q: z(),
            qd: z(),
            x: x(),
            stretch: z(),
            stretch_rate: z(),
            uv: z(),
            axial: vec![false; dofs],
            start_q: z(),
            start_qd: z(),
            start_x: x(),
        }
    }

    /// Buffers sized for `system`.
    pub fn for_system<Y: System + ?Sized>(system: &Y) -> Self {
        Rosenbrock::new(system.dofs(), system.first_order_states())
    }

    /// Advances `(q, qd, x)` from `time` by `dt` in `substeps` equal ROS34PW2 steps (at least
    /// one), checking after each that no value is NaN or beyond [`STATE_BOUND`] and projecting
    /// x ([`System::project`]). On error `(q, qd, x)` are left unchanged. Allocates nothing.
    #[allow(clippy::too_many_arguments)]
    pub fn advance<Y: AxialSystem + ?Sized>(
        &mut self,
        system: &mut Y,
        time: f64,
        dt: f64,
        substeps: usize,
        q: &mut [f64],
        qd: &mut [f64],
        x: &mut [f64],
    ) -> Result<()> {
        self.check_sizes(system, q, qd, x)?;
        let substeps = substeps.max(1);
        let h = dt / substeps as f64;
        for (i, axial) in self.axial.iter_mut().enumerate() {
            *axial = system.is_axial(i);
        }
        // The start, restored if a substep fails.
        self.start_q.copy_from_slice(q);
        self.start_qd.copy_from_slice(qd);
        self.start_x.copy_from_slice(x);
        for j in 0..substeps {
            let t = time + j as f64 * h;
            if let Err(e) = self.step(system, t, h, q, qd, x) {
                q.copy_from_slice(&self.start_q);
                qd.copy_from_slice(&self.start_qd);
                x.copy_from_slice(&self.start_x);
                return Err(e);
            }
        }
        Ok(())
    }

    fn check_sizes<Y: System + ?Sized>(
        &self,
        system: &Y,
        q: &[f64],
        qd: &[f64],
        x: &[f64],
    ) -> Result<()> {
        crate::integrator::check_state_sizes(system, q, qd, x, self.q.len(), self.x.len())
    }

    /// One ROS34PW2 step of length `h` from `(q, qd, x)` at `t`, written back into them (the
    /// start is lost on error; [`Rosenbrock::advance`] keeps it).
    fn step<Y: AxialSystem + ?Sized>(
        &mut self,
        system: &mut Y,
        t: f64,
        h: f64,
        q: &mut [f64],
        qd: &mut [f64],
        x: &mut [f64],
    ) -> Result<()> {
        let gh = GAMMA * h;
        let dim = q.len();
        for i in 0..4 {
            // The stage point Y_i and u = sum_{j<i} gamma_ij k_j; the springs' arguments
            // s~ = q_i + u_q + gamma h (v_i + u_v), s~' = v_i + u_v (computed for every
            // coordinate, read at the stretches).
            {
                let Rosenbrock {
                    kq,
                    kv,
                    kx,
                    q: sq,
                    qd: sqd,
                    x: sx,
                    stretch,
                    stretch_rate,
                    uv,
                    ..
                } = self;
                let out = StagePoint {
                    q: sq,
                    qd: sqd,
                    uv,
                    stretch,
                    stretch_rate,
                };
                match i {
                    0 => stage_point::<0>(i, q, qd, [], [], out, gh),
                    1 => stage_point::<1>(i, q, qd, [&kq[0]], [&kv[0]], out, gh),
                    2 => stage_point::<2>(i, q, qd, [&kq[0], &kq[1]], [&kv[0], &kv[1]], out, gh),
                    _ => stage_point::<3>(
                        i,
                        q,
                        qd,
                        [&kq[0], &kq[1], &kq[2]],
                        [&kv[0], &kv[1], &kv[2]],
                        out,
                        gh,
                    ),
                }
                let (a, _) = (&ALPHA[i], &GAMMAS[i]);
                for r in 0..sx.len() {
                    let mut y = x[r];
                    for j in 0..i {
                        y += a[j] * kx[j][r];
                    }
                    sx[r] = y;
                }
            }
            let time = t + stage_fraction(i) * h;
            let stage = AxialStage {
                stretch: &self.stretch,
                stretch_rate: &self.stretch_rate,
                gamma_h: gh,
            };
            // k_v = h (augmented solve), k_x = h x'; k_q = h (v_i + u_v) + gamma h k_v at the
            // stretches, h v_i elsewhere (T's q' = v block is on the stretches alone).
            system.derivatives_axial(
                time,
                &self.q,
                &self.qd,
                &self.x,
                &stage,
                &mut self.kv[i],
                &mut self.kx[i],
            )?;
            let (kq, kv) = (&mut self.kq[i][..dim], &mut self.kv[i][..dim]);
            let (uv, sqd, axial) = (&self.uv[..dim], &self.qd[..dim], &self.axial[..dim]);
            for r in 0..dim {
                kv[r] *= h;
                kq[r] = if axial[r] {
                    h * (sqd[r] + uv[r]) + gh * kv[r]
                } else {
                    h * sqd[r]
                };
            }
            for v in self.kx[i].iter_mut() {
                *v *= h;
            }
        }
        let (q, qd) = (&mut q[..dim], &mut qd[..dim]);
        let kq: [&[f64]; 4] = std::array::from_fn(|i| &self.kq[i][..dim]);
        let kv: [&[f64]; 4] = std::array::from_fn(|i| &self.kv[i][..dim]);
        for r in 0..dim {
            let (mut yq, mut yv) = (q[r], qd[r]);
            for (i, b) in WEIGHTS.iter().enumerate() {
                yq += b * kq[i][r];
                yv += b * kv[i][r];
            }
            q[r] = yq;
            qd[r] = yv;
        }
        for (r, x) in x.iter_mut().enumerate() {
            let mut y = *x;
            for (i, b) in WEIGHTS.iter().enumerate() {
                y += b * self.kx[i][r];
            }
            *x = y;
        }
        let end = t + h;
        for (what, v) in [("q", &*q), ("qd", &*qd), ("x", &*x)] {
            if let Some((i, value)) = v
                .iter()
                .copied()
                .enumerate()
                .find(|(_, v)| v.is_nan() || v.abs() > STATE_BOUND)
            {
                return Err(TetherError::Diverged {
                    time: end,
                    reason: format!(
                        "{what}[{i}] = {value:e} is non-finite or beyond {STATE_BOUND:e}"
                    ),
                });
            }
        }
        system.project(end, x)
    }
}
