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
# uv (from PyPI, into the venv) installs what the README's `pip install -e` installs, the same
# packages from the same index, but downloads and unpacks them in parallel: PyTorch with its CUDA
# libraries is about 3 GB, which pip fetches one file at a time (about 2 minutes against half
# a minute). pip is kept as the fallback where uv cannot be installed.
"${PIP[@]}" install --upgrade pip >/dev/null
"${PIP[@]}" install "uv>=0.5" >/dev/null 2>&1 || echo "setup: uv could not be installed; using pip"
# The README's install command: the package in editable mode with its extras. The build backend
# (maturin) compiles the Rust extension (release profile, pyproject.toml) on every run:
# --reinstall-package makes uv rebuild it as pip does, rather than reuse a build from its cache
# after a change to the Rust sources.
echo "setup: install -e \".[$EXTRAS]\" (builds the Rust extension)"
if [ -x "$VENV/bin/uv" ]; then
  (cd "$ROOT" && "$VENV/bin/uv" pip install -q --python "$VENV/bin/python" --reinstall-package accd-gym -e ".[$EXTRAS]")
else
  (cd "$ROOT" && "${PIP[@]}" install -e ".[$EXTRAS]")
fi
export ACCD_PY="$VENV/bin/python"
