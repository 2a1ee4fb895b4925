//! The capture dynamics linearized about the open-loop equilibrium: the discrete-time model of
//! one agent step that a classical controller (LQR, observers) is designed on.
//!
//! # The model
//! With `x` the plant state, `u` the four flap commands (the env's action: units of the flap
//! limit `accd.flap_limit_deg`, held over the step), `w` a wind bias at the ACCD (m/s, lateral
//! y and vertical z) and `y` the observation of [`crate::task::observation::OBSERVATION`] (each quantity
//! times its scale, *before* clipping):
//!
//! ```text
//! x_{k+1} - x* = A (x_k - x*) + B u_k + E w_k
//! y_k     - y* = C (x_k - x*)
//! ```
//!
//! about the trim `x*` (neutral flaps, mean wake, turbulence off, the wind bias zero) with its
//! observation `y*`. One step is `config.agent_step` of the nonlinear [`CaptureSim::step`]
//! (`agent_step / tether.time_step` physics steps) with the commands held, exactly as an
//! [`crate::Episode`] steps, at time 0 (a scripted aircraft profile is frozen at its start).
//!
//! # State (`n` segments; [`Linearization::state_names`])
//! | block | entries | unit |
//! |---|---|---|
//! | tether coordinates `q` | `s` (elongation), `phi_k`, `psi_k` for k = 1..n (and `s_k`, k = 2..n, when the elasticity is distributed) | m, rad |
//! | their rates `q'` | the same names with `_dot` | m/s, rad/s |
//! | attitude error `theta` | `att_x`, `att_y`, `att_z`: the rotation vector of `q*^-1 q` (body axes), so `q = q* exp(theta / 2)` | rad |
//! | body rates | `p`, `q`, `r` | rad/s |
//! | flap deflections | `flap_right`, `flap_left`, `flap_top`, `flap_bottom` (the actuators' state) | rad |
//!
//! The quaternion's fourth, dependent coordinate is gone (the error is a 3-vector), and the flap
//! commands are inputs, not states: the actuator's first-order lag starts every physics step
//! from the deflection and the command ([`crate::physics::accd::Actuators::advance`]). Nothing is
//! reduced: the model is exact to first order in the whole state; a design may reduce it.
//!
//! # The boom and the observation
//! The boom is not part of the plant: `C` is the observation's sensitivity with the boom tip
//! held fixed, so its rows `boom_rel_*` are minus the capture point's, and `y*` is computed with
//! the boom tip *at the trim capture point, at rest* (those six entries of `y*` are 0). With the
//! boom tip at `b` (velocity `b'`) the observation is `y* + C dx` plus `(b - p*, b')` times the
//! scales in those six rows, `p*` the trim capture point ([`Linearization::capture_point`]).
//! `time_left` does not depend on the state (its row of `C` is 0; its `y*` is 1, time 0).
//!
//! # The wind bias
//! `w` adds `(0, w_y, w_z)` to the air velocity within `l / 4` of the ACCD's trim position
//! (`l` the segment length: the ACCD alone, no segment centre is that close to the tip), for
//! the observer's disturbance model: a mean-wake error or slow turbulence at the ACCD.
//!
//! # Finite differences
//! Central differences, `(f(x + h e_i) - f(x - h e_i)) / (2 h)`, with the step `h` of each
//! component stated in [`Linearization::steps`] (see [`state_step`]): small enough that the
//! truncation error `O(h^2)` is far below the rounding error `O(eps |f| / h)` of the step.
//!
//! # The trim
//! [`Equilibrium::settle`] settles the system open loop for `initial.settle_time`; its residual
//! motion is then removed by Newton iterations on `f(x) - x = 0` (`f` the step with `u = 0`),
//! each solving with the pseudo-inverse of `A - I` (the roll angle is neutral: the ACCD hangs
//! from a swivel at its centre of gravity, so one singular value of `A - I` is about zero). The
//! residual `max |f(x*) - x*|` before and after is reported ([`Linearization::settle_residual`],
//! [`Linearization::trim_residual`]).

use std::sync::Arc;

use accd_tether::Atmosphere;
use nalgebra::{DMatrix, UnitQuaternion, Vector3};

