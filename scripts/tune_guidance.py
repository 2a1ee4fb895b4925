"""Tunes the guidance baseline's gains by a grid search on TRAINING wake seeds (never held-out ones).

Usage: python scripts/tune_guidance.py [--episodes 32] [--out training/guidance_tuning.json] [--grid JSON]
Stage 1 (the default GRID) wrote training/guidance_tuning.json; stage 2 refined around its winner
(training/guidance_tuning_stage2.json, the grid is stored in the file).
Scores every gain set by capture rate (ties: lower median miss distance) on wake seeds
1000..1000+episodes-1 (inside TRAINING_WAKE_SEEDS) with base seed 7, and writes every result and
the winner to JSON. The winner's gains are the defaults of accd_gym.control.baselines.GuidanceGains.
"""

import argparse
import itertools
import json
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from accd_gym.control.baselines import GuidancePolicy
from accd_gym.evals.evaluation import run_episodes, summarize
from accd_gym.envs.task import TRAINING_WAKE_SEEDS

GRID = {"kp": [0.08, 0.15, 0.25], "kd": [0.15, 0.25, 0.4], "ki": [0.0, 0.02, 0.05], "kq": [0.05]}


def main() -> None:
    """Runs the grid and writes the JSON."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=32)
    ap.add_argument("--out", default="training/guidance_tuning.json")
    ap.add_argument("--grid", help="the grid as JSON (gain name -> list of values), default: GRID")
    ap.add_argument("--env", default="{}", help="environment config overrides as JSON")
    args = ap.parse_args()
    grid = json.loads(args.grid) if args.grid else GRID
    env = json.loads(args.env)
    seeds = list(range(1000, 1000 + args.episodes))
    assert all(s in TRAINING_WAKE_SEEDS for s in seeds)
    rows = []
    t0 = time.time()
    for values in tqdm(list(itertools.product(*grid.values())), desc="gain sets"):
        gains = dict(zip(grid, values))
        s = summarize(run_episodes(GuidancePolicy(**gains), args.episodes, seed=7, wake_seeds=seeds, num_envs=args.episodes, config=env))
        rows.append({"gains": gains, "capture_rate": s["capture_rate"], "median_miss_m": s["miss_distance_m"]["median"],
                     "mean_abs_action": s["mean_abs_action"], "outcomes": s["outcomes"]})
    best = max(rows, key=lambda r: (r["capture_rate"], -r["median_miss_m"]))
    doc = {"env": env, "wake_seeds": [seeds[0], seeds[-1]], "base_seed": 7, "episodes": args.episodes, "grid": grid,
           "wall_time_s": round(time.time() - t0, 1), "best": best, "results": rows}
    Path(args.out).write_text(json.dumps(doc, indent=1))
    print(json.dumps(best, indent=1))


if __name__ == "__main__":
    main()
