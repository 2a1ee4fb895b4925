//! The crate's integration tests, one module per file, linked into one test binary (one link
//! and one instantiation of the generic code instead of one per file). `no_alloc.rs` stays a
//! binary of its own: it replaces the global allocator.

#[path = "../common/mod.rs"]
mod common;

mod axial_mass;
mod distributed;
mod drag_velocity;
mod energy;
mod held_air;
mod implicit_axial;
mod kinematics;
mod mass_matrix;
mod oscillation;
mod recursive_vs_dense;
mod singularity;
mod stability_regressions;
mod statics;
