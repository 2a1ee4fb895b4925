//! The crate's integration tests, one module per file, linked into one test binary (one link
//! and one instantiation of the generic code instead of one per file). `no_alloc.rs` stays a
//! binary of its own: it replaces the global allocator.

mod batch;
mod controller;
mod reliability;
