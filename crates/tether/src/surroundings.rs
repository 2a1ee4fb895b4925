//! What the tether's surroundings supply: the air (velocity and density at a point), the towing
//! aircraft's acceleration (the rheonomous constraint), and the external force on the tip body.
//!
//! All vectors are in the towing-aircraft (TA) frame: x forward, y starboard, z down, origin at the
//! attachment point. The air moves through this frame at about (-V_TA, 0, 0) plus wake and
//! turbulence. The model queries these functions at every right-hand-side evaluation (four times per
//! RK4 step), at the current positions, so position-dependent fields (a wake) are sampled where the
//! tether is at each stage.

use nalgebra::Vector3;

/// A source of air data and loads. Implementations must be pure functions of their arguments
/// during a step (no interior mutation), so that steps are deterministic.
pub trait Surroundings {
    /// What the tip body's loads yield besides the force (a capturing device's aerodynamic
    /// moment, say), returned by [`crate::TetherModel::accelerations`]; `()` when nothing.
    type TipReport: Copy + Default;

    /// Velocity of the air relative to the TA frame at `position` (m), m/s.
    fn air_velocity(&self, time: f64, position: &Vector3<f64>) -> Vector3<f64>;

    /// The air velocity at every segment centre during this stage, when the surroundings hold
    /// it (a costly field sampled once per step and held over the RK4 stages): `(uniform, held)`,
    /// segment `k`'s air being `uniform + held[k]`; `held` has one entry per segment (another
    /// length is a [`crate::TetherError::WrongSize`]). The loads then read the samples in one
    /// pass that the compiler vectorizes. Default `None`: the loads ask
    /// [`Surroundings::air_velocity`] at each segment centre.
    #[inline(always)]
    fn held_segment_air(&self, _time: f64) -> Option<(Vector3<f64>, &[Vector3<f64>])> {
        None
    }

    /// Air density at `position` (m), kg/m^3.
    fn air_density(&self, time: f64, position: &Vector3<f64>) -> f64;

    /// Acceleration of the towing aircraft (of the frame's origin) expressed in the TA frame,
    /// m/s^2. Every mass feels the apparent force -m a (paper Eq. 10). Default: none.
    fn frame_acceleration(&self, _time: f64) -> Vector3<f64> {
        Vector3::zeros()
    }

    /// External force on the tip body (N) given its position (m) and velocity (m/s) in the TA
    /// frame: the capturing device's aerodynamics, a towed load, ... Gravity and the apparent force
    /// of [`Surroundings::frame_acceleration`] on the tip mass are added by the model. Default: none.
    fn tip_force(
        &self,
        _time: f64,
        _position: &Vector3<f64>,
        _velocity: &Vector3<f64>,
    ) -> Vector3<f64> {
        Vector3::zeros()
    }

    /// The tip body's force (N, as [`Surroundings::tip_force`]) and its report. Default: the
    /// force of [`Surroundings::tip_force`] and the default report.
    #[inline(always)]
    fn tip_loads(
        &self,
        time: f64,
        position: &Vector3<f64>,
        velocity: &Vector3<f64>,
    ) -> (Vector3<f64>, Self::TipReport) {
        (
            self.tip_force(time, position, velocity),
            Self::TipReport::default(),
        )
    }
}

/// No air, no frame acceleration, no tip force: the tether under gravity alone.
#[derive(Debug, Clone, Copy, Default)]
pub struct Vacuum;

impl Surroundings for Vacuum {
    type TipReport = ();
    fn air_velocity(&self, _time: f64, _position: &Vector3<f64>) -> Vector3<f64> {
        Vector3::zeros()
    }
    fn air_density(&self, _time: f64, _position: &Vector3<f64>) -> f64 {
        0.0
    }
}

/// Uniform air, constant frame acceleration, and a tip body with a constant force and a quadratic
/// drag `0.5 rho C_D A |v_rel| v_rel` on its velocity relative to the air.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UniformFlow {
    /// Air velocity in the TA frame, m/s (the TA flying at V is (-V, 0, 0)).
    pub velocity: Vector3<f64>,
    /// Air density, kg/m^3.
    pub density: f64,
    /// Acceleration of the towing aircraft in its own frame, m/s^2.
    pub frame_acceleration: Vector3<f64>,
    /// Constant external force on the tip body, N.
    pub tip_force: Vector3<f64>,
    /// Drag area C_D A of the tip body, m^2.
    pub tip_drag_area: f64,
}

impl UniformFlow {
    /// The towing aircraft flying straight and level at `airspeed` (m/s) through air of `density`.
    pub fn towing(airspeed: f64, density: f64) -> Self {
        UniformFlow {
            velocity: Vector3::new(-airspeed, 0.0, 0.0),
            density,
            frame_acceleration: Vector3::zeros(),
            tip_force: Vector3::zeros(),
            tip_drag_area: 0.0,
        }
    }

    /// Still air (no flow, no density) with the given frame acceleration: for the rheonomous tests.
    pub fn still() -> Self {
        UniformFlow::towing(0.0, 0.0)
    }
}

impl Surroundings for UniformFlow {
    type TipReport = ();
    fn air_velocity(&self, _time: f64, _position: &Vector3<f64>) -> Vector3<f64> {
        self.velocity
    }
    fn air_density(&self, _time: f64, _position: &Vector3<f64>) -> f64 {
        self.density
    }
    fn frame_acceleration(&self, _time: f64) -> Vector3<f64> {
        self.frame_acceleration
    }
    fn tip_force(
        &self,
        _time: f64,
        _position: &Vector3<f64>,
        velocity: &Vector3<f64>,
    ) -> Vector3<f64> {
        let relative = self.velocity - velocity;
        self.tip_force + relative * (0.5 * self.density * self.tip_drag_area * relative.norm())
    }
}
