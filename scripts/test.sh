#!/usr/bin/env bash
# Runs every test: formatting, clippy, the Rust test suites with and without the `lockstep`
# feature, and the Python suite, all against one optimised build (the `ci` profile: release
# optimisation without LTO; they integrate physics). Does its own set-up.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
# The test extras plus Ray (tests/test_ray.py); ACCD_EXTRAS=test runs without Ray (those tests skip).
export ACCD_EXTRAS="${ACCD_EXTRAS:-test,ray}"
# One build for the extension and the Rust test suites: the `ci` profile (release optimisation
# without LTO), which maturin takes here and cargo below; a user's install builds `release`.
export MATURIN_PEP517_ARGS="--profile ci"
source scripts/setup.sh

echo "== cargo fmt --check [$SECONDS s]"
cargo fmt --all -- --check
echo "== cargo clippy (warnings are errors) [$SECONDS s]"
cargo clippy --workspace --all-targets --profile ci -q -- -D warnings
echo "== cargo test (profile ci: release optimisation, no LTO) [$SECONDS s]"
# The bindings crate is a cdylib built and tested through Python below.
cargo test --profile ci --workspace --exclude accd-py
echo "== without the lockstep feature (envs stepped one at a time) [$SECONDS s]"
cargo clippy -p accd-tether -p accd-sim -p accd-batch --all-targets --profile ci -q --no-default-features -- -D warnings
cargo test --profile ci -q -p accd-tether -p accd-batch --no-default-features
# The replay pages are tested in a real browser (tests/test_replay.py): Debian's chromium, installed
# here under CI (about 30 s); locally those tests are skipped, saying so, when it is missing.
if [ "${CI:-}" = "true" ] && ! command -v chromium >/dev/null && [ ! -x /usr/lib/chromium/chromium ]; then
  echo "== installing chromium (Debian) for the browser tests"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends chromium >/dev/null
fi
echo "== pytest (two workers; the slowest tests listed at the end) [$SECONDS s]"
"$ACCD_PY" -m pytest -q -n 2 --dist worksteal --durations=15 tests
echo "== done [$SECONDS s]"
