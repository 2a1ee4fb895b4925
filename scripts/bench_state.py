"""Size and time of env snapshots: ``get_state``, ``set_state`` and a pickle round trip of a
vector env, best of several rounds. Runs against whatever ``accd_gym`` is importable, so the same
script measures the old and the new state format.

    python scripts/bench_state.py [--num-envs 16] [--rounds 20]
"""

from __future__ import annotations

import argparse
import pickle
import time

import numpy as np

import accd_gym


def best(f, rounds: int) -> float:
    """Smallest wall time of ``rounds`` calls of ``f``, s."""
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    """Prints one line per measurement."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--rounds", type=int, default=20)
    args = parser.parse_args()
    env = accd_gym.InAirCaptureVectorEnv(args.num_envs, num_threads=1, initial={"settle_time": 5.0})
    env.reset(seed=1)
    for k in range(20):
        env.step(np.full((args.num_envs, 4), 0.1 * np.sin(k), np.float32))
    state = env.get_state()
    get = best(env.get_state, args.rounds)
    put = best(lambda: env.set_state(state), args.rounds)
    blob = pickle.dumps(env)
    unpickle = best(lambda: pickle.loads(blob), max(3, args.rounds // 5))
    n = args.num_envs
    print(f"num_envs {n}: state {len(state)} bytes ({len(state) / n / 1024:.1f} KiB per env)")
    print(f"get_state {get * 1e3:.2f} ms ({get / n * 1e3:.3f} ms per env)")
    print(f"set_state {put * 1e3:.2f} ms ({put / n * 1e3:.3f} ms per env)")
    print(f"pickle.loads (builds the env, settles, restores) {unpickle * 1e3:.0f} ms")


if __name__ == "__main__":
    main()
