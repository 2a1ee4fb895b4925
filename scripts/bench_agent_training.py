"""PPO training throughput (agent steps per second, ``run.json``'s ``steps_per_s``) of a recipe
with the env plain, with residual control, with observation history and with both; short runs,
interleaved rounds, median reported.

    python scripts/bench_agent_training.py [--config training/residual_ppo_hard.json] [--steps 20000] [--rounds 2]
"""

import argparse
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from accd_gym.learning.training import load_config, train

VARIANTS = {
    "plain": {},
    "residual": {"residual": {"base": "lqr", "scale": 0.3}},
    "history4": {"history": 4},
    "residual+history4": {"residual": {"base": "lqr", "scale": 0.3}, "history": 4},
}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--config", default="training/residual_ppo_hard.json")
    p.add_argument("--steps", type=int, default=20_000)
    p.add_argument("--rounds", type=int, default=2)
    args = p.parse_args()
    base = load_config(args.config)
    physics = {k: v for k, v in base["env"].items() if k not in ("residual", "history")}
    rates: dict[str, list[float]] = {k: [] for k in VARIANTS}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for name, options in VARIANTS.items():
                cfg = dict(base, env={**physics, **options}, checkpoint_every=10**9)
                meta = train(cfg, Path(tmp) / f"{name}_{r}", timesteps=args.steps, progress=False)
                rates[name].append(meta["steps_per_s"])
                print(json.dumps({"round": r, "variant": name, "steps_per_s": meta["steps_per_s"],
                                  "timesteps": meta["timesteps"]}), flush=True)
    med = {k: float(np.median(v)) for k, v in rates.items()}
    print(json.dumps({k: {"steps_per_s": round(med[k], 1), "vs_plain": round(med[k] / med["plain"], 3), "rounds": v}
                      for k, v in rates.items()}))
    print(json.dumps({"config": args.config, "num_envs": base["num_envs"], "loadavg": os.getloadavg(),
                      "cpus": os.cpu_count()}))


if __name__ == "__main__":
    main()
