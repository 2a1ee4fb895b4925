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
# The dependencies first, by uv (from PyPI, into the venv): the same packages from the same index
# as pip, downloaded and unpacked in parallel (PyTorch with its CUDA libraries is about 3 GB, which
# pip fetches one file at a time). Where uv cannot be installed, pip below installs them itself.
"${PIP[@]}" install --upgrade pip >/dev/null
if "${PIP[@]}" install "uv>=0.5" >/dev/null 2>&1; then
  echo "setup: uv pip install (the dependencies of \".[$EXTRAS]\")"
  "$VENV/bin/python" - "$ROOT/pyproject.toml" "$EXTRAS" >"$VENV/accd-requirements.txt" <<'PY'
import sys, tomllib
project = tomllib.load(open(sys.argv[1], "rb"))["project"]
extras = [e for e in sys.argv[2].split(",") if e]
print("\n".join(project["dependencies"] + [r for e in extras for r in project["optional-dependencies"].get(e, [])]))
PY
  # --compile-bytecode as pip does: without the .pyc files every new process (Ray's workers, the
  # tests' subprocesses) compiles the modules it imports again.
  "$VENV/bin/uv" pip install -q --compile-bytecode --python "$VENV/bin/python" -r "$VENV/accd-requirements.txt"
fi
# The README's install command: the package in editable mode with its extras. pip builds the Rust
# extension through maturin (release profile, pyproject.toml) and installs what is still missing.
echo "setup: pip install -e \".[$EXTRAS]\" (builds the Rust extension)"
(cd "$ROOT" && "${PIP[@]}" install -e ".[$EXTRAS]")
export ACCD_PY="$VENV/bin/python"
