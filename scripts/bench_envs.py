"""Steps per second of the Python envs: the single gymnasium env, gymnasium's SyncVectorEnv of
single envs, the native gymnasium VectorEnv and the native stable-baselines3 VecEnv, for
N = 1, 16, 256 envs. One agent step is ``agent_step / tether.time_step`` physics steps (10 by
default). Random actions are drawn before timing; episodes autoreset (their resets are timed too).

Then, for N = 16 and 256, the two vector envs side by side with the Rust batch they wrap, in one
process and in interleaved rounds (best round per case; ``BatchEnv.time_rust_steps`` runs the
batch's own step loop, as the criterion benchmark ``batch_step`` does): the share of the Rust
batch's speed that each Python env keeps, measured on the same machine in the same minutes.

Usage: python scripts/bench_envs.py [--seconds S] [--threads T] [--config JSON] [--json OUT]

``--config``: env configuration (JSON) for every case, e.g. the fast air scheme
``'{"wake": {"sampling": "per_step"}, "turbulence": {"normal_sampler": "ziggurat", "lane_streams": "per_lane"}}'``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import gymnasium as gym
import numpy as np

import accd_gym

ENV_ID = "accd_gym/InAirCapture-v0"
#: Env configuration of every case (``--config``).
CONFIG: dict = {}


def timed(step, actions, seconds: float) -> tuple[float, int]:
    """Agent steps per env per second: runs ``step`` over ``actions`` (cycled) for ``seconds``."""
    step(actions[0])
    n, t0 = 0, time.perf_counter()
    while True:
        step(actions[n % len(actions)])
        n += 1
        elapsed = time.perf_counter() - t0
        if elapsed >= seconds:
            return n / elapsed, n


def bench_single(seconds: float) -> float:
    """The single env through ``gymnasium.make`` (with its checker wrappers), manual resets."""
    env = gym.make(ENV_ID, **CONFIG)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (256, 4)).astype(np.float32)

    def step(a):
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()

    return timed(step, actions, seconds)[0]


def bench_sync(n: int, seconds: float) -> float:
    """gymnasium's SyncVectorEnv of ``n`` single envs (Python loop over envs)."""
    env = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="sync", **CONFIG)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (64, n, 4)).astype(np.float32)
    return timed(env.step, actions, seconds)[0] * n


def bench_native(n: int, seconds: float, threads: int) -> float:
    """The native gymnasium VectorEnv (``gymnasium.make_vec``)."""
    env = gym.make_vec(ENV_ID, num_envs=n, num_threads=threads, **CONFIG)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (64, n, 4)).astype(np.float32)
    return timed(env.step, actions, seconds)[0] * n


def bench_sb3(n: int, seconds: float, threads: int) -> float:
    """The native stable-baselines3 VecEnv (builds an info dict per env per step)."""
    env = accd_gym.AccdVecEnv(num_envs=n, seed=0, num_threads=threads, **CONFIG)
    env.reset()
    actions = np.random.default_rng(0).uniform(-1, 1, (64, n, 4)).astype(np.float32)

    def step(a):
        env.step_async(a)
        env.step_wait()

    return timed(step, actions, seconds)[0] * n


def _criterion_actions(n: int) -> np.ndarray:
    """The criterion benchmark's fixed actions, ``((k mod 7) - 3) / 4``."""
    k = np.arange(n * 4)
    return (((k % 7) - 3) / 4.0).astype(np.float32).reshape(n, 4)


def side_by_side(n: int, seconds: float, threads: int, rounds: int = 20) -> dict[str, float]:
    """Agent steps/s of the Rust batch, the native VectorEnv and the SB3 AccdVecEnv at ``n`` envs,
    in ``rounds`` interleaved rounds of ``seconds / rounds`` per case (best round of each: on a shared
    machine other load only ever slows a round, so short rounds and the best of many), all with
    the criterion benchmark's fixed actions."""
    from accd_gym import _core
    from accd_gym.envs.config import valid_config

    actions = _criterion_actions(n)
    rust = _core.BatchEnv(valid_config(dict(CONFIG)), n, 0, "same_step", threads)
    rust.reset(0)
    native = gym.make_vec(ENV_ID, num_envs=n, num_threads=threads, **CONFIG)
    native.reset(seed=0)
    sb3 = accd_gym.AccdVecEnv(num_envs=n, seed=0, num_threads=threads, **CONFIG)
    sb3.reset()

    def sb3_step(a):
        sb3.step_async(a)
        sb3.step_wait()

    per_round = seconds / rounds
    # Steps of the Rust loop per round, from a first short run.
    calib = rust.time_rust_steps(actions, 3) / 3
    rust_steps = max(1, round(per_round / max(calib, 1e-6)))
    best = {"rust batch": 0.0, "native VectorEnv": 0.0, "native SB3 AccdVecEnv": 0.0}
    for _ in range(rounds):
        best["rust batch"] = max(best["rust batch"], rust_steps * n / rust.time_rust_steps(actions, rust_steps))
        best["native VectorEnv"] = max(best["native VectorEnv"], timed(native.step, actions[None], per_round)[0] * n)
        best["native SB3 AccdVecEnv"] = max(best["native SB3 AccdVecEnv"], timed(sb3_step, actions[None], per_round)[0] * n)
    native.close()
    sb3.close()
    return best


def main() -> None:
    """Runs every case and prints a markdown table (and writes JSON with ``--json``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="time per case, s (default 5)")
    parser.add_argument("--threads", type=int, default=0, help="threads of the native envs (0: one per core)")
    parser.add_argument("--json", default=None, help="write the results to this JSON file")
    parser.add_argument("--config", default="{}", help="env configuration (JSON) for every case")
    args = parser.parse_args()
    CONFIG.update(json.loads(args.config))
    substeps = round(accd_gym.default_config()["agent_step"] / accd_gym.default_config()["tether"]["time_step"])
    rows = []

    def record(name: str, n: int, rate: float) -> None:
        rows.append({"env": name, "num_envs": n, "agent_steps_per_s": rate, "physics_steps_per_s": rate * substeps})
        print(f"| {name} | {n} | {rate:,.0f} | {rate * substeps:,.0f} |", flush=True)

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}")
    print("| env | N | agent steps/s | physics steps/s |\n|---|---|---|---|")
    record("single env, gymnasium.make", 1, bench_single(args.seconds))
    for n in (1, 16, 256):
        record("native VectorEnv (gymnasium.make_vec)", n, bench_native(n, args.seconds, args.threads))
    for n in (16,):
        record("SyncVectorEnv of single envs", n, bench_sync(n, args.seconds))
    for n in (1, 16, 256):
        record("native SB3 AccdVecEnv", n, bench_sb3(n, args.seconds, args.threads))
    print("\nside by side with the Rust batch (one process, interleaved rounds, best round each)")
    print("| N | Rust batch | native VectorEnv | native SB3 AccdVecEnv | VectorEnv / Rust | SB3 / Rust |\n|---|---|---|---|---|---|")
    beside = {}
    for n in (16, 256):
        b = side_by_side(n, 3 * args.seconds, args.threads)
        beside[str(n)] = b
        r = b["rust batch"]
        print(f"| {n} | {r:,.0f} | {b['native VectorEnv']:,.0f} | {b['native SB3 AccdVecEnv']:,.0f} "
              f"| {b['native VectorEnv'] / r:.3f} | {b['native SB3 AccdVecEnv'] / r:.3f} |", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"substeps": substeps, "rows": rows, "side_by_side": beside}, f, indent=2)


if __name__ == "__main__":
    main()
