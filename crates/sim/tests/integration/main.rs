//! The crate's integration tests, one module per file, linked into one test binary (one link
//! and one instantiation of the generic code instead of one per file). `no_alloc.rs` stays a
//! binary of its own: it replaces the global allocator.

#[path = "../support/mod.rs"]
mod support;

mod aircraft_profile;
mod behaviour;
mod boom_placement;
mod episode;
mod fingerprint;
mod linearize;
mod module_graph;
mod randomization;
mod reliability;
mod sensors;
mod state_format;
mod turbulence;
mod wake;
mod wake_field;
