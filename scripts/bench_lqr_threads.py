"""Evaluation of the ``lqr`` (or ``mpc``) baseline with its filter stepped per env in the batch's
threads against the calling-thread path (the policy's own ``predict`` from Python, as before
the batch ran it): wall and CPU seconds (the process's, every thread), interleaved rounds, and
whether every episode ended the same (outcome, length, miss distance to the last bit).

    python scripts/bench_lqr_threads.py [--policy lqr] [--tier hard] [--episodes 100] [--rounds 2]
"""

import argparse
import json
import os
import time

from accd_gym.control.registry import make_controller
from accd_gym.envs.overrides import tier
from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS
from accd_gym.evals.episodes import run_episodes


class CallingThread:
    """A policy's predict and reset without its Rust stepper: evaluation steps it from Python."""

    def __init__(self, policy):
        self.policy = policy
        self.name = policy.name

    def predict(self, obs):
        """The policy's commands, stepped on the calling thread."""
        return self.policy.predict(obs)

    def reset(self, mask=None):
        """Restarts the policy's envs in ``mask``."""
        self.policy.reset(mask)


def main() -> None:
    """Runs the rounds and prints one JSON line per run and a summary."""
    p = argparse.ArgumentParser()
    p.add_argument("--policy", default="lqr")
    p.add_argument("--tier", default="hard", help="a tier name, or 'default' for the default task")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--num-envs", type=int, default=16)
    p.add_argument("--rounds", type=int, default=2)
    args = p.parse_args()
    cfg = {} if args.tier == "default" else tier(args.tier).config()
    seeds = list(HELD_OUT_WAKE_SEEDS[: args.episodes])
    results: dict[str, list] = {"batch": [], "calling_thread": []}
    episodes = {}
    for r in range(args.rounds):
        for path in ("batch", "calling_thread"):
            policy = make_controller(args.policy, 0, cfg)
            run = policy if path == "batch" else CallingThread(policy)
            w0, c0 = time.perf_counter(), time.process_time()
            eps = run_episodes(run, args.episodes, wake_seeds=seeds, num_envs=args.num_envs, config=cfg)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            results[path].append({"wall_s": round(wall, 2), "cpu_s": round(cpu, 2)})
            episodes[path] = [(e.outcome, e.steps, float(e.min_distance).hex(), float(e.final_distance).hex())
                              for e in eps]
            print(json.dumps({"round": r, "path": path, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
                              "loadavg": os.getloadavg()}), flush=True)
    print(json.dumps({"policy": args.policy, "tier": args.tier, "episodes": args.episodes, "num_envs": args.num_envs,
                      "same_episodes": episodes["batch"] == episodes["calling_thread"], "runs": results,
                      "cpus": os.cpu_count()}))


if __name__ == "__main__":
    main()
