//! [`Valid`]: a configuration that has passed its validation. Parse, don't re-validate: the
//! simulation's constructors ([`crate::CaptureSim::new`], [`crate::Episode::new`],
//! [`crate::Equilibrium::settle`], and the batch env above them) take a `Valid` value, so a
//! configuration is checked exactly once, where it is read ([`crate::EnvConfig::from_json`],
//! [`crate::EnvConfig::validated`], [`crate::CaptureConfig::validated`]), and never again.

use std::ops::Deref;
use std::sync::atomic::{AtomicU64, Ordering};

use serde::Serialize;

/// A validated `T`: only the validating functions of this crate make one, and it derefs to the
/// `T` it holds (read-only; a changed configuration must be validated again).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(transparent)]
pub struct Valid<T>(T);

impl<T> Valid<T> {
    /// Wraps a value this crate has just validated (or derived from a validated one by a change
    /// that keeps every rule, documented where it is used).
    pub(crate) fn trusted(value: T) -> Self {
        Valid(value)
    }

    /// The configuration, no longer marked as validated.
    pub fn into_inner(self) -> T {
        self.0
    }
}

impl<T> Deref for Valid<T> {
    type Target = T;

    fn deref(&self) -> &T {
        &self.0
    }
}

impl<T> AsRef<T> for Valid<T> {
    fn as_ref(&self) -> &T {
        &self.0
    }
}

/// Full validations of a physics configuration so far in this process (every
/// [`crate::CaptureConfig::validate`], which every [`crate::EnvConfig::validate`] includes): a
/// diagnostic that lets tests show a configuration is checked once per env construction.
static VALIDATION_PASSES: AtomicU64 = AtomicU64::new(0);

pub(crate) fn count_validation_pass() {
    VALIDATION_PASSES.fetch_add(1, Ordering::Relaxed);
}

/// Full validations of a physics configuration so far in this process (every
/// [`crate::CaptureConfig::validate`], which every [`crate::EnvConfig::validate`] includes): a
/// diagnostic that shows a configuration is checked once per env construction.
pub fn validation_passes() -> u64 {
    VALIDATION_PASSES.load(Ordering::Relaxed)
}
