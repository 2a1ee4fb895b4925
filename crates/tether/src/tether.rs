//! [`Tether`]: a model, its state and its integrator together, for users who just want to step.

use nalgebra::Vector3;

use crate::config::{StepLoad, TetherConfig};
use crate::dynamics::{Energy, TetherModel};
use crate::error::{Result, TetherError};
use crate::implicit::Rosenbrock;
use crate::integrator::{InSurroundings, Rk4};
use crate::state::TetherState;
use crate::surroundings::Surroundings;

/// A tether ready to step: config (validated), model, state and RK4 buffers.
///
/// A new tether trails straight back from the aircraft (all segments along -x), at rest and
/// unstretched, at t = 0: the paper's initial condition of section 4.
///
/// Each [`Tether::step`] of [`TetherConfig::time_step`] is split into as many RK4 substeps as the
/// chain's fastest mode needs at the current attachment tension and air
/// ([`TetherConfig::substeps_for`]): one for Table 3's n = 30 at 0.01 s, so its steps are plain
/// RK4 steps; two or more for fine discretizations (n = 300) that a single step would blow up.
/// With [`crate::Scheme::ImplicitAxial`] the steps are ROS34PW2 steps ([`crate::implicit`]),
/// substepped for the modes other than the axial ones.
///
/// Time is kept as `origin + steps * dt` (the origin is the time of the last state set from
/// outside), free of the drift of summing dt: the rule of the capture simulation too.
#[derive(Debug, Clone)]
pub struct Tether {
    model: TetherModel,
    state: TetherState,
    rk4: Rk4,
    /// The Rosenbrock-W buffers, for [`crate::Scheme::ImplicitAxial`] only.
    rosenbrock: Option<Rosenbrock>,
    qdd: Vec<f64>,
    /// Time of the last state set from outside, s.
    time_origin: f64,
    /// Steps taken since `time_origin`.
    steps: u64,
}