use crate::config::CaptureConfig;
use crate::error::{Result, SimError};
use crate::physics::aero::AeroModel;
use crate::physics::air::{AirDisturbance, AirState};
use crate::physics::capture::{CaptureSim, CaptureState};
use crate::physics::turbulence::{AmbientTurbulence, Turbulence};
use crate::physics::wake::Wake;
use crate::physics::wake_field::WakeField;
use crate::rng::Seeds;
use crate::rotation;
use crate::state_format::StateError;
use crate::task::config::EnvConfig;
use crate::task::episode::Equilibrium;
use crate::task::observation::{ObservationInputs, ACT_DIM, OBSERVATION, OBS_DIM};
use crate::valid::Valid;

type V3 = Vector3<f64>;

/// Number of wind-bias components (lateral y, vertical z).
pub const WIND_DIM: usize = 2;

const NO_WIND: [f64; WIND_DIM] = [0.0; WIND_DIM];

/// Finite-difference step of a flap command, in units of the flap limit.
pub const INPUT_STEP: f64 = 1e-5;

/// Finite-difference step of the wind bias, m/s.
pub const WIND_STEP: f64 = 1e-4;

/// Newton iterations on the trim at most.
pub const MAX_NEWTON: usize = 4;

/// Newton stops when `max |f(x) - x|` is below this (in the state's units).
pub const TRIM_TOLERANCE: f64 = 1e-10;

/// Relative singular-value cut of the pseudo-inverse in the Newton step.
const PINV_CUT: f64 = 1e-9;

pub use crate::task::state_steps::{state_step, Component};

/// The linear model of a configuration (see the module docs).
#[derive(Debug, Clone)]
pub struct Linearization {
    /// Names of the state components, in order.
    pub state_names: Vec<String>,
    /// What each state component is.
    pub components: Vec<Component>,
    /// Finite-difference step of each state component, in its unit.
    pub steps: Vec<f64>,
    /// The trim state `x*` (its attitude-error entries are 0).
    pub trim: Vec<f64>,
    /// The trim attitude `q*` (body to TA frame).
    pub trim_attitude: UnitQuaternion<f64>,
    /// The observation at the trim `y*` (boom tip at the trim capture point, at rest; scaled,
    /// not clipped).
    pub trim_observation: [f64; OBS_DIM],
    /// The capture point at the trim, m (TA frame).
    pub capture_point: V3,
    /// The ACCD's centre of gravity at the trim, m (TA frame).
    pub position: V3,
    /// The open-loop equilibrium's position the observation's `accd_d*` refer to, m.
    pub equilibrium_position: V3,
    /// `max |f(x) - x|` at the settled equilibrium, before the Newton iterations.
    pub settle_residual: f64,
    /// `max |f(x*) - x*|` at the trim.
    pub trim_residual: f64,
    /// Newton iterations done.
    pub newton_iterations: usize,
    /// `A` (state x state).
    pub a: DMatrix<f64>,
    /// `B` (state x 4), per unit of flap command (the action).
    pub b: DMatrix<f64>,
    /// `E` (state x 2), per m/s of wind bias (y, z).
    pub e: DMatrix<f64>,
    /// `C` (25 x state).
    pub c: DMatrix<f64>,
    /// The step of the model, s (`agent_step`).
    pub dt: f64,
}

/// A wind bias within a sphere: the mean wake (no turbulence) plus `bias` within `radius` of
/// `centre`.
#[derive(Clone)]
struct Biased {
    field: WakeField,
    bias: V3,
    centre: V3,
    radius: f64,
}

impl AirDisturbance for Biased {
    fn velocity(&self, time: f64, position: &V3) -> V3 {
        let v = self.field.velocity(time, position);
        if (position - self.centre).norm() <= self.radius {
            v + self.bias
        } else {
            v
        }
    }
    fn advance(&mut self, time: f64, dt: f64) -> Result<()> {
        AirDisturbance::advance(&mut self.field, time, dt)
    }
    fn reset(&mut self, wake_seed: u64) {
        AirDisturbance::reset(&mut self.field, wake_seed)
    }
    fn prepare(&mut self, points: &[V3]) {
        self.field.prepare(points)
    }
    fn prepare_all(&mut self) {
        self.field.prepare_all()
    }
    fn clone_box(&self) -> Box<dyn AirDisturbance> {
        Box::new(self.clone())
    }
    fn state(&self) -> AirState {
        self.field.state()
    }
    fn set_state(&mut self, state: AirState) -> Result<(), StateError> {
        self.field.set_state(state)
    }
}

