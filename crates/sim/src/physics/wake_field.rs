//! [`WakeField`]: the air around the tether and the capturing device: free stream, the TA's mean
//! wake ([`crate::physics::wake`]) and turbulence ([`crate::physics::turbulence`]), as an
//! [`accd_tether::Surroundings`], so that wake and turbulence act on every tether segment.
//!
//! `air_velocity(t, p) = (-U_inf, 0, 0) + wake(p).velocity + turbulence(p, wake(p).tke)`, in the
//! TA frame; `air_density` is uniform: ISA at the configured altitude (0.6601 kg/m^3 at 6000 m).
//!
//! **Time.** The turbulence is advanced once per physics step by [`WakeField::advance`] and held
//! over the RK4 stages of the step: `air_velocity` ignores its `time` argument (the
//! [`accd_tether::Surroundings`] contract requires a pure function during a step). The wake and
//! the frozen turbulence are still sampled at each stage's positions.
//!
//! A typical loop: `tether.step(&field)?; field.advance(dt)?;`. The capture simulation builds
//! its field with [`WakeField::from_parts`]; the tests build standalone fields from a small
//! configuration of their own (`tests/support/wake_field.rs`).

use accd_tether::Surroundings;
use nalgebra::Vector3;

use crate::error::Result;
use crate::physics::air::{AirDisturbance, AirState};
use crate::physics::turbulence::Turbulence;
use crate::physics::wake::Wake;
use crate::state_format::StateError;

/// Free stream + mean wake + turbulence, as the tether's [`Surroundings`].
#[derive(Debug, Clone)]
pub struct WakeField {
    wake: Wake,
    turbulence: Turbulence,
    density: f64,
    free_stream: Vector3<f64>,
    tip_drag_area: f64,
}

impl WakeField {
    /// Assembles a field; the free stream is `(-wake.airspeed(), 0, 0)`, `density` in kg/m^3.
    /// Every wake lane is generated (per-lane streams too, [`crate::physics::turbulence::LaneStreams`]:
    /// a standalone field cannot know where it will be sampled).
    pub fn from_parts(wake: Wake, turbulence: Turbulence, density: f64) -> WakeField {
        let mut field = WakeField::on_demand(wake, turbulence, density);
        field.turbulence.activate_all();
        field
    }

    /// [`WakeField::from_parts`] without generating any wake lane: for an owner that prepares
    /// the points it samples ([`AirDisturbance::prepare`], [`AirDisturbance::prepare_all`]),
    /// such as a simulation reset before its first step. A lane generated later has the values
    /// it would have had if generated at once.
    pub fn on_demand(wake: Wake, turbulence: Turbulence, density: f64) -> WakeField {
        WakeField {
            free_stream: Vector3::new(-wake.airspeed(), 0.0, 0.0),
            wake,
            turbulence,
            density,
            tip_drag_area: 0.0,
        }
    }

    /// Gives the tip a stand-in body with quadratic drag `0.5 rho C_D A |v_rel| v_rel` on its
    /// velocity relative to the local air (wake and turbulence included); `drag_area` C_D A in m^2.
    /// Default 0 (no tip force): the capturing device's own model supplies its forces.
    pub fn with_tip_drag_area(mut self, drag_area: f64) -> WakeField {
        self.tip_drag_area = drag_area;
        self
    }

    /// Advances the turbulence by `dt` (s); call once per physics step.
    pub fn advance(&mut self, dt: f64) -> Result<()> {
        self.turbulence.advance(dt)
    }

    /// Restarts the turbulence at time 0 from `wake_seed` (every lane generated). Allocates
    /// nothing.
    pub fn reset(&mut self, wake_seed: u64) {
        self.turbulence.reset(wake_seed);
        self.turbulence.activate_all();
    }

    /// The mean wake.
    pub fn wake(&self) -> &Wake {
        &self.wake
    }

    /// The turbulence.
    pub fn turbulence(&self) -> &Turbulence {
        &self.turbulence
    }

    /// Air density, kg/m^3.
    pub fn density(&self) -> f64 {
        self.density
    }

    /// Free-stream air velocity in the TA frame, (-U_inf, 0, 0), m/s.
    pub fn free_stream(&self) -> Vector3<f64> {
        self.free_stream
    }

