#!/usr/bin/env bash
# The main job: installs everything, then simulates Table 3's tether settling behind the towing
# aircraft (185 m/s, 6000 m, stand-in capturing device at the tip) and writes a plot and a summary
# to runs/settle (or the folder given as the first argument).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
ACCD_EXTRAS="" source scripts/setup.sh
"$ACCD_PY" -m accd_gym settle --out "${1:-runs/settle}"