impl Tether {
    /// Builds a tether from a config (validated, [`TetherConfig::validate_for_stepping`]).
    pub fn new(config: &TetherConfig) -> Result<Self> {
        config.validate_for_stepping()?;
        let model = TetherModel::new(config)?;
        let state = TetherState::straight(config.segments, Vector3::new(-1.0, 0.0, 0.0), 0.0)?;
        let state = if config.is_distributed() {
            state.to_distributed()?
        } else {
            state
        };
        Ok(Tether {
            rk4: Rk4::new(model.dofs(), 0),
            rosenbrock: (config.scheme == crate::Scheme::ImplicitAxial)
                .then(|| Rosenbrock::new(model.dofs(), 0)),
            qdd: vec![0.0; model.dofs()],
            model,
            state,
            time_origin: 0.0,
            steps: 0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &TetherConfig {
        self.model.config()
    }

    /// The model (equations of motion), e.g. for the mass matrix or accelerations at any state.
    pub fn model_mut(&mut self) -> &mut TetherModel {
        &mut self.model
    }

    /// The current state.
    pub fn state(&self) -> &TetherState {
        &self.state
    }

    /// Replaces the state after checking its size and values.
    pub fn set_state(&mut self, state: TetherState) -> Result<()> {
        if state.q.len() != self.model.dofs() {
            return Err(TetherError::WrongSize {
                what: "state.q",
                expected: self.model.dofs(),
                found: state.q.len(),
            });
        }
        state.validate_for(self.model.segments())?;
        self.time_origin = state.time;
        self.steps = 0;
        self.state = state;
        Ok(())
    }

    /// The fixed step, s.
    pub fn time_step(&self) -> f64 {
        self.config().time_step
    }

    /// Substeps the next step takes, from the state and the air at the attachment
    /// ([`StepLoad::of_state`] with the state's effective axial mass, [`TetherModel::axial_mass`],
    /// [`TetherConfig::substeps_for`]). Evaluates the accelerations at the current state for it
    /// (a step does that as its first stage anyway).
    pub fn substeps<S: Surroundings + ?Sized>(&mut self, surroundings: &S) -> Result<usize> {
        let s = &self.state;
        self.model
            .accelerations(s.time, &s.q, &s.qd, surroundings, &mut self.qdd)?;
        let (density, airspeed) = attachment_air(surroundings, s.time);
        let c = self.model.config();
        Ok(c.substeps_for(&StepLoad::of_state(
            c,
            s,
            c.tip_mass,
            density,
            airspeed,
            self.model.axial_mass(),
        )))
    }

    /// One step of the configured length (see [`Tether::substeps`]; the substeps are chosen
    /// after the first stage, whose evaluation gives the axial mass). On error the state is
    /// unchanged. A step that would need more than [`crate::config::MAX_SUBSTEPS`] substeps is
    /// a divergence.
    pub fn step<S: Surroundings + ?Sized>(&mut self, surroundings: &S) -> Result<()> {
        let dt = self.model.config().time_step;
        let time = self.state.time;
        let (density, airspeed) = attachment_air(surroundings, time);
        let mut system = InSurroundings {
            model: &mut self.model,
            surroundings,
        };
        let s = &mut self.state;
        if let Some(rosenbrock) = &mut self.rosenbrock {
            // The substeps from the state alone: the stage matrix depends on the step length,
            // and the modes left explicit do not need the axial mass.
            let k = substeps_at(system.model, time, density, airspeed, &s.q, &s.qd)?;
            rosenbrock.advance(&mut system, time, dt, k, &mut s.q, &mut s.qd, &mut [])?;
            self.steps += 1;
            s.time = self.time_origin + self.steps as f64 * dt;
            return Ok(());
        }
        let choose = |system: &InSurroundings<'_, S>, q: &[f64], qd: &[f64]| {
            substeps_at(system.model, time, density, airspeed, q, qd)
        };
        self.rk4
            .advance_adaptive(&mut system, time, dt, &mut s.q, &mut s.qd, &mut [], choose)?;
        self.steps += 1;
        s.time = self.time_origin + self.steps as f64 * dt;
        Ok(())
    }

    /// Steps `steps` times, stopping at the first error.
    pub fn step_many<S: Surroundings + ?Sized>(
        &mut self,
        steps: usize,
        surroundings: &S,
    ) -> Result<()> {
        self.step_many_interruptible(steps, surroundings, &mut || false)
    }

    /// Steps `steps` times, stopping at the first error, and after any whole step at which
    /// `interrupted()` returns true ([`TetherError::Interrupted`]; the state is that step's).
    /// Long loops of the bindings pass a check of the caller's signals here.
    pub fn step_many_interruptible<S: Surroundings + ?Sized>(
        &mut self,
        steps: usize,
        surroundings: &S,
        interrupted: &mut dyn FnMut() -> bool,
    ) -> Result<()> {
        for done in 0..steps {
            self.step(surroundings)?;
            if interrupted() {
                return Err(TetherError::Interrupted {
                    time: self.state.time,
                    done: done + 1,
                    requested: steps,
                });
            }
        }
        Ok(())
    }

    /// Generalized accelerations at the current state.
    pub fn accelerations<S: Surroundings + ?Sized>(&mut self, surroundings: &S) -> Result<&[f64]> {
        let s = &self.state;
        self.model
            .accelerations(s.time, &s.q, &s.qd, surroundings, &mut self.qdd)?;
        Ok(&self.qdd)
    }

    /// Energy of the current state.
    pub fn energy(&mut self) -> Energy {
        self.model
            .energy(&self.state.q, &self.state.qd)
            .expect("state size is checked on set")
    }

    /// Tip position (m) and velocity (m/s) in the TA frame.
    pub fn tip_state(&mut self) -> (Vector3<f64>, Vector3<f64>) {
        self.model
            .tip_state(&self.state.q, &self.state.qd)
            .expect("state size is checked on set")
    }

    /// Joint positions (n + 1 points, see [`TetherModel::joint_positions`]).
    pub fn joint_positions(&self, out: &mut [Vector3<f64>]) -> Result<()> {
        self.model.joint_positions(&self.state.q, out)
    }

    /// Tensions along the chain at the current state (n + 1 values, see [`TetherModel::tensions`]).
    pub fn tensions<S: Surroundings + ?Sized>(
        &mut self,
        surroundings: &S,
        out: &mut [f64],
    ) -> Result<()> {
        let s = &self.state;
        self.model
            .tensions(s.time, &s.q, &s.qd, surroundings, &mut self.qdd, out)
    }

    /// Tension of the axial element at the attachment, k s + c_s s' (segment 1's element,
    /// n k s_1 + n c_s s_1', when distributed), N.
    pub fn attachment_tension(&self) -> f64 {
        let c = self.config();
        c.element_stiffness() * self.state.q[0] + c.element_damping() * self.state.qd[0]
    }
}

/// Air density (kg/m^3) and airspeed (m/s) at the attachment at `time`.
/// The RK4 substeps of a step from `(q, qd)` at `time` (the chain's fastest mode under the
/// step's load, with the state's effective axial mass from the first stage); more than
/// [`crate::config::MAX_SUBSTEPS`] is a divergence.
pub(crate) fn substeps_at(
    model: &TetherModel,
    time: f64,
    density: f64,
    airspeed: f64,
    q: &[f64],
    qd: &[f64],
) -> Result<usize> {
    let c = model.config();
    let load =
        StepLoad::of_coordinates(c, q, qd, c.tip_mass, density, airspeed, model.axial_mass());
    let k = c.substeps_for(&load);
    if k > crate::config::MAX_SUBSTEPS {
        return Err(TetherError::Diverged {
            time,
            reason: format!(
                "the chain's fastest mode needs {k} {} substeps per step (at most {}): \
                 the tension or the rates are beyond what this discretization can follow",
                c.scheme.integrator(),
                crate::config::MAX_SUBSTEPS
            ),
        });
    }
    Ok(k)
}

fn attachment_air<S: Surroundings + ?Sized>(surroundings: &S, time: f64) -> (f64, f64) {
    let origin = Vector3::zeros();
    (
        surroundings.air_density(time, &origin),
        surroundings.air_velocity(time, &origin).norm(),
    )
}