/// The nonlinear agent step in the coordinates of the module docs.
struct Plant {
    /// The physics, turbulence off.
    capture: Valid<CaptureConfig>,
    aero: Arc<AeroModel>,
    /// The mean wake.
    field: WakeField,
    /// Where the wind bias applies: within `radius` of the ACCD's trim position.
    radius: f64,
    centre: V3,
    /// The simulation without wind bias.
    base: CaptureSim,
    /// The state a step starts from, with the tether and ACCD entries replaced.
    template: CaptureState,
    trim_attitude: UnitQuaternion<f64>,
    dofs: usize,
    substeps: usize,
    flap_limit: f64,
    equilibrium_position: V3,
    capture_window: f64,
}

impl Plant {
    fn new(config: &Valid<EnvConfig>, eq: &Equilibrium) -> Result<Plant> {
        let mut capture = config.capture().into_inner();
        capture.turbulence.wake_turbulence = false;
        capture.turbulence.ambient = AmbientTurbulence::None;
        // Switching the turbulence off keeps every rule (as in `Equilibrium::settle`).
        let capture = Valid::trusted(capture);
        let seeds = Seeds::default();
        let aero = Arc::new(capture.accd.aero_model()?);
        let airspeed = capture.aircraft.airspeed;
        let wake = Wake::from_config(&capture.wake, airspeed)?;
        let turbulence = Turbulence::new(&capture.turbulence, airspeed, seeds.wake)?;
        let density = Atmosphere::isa(capture.aircraft.altitude)?.density;
        let field = WakeField::from_parts(wake, turbulence, density);
        let radius = 0.25 * capture.tether.length / capture.tether.segments as f64;
        let air = Biased {
            field: field.clone(),
            bias: V3::zeros(),
            centre: eq.position,
            radius,
        };
        let mut base = CaptureSim::with_parts(&capture, seeds, Arc::clone(&aero), Box::new(air))?;
        base.reset(seeds, &eq.tether, eq.accd)?;
        Ok(Plant {
            template: base.state(),
            base,
            capture,
            aero,
            field,
            radius,
            centre: eq.position,
            trim_attitude: eq.accd.attitude,
            dofs: eq.tether.q.len(),
            substeps: config.substeps(),
            flap_limit: config.physics.accd.flap_limit_deg.to_radians(),
            equilibrium_position: eq.position,
            capture_window: config.capture_window,
        })
    }

    /// A simulation of the plant's physics with the wind bias `wind` (y, z; m/s).
    fn with_wind(&self, wind: &[f64; WIND_DIM]) -> Result<CaptureSim> {
        let air = Biased {
            field: self.field.clone(),
            bias: V3::new(0.0, wind[0], wind[1]),
            centre: self.centre,
            radius: self.radius,
        };
        CaptureSim::with_parts(
            &self.capture,
            Seeds::default(),
            Arc::clone(&self.aero),
            Box::new(air),
        )
    }

    fn dim(&self) -> usize {
        2 * self.dofs + 10
    }

    /// A simulation with the wind bias `wind` (y, z; m/s) set to state `x`.
    fn sim_at(&self, x: &[f64], wind: &[f64; WIND_DIM]) -> Result<CaptureSim> {
        let n = self.dofs;
        let mut state = self.template.clone();
        state.q.copy_from_slice(&x[..n]);
        state.qd.copy_from_slice(&x[n..2 * n]);
        let theta = V3::new(x[2 * n], x[2 * n + 1], x[2 * n + 2]);
        let attitude = self.trim_attitude * rotation::from_scaled_axis(theta);
        let c = attitude.coords;
        state.attitude = [c[0], c[1], c[2], c[3]];
        state.omega = [x[2 * n + 3], x[2 * n + 4], x[2 * n + 5]];
        state
            .flap_deflection
            .copy_from_slice(&x[2 * n + 6..2 * n + 10]);
        state.flap_command = state.flap_deflection;
        let mut sim = if wind.iter().all(|w| *w == 0.0) {
            self.base.clone()
        } else {
            self.with_wind(wind)?
        };
        sim.set_state(state)?;
        Ok(sim)
    }

