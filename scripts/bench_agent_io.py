"""Env steps per second of AccdVecEnv plain, with residual control (LQR base), with observation
history, and with both, at several batch sizes; interleaved rounds, median reported.

Every variant steps the same episodes: the residual envs get random corrections in [-1, 1]
(seeded), and the plain and history envs replay the flap commands the residual env sent, from
the same seed, so the physics, the episode ends and the resets are the same and the difference
is the cost of the option. Besides wall-clock rates it reports rates per CPU second of the
process (all its threads): on a shared, busy machine the wall clock measures the other
processes as much as this one.

    python scripts/bench_agent_io.py [--num-envs 16 64] [--steps 300] [--rounds 3] [--tier hard]
"""

import argparse
import json
import os
import time

import numpy as np

from accd_gym import AccdVecEnv

RESIDUAL = {"base": "lqr", "scale": 0.3}
VARIANTS = {
    "plain": {},
    "residual": {"residual": RESIDUAL},
    "history4": {"history": 4},
    "residual+history4": {"residual": RESIDUAL, "history": 4},
}


def run(env: AccdVecEnv, actions: np.ndarray, seed: int) -> tuple[float, float, np.ndarray]:
    """(env steps per wall-clock second, per CPU second, the flap commands sent)."""
    env.seed(seed)
    env.reset()
    sent = np.empty_like(actions)
    io = env._agent_io
    t0, c0 = time.perf_counter(), time.process_time()
    for k, a in enumerate(actions):
        env.step(a)
        if io is not None:
            sent[k] = io._sent  # (the command of this step; read for the replay, not timed apart)
    w, c = time.perf_counter() - t0, time.process_time() - c0
    n = actions.shape[0] * env.num_envs
    return n / w, n / c, sent if io is not None else actions


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--num-envs", type=int, nargs="+", default=[16, 64])
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--tier", default="hard")
    p.add_argument("--num-threads", type=int, default=0)
    args = p.parse_args()
    rng = np.random.default_rng(0)
    for n in args.num_envs:
        envs = {k: AccdVecEnv(n, seed=0, num_threads=args.num_threads, tier=args.tier, **v) for k, v in VARIANTS.items()}
        wall: dict[str, list[float]] = {k: [] for k in envs}
        cpu: dict[str, list[float]] = {k: [] for k in envs}
        run(envs["residual"], np.zeros((5, n, 4), np.float32), 0)  # warm-up: the LQR design is cached per process
        for r in range(args.rounds + 1):
            corrections = rng.uniform(-1, 1, (args.steps, n, 4)).astype(np.float32)
            rw, rc, sent = run(envs["residual"], corrections, r)
            out = {"residual": (rw, rc)}
            out["residual+history4"] = run(envs["residual+history4"], corrections, r)[:2]
            out["plain"] = run(envs["plain"], sent, r)[:2]
            out["history4"] = run(envs["history4"], sent, r)[:2]
            if r == 0:
                continue  # warm-up round
            for k, (w, c) in out.items():
                wall[k].append(w)
                cpu[k].append(c)
        med = {k: float(np.median(v)) for k, v in wall.items()}
        medc = {k: float(np.median(v)) for k, v in cpu.items()}
        print(json.dumps({"num_envs": n, **{k: {
            "steps_per_s": round(med[k]), "vs_plain": round(med[k] / med["plain"], 3),
            "steps_per_cpu_s": round(medc[k]), "cpu_vs_plain": round(medc[k] / medc["plain"], 3),
            "rounds": [round(x) for x in wall[k]]} for k in envs}}), flush=True)
    print(json.dumps({"loadavg": os.getloadavg(), "cpus": os.cpu_count()}))


if __name__ == "__main__":
    main()
