#!/usr/bin/env bash
# Runs every benchmark and prints the ratios the performance work tracks:
#   criterion: the tether (n = 10 .. 300), one capture-system physics step (the default fast and
#   the exact air scheme beside the tether), the batch env (N = 1, 16, 256; 1 thread and all cores);
#   examples/capture_ratio: the capture step against the tether in interleaved rounds;
#   scripts/bench_physics.py: MuJoCo's bare chain, the tether and the capture system in one process;
#   scripts/bench_envs.py: the Python envs (default fast scheme and the exact one);
#   scripts/bench_training.py: PPO end to end with the time split;
#   scripts/bench_summary.py: the performance targets against this run's figures.
# Does its own set-up (the venv with the sb3 extras and mujoco). Takes about 15 minutes.
#   bash scripts/bench.sh [OUT_DIR]      (default runs/bench)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
OUT="${1:-runs/bench}"
mkdir -p "$OUT"
ACCD_EXTRAS="${ACCD_EXTRAS:-sb3}" source scripts/setup.sh
"$ACCD_PY" -m pip --disable-pip-version-check -q install "mujoco>=3"
EXACT='{"wake": {"sampling": "per_stage"}, "turbulence": {"normal_sampler": "box_muller", "lane_streams": "shared"}}'
{
  echo "date: $(date -u +%FT%TZ)  load: $(cut -d' ' -f1-3 /proc/loadavg)  cores: $(nproc)"
  echo "== criterion: tether"
  cargo bench -q -p accd-tether --features bench --bench tether -- --warm-up-time 1 --measurement-time 3 recursive 2>&1 | grep -E "time:|^[a-z_/0-9]+ *$|recursive" || true
  echo "== criterion: capture-system physics step"
  cargo bench -q -p accd-sim --features bench --bench capture -- --warm-up-time 1 --measurement-time 3 2>&1 | grep -E "time:|physics_step" || true
  echo "== capture-system step / tether alone, interleaved rounds (minimum per step)"
  cargo run -q --release -p accd-sim --example capture_ratio 2>&1 || true
  echo "== criterion: batch env"
  cargo bench -q -p accd-batch --features bench --bench batch -- --warm-up-time 1 --measurement-time 4 2>&1 | grep -E "time:|thrpt:|batch_step" || true
  echo "== physics steps side by side (one process)"
  "$ACCD_PY" scripts/bench_physics.py --json "$OUT/physics.json"
  echo "== Python envs, default (fast) scheme"
  "$ACCD_PY" scripts/bench_envs.py --seconds 4 --json "$OUT/envs_default.json"
  echo "== Python envs, exact scheme"
  "$ACCD_PY" scripts/bench_envs.py --seconds 4 --config "$EXACT" --json "$OUT/envs_exact.json"
  echo "== PPO training (training/ppo.json): | env | agent steps/s | env s | inference, wrappers, SB3 s | gradient updates s | other s | wall s |"
  "$ACCD_PY" scripts/bench_training.py --json "$OUT/training_default.json"
  echo "== PPO training, exact scheme"
  "$ACCD_PY" scripts/bench_training.py --env "$EXACT" --json "$OUT/training_exact.json"
  echo "== the performance targets from this run"
  "$ACCD_PY" scripts/bench_summary.py "$OUT" --json "$OUT/targets.json"
  echo "load at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
} 2>&1 | tee "$OUT/bench.txt"