    /// Mean air velocity at `p` (TA frame, m): free stream + wake, m/s.
    #[inline]
    pub fn mean_air_velocity_at(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.free_stream + self.wake.sample(p).velocity
    }

    /// Air velocity at `p` (TA frame, m) now: free stream + wake + turbulence, m/s.
    /// Allocates nothing.
    #[inline]
    pub fn air_velocity_at(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let w = self.wake.sample(p);
        self.free_stream + w.velocity + self.turbulence.sample(p, w.tke)
    }
}

impl Surroundings for WakeField {
    type TipReport = ();
    /// [`WakeField::air_velocity_at`]; `time` is ignored (turbulence held over the step).
    fn air_velocity(&self, _time: f64, position: &Vector3<f64>) -> Vector3<f64> {
        self.air_velocity_at(position)
    }

    fn air_density(&self, _time: f64, _position: &Vector3<f64>) -> f64 {
        self.density
    }

    fn tip_force(
        &self,
        _time: f64,
        position: &Vector3<f64>,
        velocity: &Vector3<f64>,
    ) -> Vector3<f64> {
        if self.tip_drag_area == 0.0 {
            return Vector3::zeros();
        }
        let relative = self.air_velocity_at(position) - velocity;
        relative * (0.5 * self.density * self.tip_drag_area * relative.norm())
    }
}

impl WakeField {
    /// Wake and turbulence at `p` (TA frame, m), without the free stream, m/s: the
    /// [`AirDisturbance`] of a capture episode.
    #[inline(always)]
    fn disturbance_at(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let w = self.wake.sample(p);
        w.velocity + self.turbulence.sample(p, w.tke)
    }

    /// The disturbance at each of `positions` into `out`: [`AirDisturbance::velocities`].
    #[inline(always)]
    fn velocities_body(&self, positions: &[Vector3<f64>], out: &mut [Vector3<f64>]) {
        for (v, p) in out.iter_mut().zip(positions) {
            *v = self.disturbance_at(p);
        }
    }

    /// [`WakeField::velocities_body`] compiled for AVX2: the table's corner sums four wide.
    /// Bit for bit the plain build's (no fused multiply-adds: Rust never contracts `a * b + c`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn velocities_avx2(&self, positions: &[Vector3<f64>], out: &mut [Vector3<f64>]) {
        self.velocities_body(positions, out);
    }
}

/// The wake and its turbulence as the disturbance of a capture episode, whose free stream and
/// density come from the towing aircraft instead (the field's own are not used there).
impl AirDisturbance for WakeField {
    fn velocity(&self, _time: f64, position: &Vector3<f64>) -> Vector3<f64> {
        self.disturbance_at(position)
    }

    fn velocities(&self, _time: f64, positions: &[Vector3<f64>], out: &mut [Vector3<f64>]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.velocities_avx2(positions, out) };
        }
        self.velocities_body(positions, out);
    }

    fn advance(&mut self, _time: f64, dt: f64) -> Result<()> {
        self.turbulence.advance(dt)
    }

    /// Restarts the turbulence; with per-lane streams no lane is generated until
    /// [`crate::physics::air::AirDisturbance::prepare`] declares the points sampled (or
    /// [`crate::physics::air::AirDisturbance::prepare_all`]).
    fn reset(&mut self, wake_seed: u64) {
        self.turbulence.reset(wake_seed);
    }

    fn prepare_all(&mut self) {
        self.turbulence.activate_all();
    }

    fn prepare(&mut self, points: &[Vector3<f64>]) {
        let (mut y0, mut y1, mut z0, mut z1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for p in points {
            y0 = y0.min(p.y);
            y1 = y1.max(p.y);
            z0 = z0.min(p.z);
            z1 = z1.max(p.z);
        }
        if !points.is_empty() {
            self.turbulence.activate_box(y0, y1, z0, z1);
        }
    }

    fn clone_box(&self) -> Box<dyn AirDisturbance> {
        Box::new(self.clone())
    }

    fn state(&self) -> AirState {
        AirState::Turbulence(Box::new(self.turbulence.state()))
    }

    fn set_state(&mut self, state: AirState) -> Result<(), StateError> {
        match state {
            AirState::Turbulence(t) => self.turbulence.set_state(*t),
            AirState::Steady => Err(StateError::invalid(
                "air",
                "a steady disturbance",
                "the state of a wake with turbulence",
            )),
        }
    }
}
