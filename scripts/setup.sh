#!/usr/bin/env bash
# Creates (or reuses) the Python virtual environment, installs the Python dependencies and builds
# the Rust extension into it. Sourced by the other scripts; safe to run repeatedly.
#   ACCD_VENV   where the venv lives (default: .venv in the repository)
#   ACCD_EXTRAS pip extras to install, comma-separated (default: test)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${ACCD_VENV:-$ROOT/.venv}"
EXTRAS="${ACCD_EXTRAS:-test}"

command -v cargo >/dev/null || { echo "setup: cargo (Rust toolchain) is required: https://rustup.rs" >&2; exit 1; }
PYTHON="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
  echo "setup: creating virtual environment in $VENV"
  "$PYTHON" -m venv "$VENV"
fi
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check -q)
"${PIP[@]}" install --upgrade pip >/dev/null
# The README's install command: the package in editable mode with its extras. pip builds the Rust
# extension through maturin (release profile, pyproject.toml) and installs the dependencies.
echo "setup: pip install -e \".[$EXTRAS]\" (builds the Rust extension)"
(cd "$ROOT" && "${PIP[@]}" install -e ".[$EXTRAS]")
export ACCD_PY="$VENV/bin/python"
