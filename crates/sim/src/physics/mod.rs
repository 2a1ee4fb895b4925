//! The physical world of one capture: the ACCD as a 6-DoF body with its flaps and coefficient
//! tables ([`accd`], [`aero`], [`interp`]), the towing aircraft ([`aircraft`]), the air it
//! flies in ([`air`]: the interface; [`wake`], [`turbulence`], [`wake_field`]: the wake and its
//! turbulence), the RLV's capture boom ([`boom`]), and the coupled step of all of them with the
//! tether ([`capture`]). Nothing here knows about the RL task.

pub mod accd;
pub mod aero;
pub mod air;
pub mod aircraft;
pub mod boom;
pub mod capture;
pub mod interp;
pub mod turbulence;
pub mod wake;
pub mod wake_field;
