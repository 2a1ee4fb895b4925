//! Helpers shared by the integration tests (not production API).

#![allow(dead_code)]

pub mod wake_field;
