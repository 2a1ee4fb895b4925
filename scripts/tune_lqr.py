"""Tunes the LQR baseline (accd_gym.control.lqr.LqrTuning) by a grid search on TRAINING wake seeds only.

Usage: python scripts/tune_lqr.py [--episodes 48] [--env JSON] [--grid JSON] [--base JSON]
       [--out training/lqr_tuning.json]

Every tuning of the grid (the ``--base`` tuning with the grid's keys replaced) is designed for the
``--env`` configuration and scored on wake seeds 2000..2000+episodes-1 (inside
TRAINING_WAKE_SEEDS; the held-out seeds are never touched) with base seed 7, by capture rate
(ties: lower median miss distance). Writes every result, the grid and the winner to JSON
(``"policy": "lqr"``, so the file is also a policy spec for ``accd-gym evaluate --policy``).
"""

import argparse
import itertools
import json
import time
from dataclasses import asdict, replace
from pathlib import Path

from tqdm import tqdm

from accd_gym.evals.evaluation import run_episodes, summarize
from accd_gym.control.lqr import LqrPolicy, LqrTuning
from accd_gym.envs.task import TRAINING_WAKE_SEEDS

GRID = {"q_velocity": [0.3, 1.0, 3.0], "r_flap": [0.3, 1.0, 3.0]}
FIRST_SEED = 2000
BASE_SEED = 7


def main() -> None:
    """Runs the grid and writes the JSON."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=48)
    ap.add_argument("--out", default="training/lqr_tuning.json")
    ap.add_argument("--grid", help="the grid as JSON (tuning key -> list of values), default: GRID")
    ap.add_argument("--base", default="{}", help="the tuning the grid varies, as JSON (default: LqrTuning())")
    ap.add_argument("--env", default="{}", help="environment config overrides as JSON")
    ap.add_argument("--note", default="", help="a description stored in the file")
    args = ap.parse_args()
    grid = json.loads(args.grid) if args.grid else GRID
    env = json.loads(args.env)
    base = LqrTuning.from_mapping(json.loads(args.base))
    seeds = list(range(FIRST_SEED, FIRST_SEED + args.episodes))
    assert all(s in TRAINING_WAKE_SEEDS for s in seeds)
    rows = []
    t0 = time.time()
    for values in tqdm(list(itertools.product(*grid.values())), desc="tunings"):
        tuning = replace(base, **dict(zip(grid, values)))
        policy = LqrPolicy.for_config(env, tuning=tuning)
        s = summarize(run_episodes(policy, args.episodes, seed=BASE_SEED, wake_seeds=seeds, num_envs=min(args.episodes, 16),
                                   config=env))
        rows.append({"tuning": asdict(tuning), "capture_rate": s["capture_rate"], "median_miss_m": s["miss_distance_m"]["median"],
                     "mean_abs_action": s["mean_abs_action"], "outcomes": s["outcomes"],
                     "closed_loop_radius": policy.design.closed_loop_radius, "observer_radius": policy.design.observer_radius})
        print(json.dumps({k: rows[-1][k] for k in ("capture_rate", "median_miss_m")}), dict(zip(grid, values)), flush=True)
    best = max(rows, key=lambda r: (r["capture_rate"], -r["median_miss_m"]))
    doc = {"policy": "lqr", "note": args.note, "env": env, "wake_seeds": [seeds[0], seeds[-1]], "base_seed": BASE_SEED,
           "episodes": args.episodes, "base": asdict(base), "grid": grid, "wall_time_s": round(time.time() - t0, 1),
           "best": best, "results": rows}
    Path(args.out).write_text(json.dumps(doc, indent=1))
    print(json.dumps(best, indent=1))


if __name__ == "__main__":
    main()
