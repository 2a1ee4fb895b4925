"""Chooses the MPC baseline's horizon (accd_gym.control.mpc.MpcTuning) on VALIDATION wake seeds only.

Usage: python scripts/tune_mpc.py [--episodes 50] [--tiers precision,hard] [--horizons 10,20,40]
       [--out training/mpc_tuning.json]

Every horizon (the other settings at MpcTuning's defaults) and the LQR are flown on the first
``--episodes`` of accd_gym.envs.task.VALIDATION_WAKE_SEEDS (never the held-out seeds) of each tier
with the evaluation's base seed; scored by captures summed over the tiers (ties: the shorter
horizon, the cheaper one). Records captures, the median miss distance and closing speed at the closest approach, the outcomes, the solve
counts and the wall time per agent step and env including the physics (on this machine, whatever
else runs: a rough cost) to JSON.
"""

import argparse
import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from accd_gym.control.lqr import LqrPolicy
from accd_gym.control.mpc import MpcPolicy, MpcTuning
from accd_gym.envs.overrides import tier
from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS, VALIDATION_WAKE_SEEDS
from accd_gym.evals.episodes import EVAL_BASE_SEED, run_episodes
from accd_gym.evals.evaluation import summarize


def _fly(policy, cfg, seeds):
    t0 = time.perf_counter()
    eps = run_episodes(policy, len(seeds), seed=EVAL_BASE_SEED, wake_seeds=seeds, num_envs=16, config=cfg)
    wall = time.perf_counter() - t0
    s = summarize(eps)
    steps = sum(e.steps for e in eps)
    row = {"captured": sum(bool(e.captured) for e in eps), "episodes": len(eps), "capture_rate": s["capture_rate"],
           "median_miss_m": s["miss_distance_m"]["median"],
           "median_closest_speed_mps": float(np.median([e.closest_speed for e in eps if e.closest_speed is not None] or [np.nan])),
           "outcomes": s["outcomes"], "wall_s": round(wall, 2)}
    row["us_per_env_step_incl_physics"] = round(1e6 * wall / steps, 1)
    if isinstance(policy, MpcPolicy):
        row["solves"] = policy.stats
    return row


def main() -> None:
    """Runs the sweep and writes the JSON."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--tiers", default="precision,hard")
    ap.add_argument("--horizons", default="10,20,40")
    ap.add_argument("--out", default="training/mpc_tuning.json")
    args = ap.parse_args()
    seeds = list(VALIDATION_WAKE_SEEDS[: args.episodes])
    assert not set(seeds) & set(HELD_OUT_WAKE_SEEDS)
    tiers = args.tiers.split(",")
    results: dict = {"lqr": {}}
    for t in tiers:
        results["lqr"][t] = _fly(LqrPolicy.for_config(tier(t).config()), tier(t).config(), seeds)
        print("lqr", t, results["lqr"][t], flush=True)
    rows = []
    for h in (int(x) for x in args.horizons.split(",")):
        tuning = MpcTuning(horizon=h)
        row = {"tuning": asdict(tuning), "tiers": {}}
        for t in tiers:
            row["tiers"][t] = _fly(MpcPolicy.for_config(tier(t).config(), tuning=tuning), tier(t).config(), seeds)
            print("mpc", h, t, row["tiers"][t], flush=True)
        row["captured"] = sum(r["captured"] for r in row["tiers"].values())
        rows.append(row)
    best = max(rows, key=lambda r: (r["captured"], -r["tuning"]["horizon"]))
    doc = {"policy": "mpc", "wake_seeds": "VALIDATION_WAKE_SEEDS[:%d]" % args.episodes, "base_seed": EVAL_BASE_SEED,
           "tiers": tiers, "lqr": results["lqr"], "best": best, "results": rows}
    Path(args.out).write_text(json.dumps(doc, indent=1))
    print(json.dumps({"best_horizon": best["tuning"]["horizon"], "captured": best["captured"]}))


if __name__ == "__main__":
    main()
