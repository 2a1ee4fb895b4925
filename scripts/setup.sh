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
"${PIP[@]}" install "maturin>=1.5,<2"
# The project's own dependencies (from pyproject.toml), then the extension, built in release mode.
"${PIP[@]}" install $(cd "$ROOT" && "$VENV/bin/python" - "$EXTRAS" <<'PY'
import sys, tomllib
meta = tomllib.load(open("pyproject.toml", "rb"))["project"]
deps = list(meta["dependencies"])
for extra in filter(None, sys.argv[1].split(",")):
    deps += meta["optional-dependencies"][extra]
print(" ".join(deps))
PY
)
echo "setup: building the Rust extension (release)"
(cd "$ROOT" && VIRTUAL_ENV="$VENV" PATH="$VENV/bin:$PATH" "$VENV/bin/maturin" develop --release --quiet)
export ACCD_PY="$VENV/bin/python"
