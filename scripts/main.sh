#!/usr/bin/env bash
# The main job: installs everything (scripts/setup.sh, with the stable-baselines3 extras), trains
# PPO on the capture task (training wake seeds only), evaluates it on the held-out wake seeds
# against the baselines (guidance controller, zero flaps, random flaps) and writes the report.
#
#   bash scripts/main.sh [OUT] [--full]      OUT defaults to runs/main
#   ACCD_FULL=1 / --full   the full-length run: training/ppo.json's total_timesteps, 1000 episodes
#   ACCD_TIMESTEPS=N       training steps of the short run (default 1000000)
#   ACCD_EPISODES=K        evaluation episodes per policy of the short run (default 200)
#   ACCD_VENV=/path        the virtual environment to use (default .venv)
#
# Writes OUT/ppo (model, VecNormalize statistics, checkpoints, TensorBoard logs), OUT/eval
# (results.json, summary.md, trajectories.png, miss_distance_cdf.png) and OUT/wall_time.txt.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
OUT="runs/main"
FULL="${ACCD_FULL:-0}"
for arg in "$@"; do
  case "$arg" in
    --full) FULL=1 ;;
    -*) echo "main.sh: unknown option $arg (allowed: --full)" >&2; exit 2 ;;
    *) OUT="$arg" ;;
  esac
done
START=$(date +%s)
ACCD_EXTRAS="sb3" source scripts/setup.sh
SETUP_DONE=$(date +%s)
if [ "$FULL" = "1" ]; then
  TRAIN_ARGS=()
  EPISODES=1000
else
  TRAIN_ARGS=(--timesteps "${ACCD_TIMESTEPS:-1000000}")
  EPISODES="${ACCD_EPISODES:-200}"
fi
if [ -f "$OUT/ppo/run.json" ]; then
  # A rerun: an interrupted training continues; a finished one is evaluated again, not replaced.
  STATUS="$("$ACCD_PY" -c 'import json, sys; print(json.load(open(sys.argv[1])).get("status"))' "$OUT/ppo/run.json")"
  if [ "$STATUS" = "done" ]; then
    echo "main: $OUT/ppo holds a finished training; evaluating it (move it away to train again)"
  else
    echo "main: continuing the training in $OUT/ppo (status: $STATUS)"
    "$ACCD_PY" -m accd_gym train --resume "$OUT/ppo"
  fi
else
  echo "main: training PPO (training/ppo.json ${TRAIN_ARGS[*]:-full length}) into $OUT/ppo"
  "$ACCD_PY" -m accd_gym train --config training/ppo.json --out "$OUT/ppo" "${TRAIN_ARGS[@]}"
fi
TRAIN_DONE=$(date +%s)
echo "main: evaluating on $EPISODES held-out wake seeds into $OUT/eval"
"$ACCD_PY" -m accd_gym evaluate --policy "$OUT/ppo" --policy guidance --policy zero --policy random \
  --episodes "$EPISODES" --out "$OUT/eval"
END=$(date +%s)
printf 'setup %d s, training %d s, evaluation %d s, total %d s\n' \
  $((SETUP_DONE - START)) $((TRAIN_DONE - SETUP_DONE)) $((END - TRAIN_DONE)) $((END - START)) | tee "$OUT/wall_time.txt"
echo "main: report in $OUT/eval/summary.md"