    /// The state of `sim` in the plant's coordinates, into `out`.
    fn read(&self, sim: &CaptureSim, out: &mut [f64]) {
        let n = self.dofs;
        let t = sim.tether_state();
        out[..n].copy_from_slice(&t.q);
        out[n..2 * n].copy_from_slice(&t.qd);
        let accd = sim.accd_state();
        let theta = rotation::scaled_axis(&(self.trim_attitude.inverse() * accd.attitude));
        out[2 * n..2 * n + 3].copy_from_slice(theta.as_slice());
        out[2 * n + 3..2 * n + 6].copy_from_slice(accd.omega.as_slice());
        out[2 * n + 6..2 * n + 10].copy_from_slice(&sim.actuators().deflection);
    }

    /// One agent step from `x` with commands `u` (flap-limit units) and wind `wind`.
    fn step(&self, x: &[f64], u: &[f64; ACT_DIM], wind: &[f64; WIND_DIM]) -> Result<Vec<f64>> {
        let mut sim = self.sim_at(x, wind)?;
        let command = u.map(|v| v * self.flap_limit);
        sim.step_many(self.substeps, command)?;
        let mut out = vec![0.0; self.dim()];
        self.read(&sim, &mut out);
        Ok(out)
    }

    /// The observation at `x` with the boom tip at `boom` (at rest), scaled, not clipped.
    fn observe(&self, x: &[f64], boom: &V3) -> Result<([f64; OBS_DIM], V3, V3)> {
        let mut sim = self.sim_at(x, &[0.0; WIND_DIM])?;
        let mut s = sim.snapshot()?;
        s.boom_tip = *boom;
        s.boom_velocity = V3::zeros();
        let inputs = ObservationInputs {
            snapshot: &s,
            equilibrium: &self.equilibrium_position,
            flap_limit: self.flap_limit,
            capture_window: self.capture_window,
        };
        let mut y = [0.0; OBS_DIM];
        for (v, field) in y.iter_mut().zip(&OBSERVATION) {
            *v = (field.value)(&inputs) * field.scale;
        }
        Ok((y, s.capture_point, s.position))
    }

    /// `A` at `x` (central differences, commands zero, no wind).
    fn jacobian_a(
        &self,
        x: &[f64],
        steps: &[f64],
        interrupted: &mut dyn FnMut() -> bool,
    ) -> Result<DMatrix<f64>> {
        let dim = self.dim();
        let mut a = DMatrix::zeros(dim, dim);
        let mut xp = x.to_vec();
        for j in 0..dim {
            let h = steps[j];
            xp[j] = x[j] + h;
            let fp = self.step(&xp, &[0.0; ACT_DIM], &NO_WIND)?;
            xp[j] = x[j] - h;
            let fm = self.step(&xp, &[0.0; ACT_DIM], &NO_WIND)?;
            xp[j] = x[j];
            for i in 0..dim {
                a[(i, j)] = (fp[i] - fm[i]) / (2.0 * h);
            }
            check(interrupted)?;
        }
        Ok(a)
    }

    /// Re-expresses the plant about `x` (its attitude error becomes the new trim attitude).
    fn retrim(&mut self, x: &mut [f64]) {
        let n = self.dofs;
        let theta = V3::new(x[2 * n], x[2 * n + 1], x[2 * n + 2]);
        self.trim_attitude *= rotation::from_scaled_axis(theta);
        x[2 * n..2 * n + 3].fill(0.0);
    }
}

