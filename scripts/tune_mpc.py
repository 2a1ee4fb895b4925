"""Chooses the MPC baseline's horizon, lead and margin (accd_gym.control.mpc.MpcTuning) on VALIDATION wake seeds only.

Usage: python scripts/tune_mpc.py [--episodes 50] [--tiers precision,hard] [--horizons 10,20,30]
       [--leads 0.5] [--margins 0.8] [--confirm 0] [--out training/mpc_tuning.json]

Every (horizon, lead, margin) of the grid (``--leads``: fractions of the horizon, rounded up; the
other settings at MpcTuning's defaults) and the LQR
are flown on the first ``--episodes`` of accd_gym.envs.task.VALIDATION_WAKE_SEEDS (never the
held-out seeds) of each tier with the evaluation's base seed; scored by captures summed over the
tiers (ties: the shorter horizon, the cheaper one, then the larger lead and margin). Records per run the
captures, the median miss distance and closing speed at the closest approach, the outcomes, the
solve counts, the policy's CPU time per env step (the controller alone, process time of its
``predict`` calls) and the wall time per env step including the physics, to JSON. Timings are of
this machine with whatever else runs on it: rough costs. ``--confirm N`` then flies the chosen
tuning and the LQR on the next N validation wake seeds, which the choice did not see.
"""

import argparse
import itertools
import json
import math
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


class _Timed:
    """Wraps a policy's ``predict``/``predict_rows`` to sum their process time."""

    def __init__(self, policy):
        self.policy, self.cpu_s, self.rows = policy, 0.0, 0

    def __getattr__(self, name):
        attr = getattr(self.policy, name)
        if name not in ("predict", "predict_rows"):
            return attr

        def timed(obs, *args, **kwargs):
            t0 = time.process_time()
            out = attr(obs, *args, **kwargs)
            self.cpu_s += time.process_time() - t0
            self.rows += len(out)
            return out

        return timed


def _fly(policy, cfg, seeds):
    timed = _Timed(policy)
    t0 = time.perf_counter()
    eps = run_episodes(timed, len(seeds), seed=EVAL_BASE_SEED, wake_seeds=seeds, num_envs=16, config=cfg)
    wall = time.perf_counter() - t0
    s = summarize(eps)
    steps = sum(e.steps for e in eps)
    row = {"captured": sum(bool(e.captured) for e in eps), "episodes": len(eps), "capture_rate": s["capture_rate"],
           "median_miss_m": s["miss_distance_m"]["median"],
           "median_closest_speed_mps": float(np.median([e.closest_speed for e in eps if e.closest_speed is not None] or [np.nan])),
           "outcomes": s["outcomes"], "wall_s": round(wall, 2),
           "us_per_env_step_incl_physics": round(1e6 * wall / steps, 1),
           "policy_cpu_us_per_env_step": round(1e6 * timed.cpu_s / max(timed.rows, 1), 1)}
    if isinstance(policy, MpcPolicy):
        row["solves"] = policy.stats
    return row


def main() -> None:
    """Runs the sweep and writes the JSON."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--tiers", default="precision,hard")
    ap.add_argument("--horizons", default="10,20,30")
    ap.add_argument("--leads", default="0.5")
    ap.add_argument("--margins", default="0.8")
    ap.add_argument("--confirm", type=int, default=0)
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
    grid = itertools.product([int(x) for x in args.horizons.split(",")], [float(x) for x in args.leads.split(",")],
                             [float(x) for x in args.margins.split(",")])
    for h, lf, m in grid:
        tuning = MpcTuning(horizon=h, lead=max(1, min(h, math.ceil(lf * h))), margin=m)
        row = {"tuning": asdict(tuning), "tiers": {}}
        for t in tiers:
            row["tiers"][t] = _fly(MpcPolicy.for_config(tier(t).config(), tuning=tuning), tier(t).config(), seeds)
            print("mpc", asdict(tuning), t, row["tiers"][t], flush=True)
        row["captured"] = sum(r["captured"] for r in row["tiers"].values())
        rows.append(row)
    best = max(rows, key=lambda r: (r["captured"], -r["tuning"]["horizon"], r["tuning"]["lead"], r["tuning"]["margin"]))
    doc = {"policy": "mpc", "wake_seeds": "VALIDATION_WAKE_SEEDS[:%d]" % args.episodes, "base_seed": EVAL_BASE_SEED,
           "tiers": tiers, "lqr": results["lqr"], "best": best, "results": rows}
    if args.confirm:
        fresh = list(VALIDATION_WAKE_SEEDS[args.episodes: args.episodes + args.confirm])
        assert not set(fresh) & set(HELD_OUT_WAKE_SEEDS)
        tuning = MpcTuning(**best["tuning"])
        doc["confirmation"] = {"wake_seeds": "VALIDATION_WAKE_SEEDS[%d:%d]" % (args.episodes, args.episodes + args.confirm)}
        for t in tiers:
            cfg = tier(t).config()
            doc["confirmation"][t] = {"mpc": _fly(MpcPolicy.for_config(cfg, tuning=tuning), cfg, fresh),
                                      "lqr": _fly(LqrPolicy.for_config(cfg), cfg, fresh)}
            print("confirmation", t, doc["confirmation"][t], flush=True)
    Path(args.out).write_text(json.dumps(doc, indent=1))
    print(json.dumps({"best": best["tuning"], "captured": best["captured"]}))


if __name__ == "__main__":
    main()
