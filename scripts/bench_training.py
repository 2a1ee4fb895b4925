"""Training throughput of PPO with ``training/ppo.json`` and where its time goes.

Trains for ``--timesteps`` agent steps with the recipe's hyperparameters (16 envs, rollouts of
16 x 256 steps, 5 epochs of minibatches of 1024) and splits the wall time into

* **env**: ``AccdVecEnv.step_wait`` / ``reset`` (the Rust physics with the Python layer),
* **wrappers**: VecMonitor and VecNormalize around it,
* **gradient updates**: ``PPO.train`` (the epochs over the rollout buffer),
* **inference and SB3 collection**: the rest of ``collect_rollouts`` (policy forward passes,
  the rollout buffer, callbacks).

Also runs the same PPO on a zero-cost VecEnv with our spaces (the ceiling SB3 and torch allow on
this machine). ``--env JSON`` sets the env configuration (e.g. the fast air scheme),
``--torch-threads``, ``--update-threads`` and ``--num-threads`` the split of cores between torch
(while the envs step / in the gradient updates) and the env pool.

    python scripts/bench_training.py [--timesteps 65536] [--env JSON] [--torch-threads 1] [--update-threads N]
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Optional

import numpy as np


def _zero_env(num_envs: int):
    """A VecEnv with our spaces whose step costs nothing (constant observations, zero reward)."""
    from stable_baselines3.common.vec_env import VecEnv

    from accd_gym.envs.task import action_space, observation_space

    class ZeroVecEnv(VecEnv):
        """Constant observations, zero rewards, episodes of 700 steps."""

        def __init__(self) -> None:
            super().__init__(num_envs, observation_space(), action_space())
            self.render_mode = None
            self._t = 0
            self._obs = np.zeros((num_envs, observation_space().shape[0]), np.float32)

        def reset(self):
            return self._obs.copy()

        def step_async(self, actions) -> None:
            pass

        def step_wait(self):
            self._t += 1
            done = np.full(self.num_envs, self._t % 700 == 0)
            infos = [{"terminal_observation": self._obs[i]} if done[i] else {} for i in range(self.num_envs)]
            return self._obs.copy(), np.zeros(self.num_envs, np.float32), done, infos

        def close(self) -> None:
            pass

        def get_attr(self, name, indices=None):
            return [getattr(self, name)] * self.num_envs

        def set_attr(self, name, value, indices=None) -> None:
            pass

        def env_method(self, name, *args, indices=None, **kwargs):
            return [None] * self.num_envs

        def env_is_wrapped(self, wrapper_class, indices=None):
            return [False] * self.num_envs

        def seed(self, seed=None):
            return [None] * self.num_envs

    return ZeroVecEnv()


def run(timesteps: int, env_config: dict, torch_threads: int, num_threads: int, zero: bool,
        update_threads: Optional[int] = None) -> dict:
    """Trains PPO for ``timesteps`` steps; returns steps/s and the time split (s)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from accd_gym.envs.sb3 import AccdVecEnv
    from accd_gym.learning.training import _policy_kwargs, _thread_split, load_config

    cfg = load_config("training/ppo.json")
    if update_threads is None:
        update_threads = cfg["update_threads"]
    torch.set_num_threads(torch_threads)
    timing = {"env": 0.0, "train": 0.0, "collect": 0.0}
    base = _zero_env(cfg["num_envs"]) if zero else AccdVecEnv(num_envs=cfg["num_envs"], seed=0, num_threads=num_threads, **env_config)
    step_wait = base.step_wait

    def timed_step_wait():
        t = time.perf_counter()
        out = step_wait()
        timing["env"] += time.perf_counter() - t
        return out

    base.step_wait = timed_step_wait
    env = VecNormalize(VecMonitor(base), gamma=cfg["algo_kwargs"]["gamma"], **cfg["vec_normalize"])
    model = PPO("MlpPolicy", env, seed=0, device="cpu", policy_kwargs=_policy_kwargs(cfg), **cfg["algo_kwargs"])
    train, collect = model.train, model.collect_rollouts

    def timed_train():
        t = time.perf_counter()
        train()
        timing["train"] += time.perf_counter() - t

    def timed_collect(*a, **k):
        t = time.perf_counter()
        out = collect(*a, **k)
        timing["collect"] += time.perf_counter() - t
        return out

    model.train, model.collect_rollouts = timed_train, timed_collect
    t0 = time.perf_counter()
    # The split of threads as training.train makes it (update_threads 0: torch_threads throughout).
    model.learn(timesteps, callback=_thread_split(torch_threads, update_threads))
    wall = time.perf_counter() - t0
    steps = model.num_timesteps
    return {
        "agent_steps_per_s": steps / wall,
        "wall_s": wall,
        "env_s": timing["env"],
        "gradient_updates_s": timing["train"],
        "inference_and_collection_s": timing["collect"] - timing["env"],
        "other_s": wall - timing["collect"] - timing["train"],
    }


def main() -> None:
    """Prints the throughput and the time split as a markdown table and JSON."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--timesteps", type=int, default=65_536)
    p.add_argument("--env", default="{}", help="env configuration, JSON")
    p.add_argument("--torch-threads", type=int, default=1)
    p.add_argument("--update-threads", type=int, default=None,
                   help="torch threads in the gradient updates (default: the recipe's update_threads; 0: --torch-threads)")
    p.add_argument("--num-threads", type=int, default=0, help="env pool threads (0: one per core)")
    p.add_argument("--json", help="write the results here")
    a = p.parse_args()
    out = {}
    for name, zero in (("accd env", False), ("zero-cost VecEnv", True)):
        r = run(a.timesteps, json.loads(a.env), a.torch_threads, a.num_threads, zero, a.update_threads)
        out[name] = r
        print(
            f"| {name} | {r['agent_steps_per_s']:,.0f} | {r['env_s']:.1f} | {r['inference_and_collection_s']:.1f} "
            f"| {r['gradient_updates_s']:.1f} | {r['other_s']:.1f} | {r['wall_s']:.1f} |",
            flush=True,
        )
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=2)


if __name__ == "__main__":
    main()
