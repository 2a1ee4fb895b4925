"""PPO training throughput (agent steps per second, ``run.json``'s ``steps_per_s``) of a recipe
with the env plain, with residual control, with observation history and with both; short runs,
interleaved rounds, median reported, and the median of each round's ratio to the plain run of the
same round; also per CPU second of the process (every thread), the figure to read on a shared
machine. ``residual (calling thread)``: the residual env with its LQR
base stepped from Python on the calling thread instead of in the batch's threads.

    python scripts/bench_agent_training.py [--config training/residual_ppo_hard.json] [--steps 20000] [--rounds 2]
        [--variants plain,residual]
"""

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

import accd_gym.envs.residual as residual
from accd_gym.learning.training import load_config, train

VARIANTS = {
    "plain": {},
    "residual": {"residual": {"base": "lqr", "scale": 0.3}},
    "history4": {"history": 4},
    "residual+history4": {"residual": {"base": "lqr", "scale": 0.3}, "history": 4},
    "residual (calling thread)": {"residual": {"base": "lqr", "scale": 0.3}},
}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--config", default="training/residual_ppo_hard.json")
    p.add_argument("--steps", type=int, default=20_000)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated names of VARIANTS")
    args = p.parse_args()
    variants = {k: VARIANTS[k] for k in args.variants.split(",")}
    base = load_config(args.config)
    physics = {k: v for k, v in base["env"].items() if k not in ("residual", "history")}
    rates: dict[str, list[float]] = {k: [] for k in variants}
    per_cpu: dict[str, list[float]] = {k: [] for k in variants}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for name, options in variants.items():
                cfg = dict(base, env={**physics, **options}, checkpoint_every=10**9)
                residual.BATCH_BASES = () if "calling thread" in name else ("lqr", "mpc")
                cpu = time.process_time()
                meta = train(cfg, Path(tmp) / f"{name.replace(' ', '_')}_{r}", timesteps=args.steps, progress=False)
                cpu = time.process_time() - cpu
                rates[name].append(meta["steps_per_s"])
                per_cpu[name].append(meta["timesteps"] / cpu)
                print(json.dumps({"round": r, "variant": name, "steps_per_s": meta["steps_per_s"],
                                  "steps_per_cpu_s": round(meta["timesteps"] / cpu, 1), "timesteps": meta["timesteps"],
                                  "loadavg": os.getloadavg()}), flush=True)
    med = {k: float(np.median(v)) for k, v in rates.items()}
    med_cpu = {k: float(np.median(v)) for k, v in per_cpu.items()}
    plain = med.get("plain", float("nan"))
    plain_cpu = med_cpu.get("plain", float("nan"))
    # Rounds swing by up to 10 % on a shared machine: besides the ratio of the medians, the median
    # of each round's ratio to the plain run of the same round (the two ran back to back).
    paired = {k: (float(np.median(np.divide(v, rates["plain"]))) if "plain" in rates else float("nan"))
              for k, v in rates.items()}
    print(json.dumps({k: {"steps_per_s": round(med[k], 1), "vs_plain": round(med[k] / plain, 3), "rounds": v,
                          "vs_plain_paired_median": round(paired[k], 3),
                          "steps_per_cpu_s": round(med_cpu[k], 1), "vs_plain_per_cpu": round(med_cpu[k] / plain_cpu, 3)}
                      for k, v in rates.items()}))
    print(json.dumps({"config": args.config, "num_envs": base["num_envs"], "loadavg": os.getloadavg(),
                      "cpus": os.cpu_count()}))


if __name__ == "__main__":
    main()
