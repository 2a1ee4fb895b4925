"""Measures what the Ray paths cost (docs/scaling.md): held-out evaluation locally and as Ray
tasks on 1 and 2 workers, and RLlib PPO's training steps per second next to stable-baselines3
PPO's at the same env count. Prints one JSON document; run with the ray extra installed.

    python scripts/bench_ray.py --episodes 1000 --workers 1 2 --train-steps 65536
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _eval_child(workers: int, episodes: int, policy: str) -> dict:
    """One evaluation in a fresh process (a Ray instance of ``workers`` CPUs, or none for 0)."""
    code = f"""
import json, time
import accd_gym
from accd_gym.evals.evaluation import load_policy, run_episodes, summarize
from accd_gym.evals import distributed
seeds = list(accd_gym.HELD_OUT_WAKE_SEEDS[:{episodes}])
policy = load_policy({policy!r})
if {workers} == 0:
    t = time.perf_counter()
    eps = run_episodes(policy, {episodes}, wake_seeds=seeds, num_envs=16, num_threads=1)
    wall, info = time.perf_counter() - t, {{}}
else:
    distributed.connect("local", num_cpus={workers})
    t = time.perf_counter()
    runs, info = distributed.run_policies({{"p": policy}}, {episodes}, seed=accd_gym.evals.episodes.EVAL_BASE_SEED,
                                          wake_seeds=seeds, num_envs=16)
    wall, eps = time.perf_counter() - t, runs["p"]
s = summarize(eps)
print(json.dumps({{"wall_s": wall, "captures": s["captures"], "steps": sum(e.steps for e in eps),
                  "tasks": len(info.get("tasks", [])), "episodes_per_task": info.get("episodes_per_task"),
                  "task_wall_s_sum": sum(t["wall_time_s"] for t in info.get("tasks", []))}}))
"""
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    doc = json.loads(out.stdout.strip().splitlines()[-1])
    doc["process_wall_s"] = time.perf_counter() - t0
    return doc


def _train(trainer: str, steps: int) -> dict:
    """Steps per second of one short training run (a fresh process each)."""
    out_dir = tempfile.mkdtemp(prefix=f"bench_{trainer}_")
    config = "training/rllib_ppo.json" if trainer == "rllib" else "training/ppo.json"
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "accd_gym", "train", "--config", config, "--out", out_dir,
                    "--timesteps", str(steps), "--quiet"], check=True, capture_output=True, cwd=ROOT)
    meta = json.loads((Path(out_dir) / "run.json").read_text())
    return {"trainer": trainer, "timesteps": meta["timesteps"], "wall_time_s": meta["wall_time_s"],
            "steps_per_s": meta["steps_per_s"], "process_wall_s": round(time.perf_counter() - t0, 1), "load": _load()}


def main() -> None:
    """Runs the measurements the command line selects and prints them as JSON."""
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--episodes", type=int, default=1000)
    p.add_argument("--workers", type=int, nargs="*", default=[1, 2], help="Ray worker counts (0: local, no Ray)")
    p.add_argument("--policy", default="guidance")
    p.add_argument("--train-steps", type=int, default=65536, help="0 skips the training comparison")
    args = p.parse_args()
    doc = {"machine": f"{platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} cores",
           "command": " ".join([Path(sys.executable).name, *sys.argv]), "evaluation": [], "training": []}
    for w in args.workers:
        load = _load()
        r = _eval_child(w, args.episodes, args.policy)
        doc["evaluation"].append({"workers": w, "episodes": args.episodes, "policy": args.policy, "load_before": load,
                                  "load_after": _load(), **r, "episodes_per_s": round(args.episodes / r["wall_s"], 2)})
        print(json.dumps(doc["evaluation"][-1]), file=sys.stderr)
    if args.train_steps:
        for trainer in ("sb3", "rllib"):
            doc["training"].append(_train(trainer, args.train_steps))
            print(json.dumps(doc["training"][-1]), file=sys.stderr)
    print(json.dumps(doc, indent=1))


if __name__ == "__main__":
    main()
