//! The components of the plant state (tether coordinates and rates, attitude error, body rates,
//! flaps) and their finite-difference steps: shared by the linearization
//! ([`crate::task::linearize`]) and the equilibrium solve ([`crate::task::static_equilibrium`]).

/// What one state component is (for its name and finite-difference step).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Component {
    /// An elongation, m.
    Elongation,
    /// A segment angle, rad.
    Angle,
    /// An elongation rate, m/s.
    ElongationRate,
    /// A segment angle rate, rad/s.
    AngleRate,
    /// The attitude error, rad.
    Attitude,
    /// A body rate, rad/s.
    BodyRate,
    /// A flap deflection, rad.
    Flap,
}

/// The finite-difference step of a state component, in its unit: 1e-7 m for an elongation (the
/// axial spring, k = 1.6e5 N/m, changes the tension by 0.016 N), 1e-6 rad for an angle or the
/// attitude error (0.25 mm at the end of a 250 m tether), 1e-5 m/s or rad/s for a rate, 1e-6 rad
/// for a flap.
pub fn state_step(c: Component) -> f64 {
    match c {
        Component::Elongation => 1e-7,
        Component::Angle | Component::Attitude | Component::Flap => 1e-6,
        Component::ElongationRate | Component::AngleRate | Component::BodyRate => 1e-5,
    }
}