fn check(interrupted: &mut dyn FnMut() -> bool) -> Result<()> {
    if interrupted() {
        return Err(SimError::Interrupted {
            time: 0.0,
            what: "linearizing the capture dynamics".into(),
        });
    }
    Ok(())
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// The names and kinds of the state components of a tether with `segments` segments and
/// `dofs` coordinates.
fn state_layout(segments: usize, dofs: usize) -> (Vec<String>, Vec<Component>) {
    let mut names = vec!["s".to_string()];
    let mut kinds = vec![Component::Elongation];
    for k in 1..=segments {
        names.push(format!("phi_{k}"));
        names.push(format!("psi_{k}"));
        kinds.extend([Component::Angle, Component::Angle]);
    }
    for k in 2..=(dofs - 2 * segments) {
        names.push(format!("s_{k}"));
        kinds.push(Component::Elongation);
    }
    let rates: Vec<String> = names.iter().map(|n| format!("{n}_dot")).collect();
    let rate_kinds: Vec<Component> = kinds
        .iter()
        .map(|k| match k {
            Component::Elongation => Component::ElongationRate,
            _ => Component::AngleRate,
        })
        .collect();
    names.extend(rates);
    kinds.extend(rate_kinds);
    for (name, kind) in [
        ("att_x", Component::Attitude),
        ("att_y", Component::Attitude),
        ("att_z", Component::Attitude),
        ("p", Component::BodyRate),
        ("q", Component::BodyRate),
        ("r", Component::BodyRate),
        ("flap_right", Component::Flap),
        ("flap_left", Component::Flap),
        ("flap_top", Component::Flap),
        ("flap_bottom", Component::Flap),
    ] {
        names.push(name.into());
        kinds.push(kind);
    }
    (names, kinds)
}

/// The linear model of `config`'s capture dynamics about its trim (see the module docs).
pub fn linearize(config: &Valid<EnvConfig>) -> Result<Linearization> {
    linearize_interruptible(config, &mut || false)
}

/// [`linearize`], asking `interrupted()` between evaluations and stopping with
/// [`SimError::Interrupted`] when it returns true.
pub fn linearize_interruptible(
    config: &Valid<EnvConfig>,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<Linearization> {
    Ok(linearize_with_plant(config, interrupted)?.0)
}

fn linearize_with_plant(
    config: &Valid<EnvConfig>,
    interrupted: &mut dyn FnMut() -> bool,
) -> Result<(Linearization, Plant)> {
    let eq = Equilibrium::settle_interruptible(config, interrupted)?;
    let mut plant = Plant::new(config, &eq)?;
    let (state_names, components) = state_layout(config.physics.tether.segments, plant.dofs);
    let steps: Vec<f64> = components.iter().map(|&c| state_step(c)).collect();
    let dim = plant.dim();
    let zero = [0.0; ACT_DIM];

    // The trim: the settled state, then Newton on f(x) - x = 0.
    let mut x = vec![0.0; dim];
    plant.read(&plant.sim_at_template()?, &mut x);
    let mut residual = max_abs_diff(&plant.step(&x, &zero, &NO_WIND)?, &x);
    let settle_residual = residual;
    let mut a = plant.jacobian_a(&x, &steps, interrupted)?;
    let mut newton_iterations = 0;
    while residual > TRIM_TOLERANCE && newton_iterations < MAX_NEWTON {
        let f = plant.step(&x, &zero, &NO_WIND)?;
        let g = DMatrix::from_iterator(dim, 1, f.iter().zip(&x).map(|(f, x)| f - x));
        let jac = &a - DMatrix::identity(dim, dim);
        let svd = jac.svd(true, true);
        let cut = PINV_CUT * svd.singular_values.max();
        let dx = svd
            .solve(&g, cut)
            .map_err(|e| SimError::invalid_config("linearize", e, "a solvable trim"))?;
        let mut next: Vec<f64> = x.iter().zip(dx.iter()).map(|(x, d)| x - d).collect();
        let previous_attitude = plant.trim_attitude;
        plant.retrim(&mut next);
        let r = max_abs_diff(&plant.step(&next, &zero, &NO_WIND)?, &next);
        newton_iterations += 1;
        if r.is_nan() || r >= residual {
            // No progress (rounding): keep the last iterate, in its own attitude frame.
            plant.trim_attitude = previous_attitude;
            break;
        }
        x = next;
        residual = r;
        a = plant.jacobian_a(&x, &steps, interrupted)?;
    }

    // B and E.
    let mut b = DMatrix::zeros(dim, ACT_DIM);
    for j in 0..ACT_DIM {
        let mut up = zero;
        up[j] = INPUT_STEP;
        let fp = plant.step(&x, &up, &NO_WIND)?;
        up[j] = -INPUT_STEP;
        let fm = plant.step(&x, &up, &NO_WIND)?;
        for i in 0..dim {
            b[(i, j)] = (fp[i] - fm[i]) / (2.0 * INPUT_STEP);
        }
    }
    check(interrupted)?;
    let mut e = DMatrix::zeros(dim, WIND_DIM);
    for j in 0..WIND_DIM {
        let mut w = NO_WIND;
        w[j] = WIND_STEP;
        let fp = plant.step(&x, &zero, &w)?;
        w[j] = -WIND_STEP;
        let fm = plant.step(&x, &zero, &w)?;
        for i in 0..dim {
            e[(i, j)] = (fp[i] - fm[i]) / (2.0 * WIND_STEP);
        }
    }

    // C, with the boom tip held at the trim capture point.
    let (_, capture_point, position) = plant.observe(&x, &V3::zeros())?;
    let (trim_observation, _, _) = plant.observe(&x, &capture_point)?;
    let mut c = DMatrix::zeros(OBS_DIM, dim);
    let mut xp = x.clone();
    for j in 0..dim {
        let h = steps[j];
        xp[j] = x[j] + h;
        let (yp, _, _) = plant.observe(&xp, &capture_point)?;
        xp[j] = x[j] - h;
        let (ym, _, _) = plant.observe(&xp, &capture_point)?;
        xp[j] = x[j];
        for i in 0..OBS_DIM {
            c[(i, j)] = (yp[i] - ym[i]) / (2.0 * h);
        }
    }
    check(interrupted)?;

    let model = Linearization {
        state_names,
        components,
        steps,
        trim: x,
        trim_attitude: plant.trim_attitude,
        trim_observation,
        capture_point,
        position,
        equilibrium_position: eq.position,
        settle_residual,
        trim_residual: residual,
        newton_iterations,
        a,
        b,
        e,
        c,
        dt: config.agent_step,
    };
    Ok((model, plant))
}

impl Plant {
    /// The simulation at the template (the settled equilibrium).
    fn sim_at_template(&self) -> Result<CaptureSim> {
        let mut sim = self.base.clone();
        sim.set_state(self.template.clone())?;
        Ok(sim)
    }
}

/// A configuration's linear model together with the nonlinear step it was taken from, to
/// check the model against ([`Linearized::step`], [`Linearized::observe`]).
pub struct Linearized {
    /// The linear model.
    pub model: Linearization,
    plant: Plant,
}

impl Linearized {
    /// Linearizes `config` ([`linearize_interruptible`]) and keeps the nonlinear step.
    pub fn new(
        config: &Valid<EnvConfig>,
        interrupted: &mut dyn FnMut() -> bool,
    ) -> Result<Linearized> {
        let (model, plant) = linearize_with_plant(config, interrupted)?;
        Ok(Linearized { model, plant })
    }

    fn state_from(&self, dx: &[f64]) -> Result<Vec<f64>> {
        let dim = self.model.trim.len();
        if dx.len() != dim {
            return Err(SimError::invalid_config(
                "dx",
                format!("{} values", dx.len()),
                &format!("{dim} values (the state of Linearization::state_names)"),
            ));
        }
        if let Some((i, v)) = dx.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(SimError::invalid_config(
                &format!("dx[{i}]"),
                v,
                "a finite number",
            ));
        }
        Ok(self.model.trim.iter().zip(dx).map(|(x, d)| x + d).collect())
    }

    /// The nonlinear agent step from the trim plus `dx` with flap commands `u` (flap-limit
    /// units, held) and the wind bias `wind` (y, z; m/s): the next state minus the trim.
    pub fn step(&self, dx: &[f64], u: &[f64; ACT_DIM], wind: &[f64; WIND_DIM]) -> Result<Vec<f64>> {
        for (i, v) in u.iter().chain(wind).enumerate() {
            if !v.is_finite() {
                let name = if i < ACT_DIM {
                    format!("u[{i}]")
                } else {
                    format!("wind[{}]", i - ACT_DIM)
                };
                return Err(SimError::invalid_config(&name, v, "a finite number"));
            }
        }
        let x = self.state_from(dx)?;
        let next = self.plant.step(&x, u, wind)?;
        Ok(next
            .iter()
            .zip(&self.model.trim)
            .map(|(x, t)| x - t)
            .collect())
    }

    /// The observation (scaled, not clipped) at the trim plus `dx`, the boom tip at the trim
    /// capture point and at rest.
    pub fn observe(&self, dx: &[f64]) -> Result<[f64; OBS_DIM]> {
        let x = self.state_from(dx)?;
        Ok(self.plant.observe(&x, &self.model.capture_point)?.0)
    }
}
