#!/usr/bin/env bash
# Runs every test: formatting, clippy, the Rust test suites and the Python suite, all against one
# optimised build (the `ci` profile: release
# optimisation without LTO; they integrate physics). Does its own set-up.
#
# The Rust checks need no Python, so they run while scripts/setup.sh installs the Python side
# (pip's downloads and unpacking leave the processors mostly idle); their output is printed when
# they end. Cargo's lock on the build folder orders the two builds that share it.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
# The test extras plus Ray (tests/test_ray.py); ACCD_EXTRAS=test runs without Ray (those tests skip).
export ACCD_EXTRAS="${ACCD_EXTRAS:-test,ray}"
# One build for the extension and the Rust test suites: the `ci` profile (release optimisation
# without LTO), which maturin takes here and cargo below; a user's install builds `release`.
export MATURIN_PEP517_ARGS="--profile ci"

rust_checks() {
  echo "== cargo fmt --check [$SECONDS s]"
  cargo fmt --all -- --check
  echo "== cargo clippy (warnings are errors) [$SECONDS s]"
  cargo clippy --workspace --all-targets --profile ci -q -- -D warnings
  echo "== cargo test (profile ci: release optimisation, no LTO) [$SECONDS s]"
  # The bindings crate is a cdylib built and tested through Python below.
  cargo test --profile ci --workspace --exclude accd-py
  # The build of a processor without AVX2 and FMA must give the recorded fingerprint too.
  echo "== the Rust fingerprint with ACCD_GYM_ARITHMETIC=portable [$SECONDS s]"
  ACCD_GYM_ARITHMETIC=portable cargo test --profile ci -q -p accd-sim --test integration fingerprint
  echo "== Rust checks done [$SECONDS s]"
}

# The replay pages are tested in a real browser (tests/test_replay.py): Debian's chromium, installed
# here under CI (about 30 s); locally those tests are skipped, saying so, when it is missing.
install_chromium() {
  if [ "${CI:-}" = "true" ] && ! command -v chromium >/dev/null && [ ! -x /usr/lib/chromium/chromium ]; then
    echo "== installing chromium (Debian) for the browser tests [$SECONDS s]"
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends chromium >/dev/null
    echo "== chromium installed [$SECONDS s]"
  fi
}

# On any exit (a failure, Ctrl+C) the background checks end too, their cargo and rustc included.
kill_tree() { local child; for child in $(pgrep -P "$1"); do kill_tree "$child"; done; kill "$1" 2>/dev/null || true; }
LOGS="$(mktemp -d)"
trap 'for job in $(jobs -p); do kill_tree "$job"; done; rm -rf "$LOGS"' EXIT
( set -euo pipefail; rust_checks ) >"$LOGS/rust" 2>&1 &
RUST=$!
( set -euo pipefail; install_chromium ) >"$LOGS/chromium" 2>&1 &
CHROMIUM=$!

echo "== Python set-up (the Rust checks run meanwhile) [$SECONDS s]"
source scripts/setup.sh
echo "== Python set-up done [$SECONDS s]"

status=0
wait "$RUST" || status=$?
cat "$LOGS/rust"
[ "$status" = 0 ] || { echo "== Rust checks failed (exit $status)" >&2; exit "$status"; }
wait "$CHROMIUM" || status=$?
cat "$LOGS/chromium"
[ "$status" = 0 ] || { echo "== chromium install failed (exit $status)" >&2; exit "$status"; }

echo "== pytest (two workers; the slowest tests listed at the end) [$SECONDS s]"
"$ACCD_PY" -m pytest -q -n 2 --dist worksteal --durations=15 tests
echo "== the physics fingerprints with ACCD_GYM_ARITHMETIC=portable [$SECONDS s]"
ACCD_GYM_ARITHMETIC=portable "$ACCD_PY" -m pytest -q tests/test_physics_hash.py
echo "== done [$SECONDS s]"
