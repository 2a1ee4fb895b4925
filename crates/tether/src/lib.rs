//! # accd-tether
//!
//! The 3D multibody tether of DLR's In-Air Capturing concept (Singh et al., "Multibody modelling
//! of tether and capture system for dynamic simulations of In-Air Capturing"; section numbers
//! below refer to that paper): a chain of `n` rigid segments hung from the towing aircraft
//! through one axial visco-elastic element (or, as an option, one in every segment:
//! [`Elasticity`], [`distributed`]), with nonlinear bending springs and Rayleigh damping
//! at the joints, per-segment aerodynamics, the aircraft's acceleration as a rheonomous
//! constraint, and a tip body (the capturing device) at the free end.
//!
//! Pure Rust, no Python, no reinforcement learning. The pieces, each a separate type:
//! * [`TetherConfig`] — serde configuration with validation and the paper's presets;
//! * [`TetherState`] — time, coordinates, rates;
//! * [`TetherModel`] — the equations of motion (M(q) q'' = Q), with preallocated buffers;
//! * [`Rk4`] — the default fixed-step integrator, over a [`System`] of second-order coordinates
//!   and first-order states (the tether in its surroundings, [`InSurroundings`], or the capture
//!   simulation above it); [`Rosenbrock`] — the linearly implicit one of
//!   [`Scheme::ImplicitAxial`], with the axial spring-dampers implicit ([`implicit`]);
//! * [`Surroundings`] — what the caller supplies: air velocity and density at any point, the
//!   aircraft's acceleration, the force on the tip;
//! * [`Tether`] — the three together, for stepping.
//!
//! Frames and units: SI; the towing-aircraft frame has x forward, y starboard, z down, origin at
//! the attachment point.

mod arith;
pub mod atmosphere;
pub mod axial;
mod chain;
pub mod config;
pub mod direction;
pub mod distributed;
pub mod dynamics;
pub mod error;
pub mod implicit;
pub mod integrator;
pub mod material;
pub mod presets;
pub mod recursive;
pub mod reference;
pub mod state;
pub mod surroundings;
pub mod tether;
mod trig;

pub use arith::{arithmetic, portable_requested, ARITHMETIC_VALUES, ARITHMETIC_VARIABLE};
pub use atmosphere::Atmosphere;
pub use axial::AxialStage;
pub use config::{DragVelocity, Elasticity, Scheme, TetherConfig, STANDARD_GRAVITY};
pub use direction::DirectionJet;
pub use dynamics::{Energy, Solver, TetherModel};
pub use error::{Result, TetherError};
pub use implicit::{AxialSystem, Rosenbrock};
pub use integrator::{InSurroundings, Rk4, System};
pub use material::Material;
pub use state::TetherState;
pub use surroundings::{Surroundings, UniformFlow, Vacuum};
pub use tether::Tether;
