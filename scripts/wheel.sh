#!/usr/bin/env bash
# Builds the release wheel and the sdist of accd-gym into OUT (default dist/):
#   - the wheel for this platform, built against CPython's stable ABI of 3.11 (tag cp311-abi3):
#     the one wheel installs into every CPython from 3.11 on, no Rust toolchain needed there;
#     on Linux maturin checks its symbols and tags it manylinux (the oldest glibc it allows);
#   - the sdist (the Python package and the crates it builds from; installing it needs cargo).
#
#   bash scripts/wheel.sh [OUT]
#   ACCD_WHEEL_PROFILE=ci   the `ci` cargo profile instead of `release` (scripts/test.sh: it reuses
#                           the build the tests compiled; `release` adds thin LTO and one codegen unit)
#   ACCD_WHEEL_PYTHON=PATH  the interpreter maturin builds with (default: python3); scripts/test.sh
#                           passes the test venv's, so that cargo finds its build unchanged
#   ACCD_WHEEL_SDIST=0      the wheel only
#
# Needs cargo. maturin comes from PATH, or is installed (the range pyproject.toml's build-system
# names) into a small virtual environment under target/.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
OUT="${1:-dist}"
PROFILE="${ACCD_WHEEL_PROFILE:-release}"
PYTHON="${ACCD_WHEEL_PYTHON:-python3}"

command -v cargo >/dev/null || { echo "wheel: cargo (Rust toolchain) is required: https://rustup.rs" >&2; exit 1; }
MATURIN="$(command -v maturin || true)"
if [ -z "$MATURIN" ]; then
  TOOLS="$ROOT/target/maturin-venv"
  if [ ! -x "$TOOLS/bin/maturin" ]; then
    echo "wheel: installing maturin into $TOOLS"
    python3 -m venv "$TOOLS"
    "$TOOLS/bin/python" -m pip --disable-pip-version-check -q install "maturin>=1.5,<2"
  fi
  MATURIN="$TOOLS/bin/maturin"
fi
mkdir -p "$OUT"
echo "wheel: maturin build --profile $PROFILE (abi3) into $OUT"
"$MATURIN" build --profile "$PROFILE" --interpreter "$PYTHON" --out "$OUT"
if [ "${ACCD_WHEEL_SDIST:-1}" != "0" ]; then
  echo "wheel: maturin sdist into $OUT"
  "$MATURIN" sdist --out "$OUT"
fi
ls -l "$OUT"
