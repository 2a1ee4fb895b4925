#!/usr/bin/env bash
# Runs every test: formatting, the Rust test suites (release build: they integrate physics), and
# the Python suite against a fresh release build of the extension. Does its own set-up.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
# The test extras plus Ray (tests/test_ray.py); ACCD_EXTRAS=test runs without Ray (those tests skip).
export ACCD_EXTRAS="${ACCD_EXTRAS:-test,ray}"
source scripts/setup.sh

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy (warnings are errors)"
cargo clippy --workspace --all-targets --release -q -- -D warnings
echo "== cargo test"
# The bindings crate is a cdylib built and tested through Python below.
cargo test --release --workspace --exclude accd-py
echo "== pytest"
"$ACCD_PY" -m pytest -q tests
