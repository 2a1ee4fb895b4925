"""The episodes of an evaluation, run in batches in one native vector env.

Episode ``k`` of an evaluation is the first episode of a single env seeded ``seed + k`` (initial
conditions and RLV motion; ``seed`` is :data:`EVAL_BASE_SEED` by default) with wake seed
``wake_seeds[k]``: it depends on neither the batch size nor how the index range is split (over
Ray workers, :mod:`accd_gym.evals.distributed`), see :func:`run_episode_range`. A *policy* is any
object with ``predict(obs_batch) -> actions`` ((N, 25) -> (N, 4)) and optionally
``reset(mask)`` (or ``start_episodes(mask, episode_indices)``, :func:`start_policy_episodes`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional, Sequence

import numpy as np

from accd_gym.envs.task import EVENT_NAMES, INFO_NAMES, MAX_ENVS, check_base_seed, check_count
from accd_gym.errors import ConfigError

#: Base seed of evaluation episodes (initial conditions and RLV motion); fixed so runs compare.
EVAL_BASE_SEED: int = 20_240_607
#: Base seed of validation episodes (with :data:`accd_gym.envs.task.VALIDATION_WAKE_SEEDS`):
#: initial conditions other than the held-out evaluation's.
VALIDATION_BASE_SEED: int = 7_340_033


@dataclass
class Episode:
    """One evaluated episode: outcome, metrics and the capture-point-minus-boom trajectory (m)."""

    index: int
    wake_seed: int
    outcome: str
    captured: bool
    steps: int
    time: float
    capture_time: Optional[float]
    min_distance: float
    final_distance: float
    peak_tension: float
    mean_abs_action: float
    mean_abs_delta_action: float
    episode_return: float
    trajectory: np.ndarray
    #: The episode's drawn physical parameters under randomized physics (None otherwise).
    parameters: Optional[dict[str, float]] = None
    #: Closing speed (m/s, of the capture point relative to the boom, from the trajectory) at the
    #: closest approach and at the episode's end (at capture for a captured episode).
    closest_speed: Optional[float] = None
    final_speed: Optional[float] = None

    def metrics(self) -> dict[str, Any]:
        """The episode's numbers as plain JSON values (no trajectory)."""
        return {k: v for k, v in self.__dict__.items() if k != "trajectory"}


def run_episodes(
    policy: Any,
    episodes: int,
    *,
    seed: int = EVAL_BASE_SEED,
    wake_seeds: Optional[Sequence[int]] = None,
    num_envs: int = 16,
    num_threads: int = 0,
    config: Optional[dict[str, Any]] = None,
    progress: bool = False,
    desc: str = "episodes",
) -> list[Episode]:
    """Runs episodes ``0 .. episodes - 1`` of ``policy`` (see :func:`run_episode_range`); returns
    them in index order. ``wake_seeds=None`` draws training wake seeds (for tuning on training
    data). Needs no stable-baselines3."""
    episodes = check_count(episodes, "episodes", 1)
    num_envs = check_count(num_envs, "num_envs", 1, MAX_ENVS)
    return run_episode_range(policy, 0, episodes, seed=seed, wake_seeds=wake_seeds, batch=min(num_envs, episodes),
                             num_threads=num_threads, config=config, progress=progress, desc=desc)


def run_episode_range(
    policy: Any,
    start: int,
    stop: int,
    *,
    seed: int = EVAL_BASE_SEED,
    wake_seeds: Optional[Sequence[int]] = None,
    batch: int = 16,
    num_threads: int = 0,
    config: Optional[dict[str, Any]] = None,
    progress: bool = False,
    desc: str = "episodes",
) -> list[Episode]:
    """Runs episodes ``start .. stop - 1`` of an evaluation; returns them in index order.

    **Episode k** is the first episode of a single env seeded ``seed + k`` (its initial
    conditions and RLV motion) with wake seed ``wake_seeds[k]`` (``wake_seeds`` is indexed by the
    episode index, so it needs at least ``stop`` entries; ``None``: that env's training draw).
    Its physics depends on nothing else: the episodes run ``batch`` at a time in one native
    vector env (:meth:`~accd_gym.InAirCaptureVectorEnv.start_episode` starts the next episode in
    whichever env finished), and an env with no episode left runs a repeat of its last one,
    whose result is dropped, so the policy always sees batches of exactly ``batch`` rows. A
    split of the index range into parts (:mod:`accd_gym.evals.distributed`) therefore gives the same
    episodes bit for bit, provided each part uses the same ``batch`` and the policy's action for
    a row depends on that row alone at a fixed batch size: true of the baselines (``random``
    draws from a stream per episode index) and, as measured here, of PyTorch's MLPs on CPU
    (``tests/test_distributed.py`` checks both; PyTorch gives other last bits for batches of
    1-3 rows than for 4 or more, which is why the batch size is fixed).
    """
    from accd_gym.envs.agent_io import physics_config
    from accd_gym.envs.vector import InAirCaptureVectorEnv

    start, stop = check_count(start, "start", 0), check_count(stop, "stop", 0)
    batch = check_count(batch, "batch", 1, MAX_ENVS)
    if not 0 <= start < stop:
        raise ConfigError(f"invalid config: episode range {start}..{stop} is empty or negative; need 0 <= start < stop")
    seed = check_base_seed(seed, stop, count="episodes")  # episode k is seeded seed + k
    if wake_seeds is not None and len(wake_seeds) < stop:
        raise ConfigError(f"invalid config: {len(wake_seeds)} wake seeds for episodes up to {stop - 1}; need at least {stop}")
    # The env options (residual control, history) are the policy's (SB3Policy applies those of its
    # run): the episodes run on the plain env.
    env = InAirCaptureVectorEnv(batch, autoreset_mode="disabled", num_threads=num_threads, **physics_config(config))
    pending = iter(range(start, stop))
    ep_of = np.full(batch, -1)  # episode index each env runs; -1: a repeat whose result is dropped
    last = np.zeros(batch, dtype=np.int64)  # the last real episode each env ran (repeated when idle)

    def wake_of(k: int) -> Optional[int]:
        return None if wake_seeds is None else int(wake_seeds[k])

    env.reset(seed=[seed + start] * batch)
    params_of: list[Optional[dict[str, float]]] = [None] * batch
    obs = None
    started = np.zeros(batch, dtype=bool)
    for i in range(batch):
        k = next(pending, None)
        ep_of[i] = -1 if k is None else k
        last[i] = start if k is None else k
        obs = env.start_episode(i, seed + int(last[i]), wake_of(int(last[i])))
        params_of[i] = env.episode_parameters(i)
    started[:] = True
    start_policy_episodes(policy, started, ep_of, last)
    # The true boom-relative position (with sensors the observation shows the sensed one).
    rel = env.true_boom_relative()
    traj: list[list[np.ndarray]] = [[-rel[i].astype(np.float32)] for i in range(batch)]
    acts: list[list[np.ndarray]] = [[] for _ in range(batch)]
    mind = np.linalg.norm(rel, axis=1)
    peak = np.zeros(batch)
    ret = np.zeros(batch)
    done_eps: dict[int, Episode] = {}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=stop - start, desc=desc, unit="ep")
    try:
        while len(done_eps) < stop - start:
            actions = np.asarray(policy.predict(obs), dtype=np.float32)
            obs, reward, terminated, truncated, infos = env.step(actions)
            rel = env.true_boom_relative()
            reward = reward.astype(np.float32)  # as stable-baselines3 reports it (returns unchanged)
            dones = terminated | truncated
            for i in range(batch):
                info = {k: infos[k][i] for k in (*INFO_NAMES, "wake_seed")}
                traj[i].append(-rel[i].astype(np.float32))
                acts[i].append(np.clip(actions[i], -1, 1))
                mind[i] = min(mind[i], info["distance"])
                peak[i] = max(peak[i], info["peak_tension"])
                ret[i] += float(reward[i])
                if not dones[i] or ep_of[i] < 0:
                    continue
                a = np.asarray(acts[i])
                da = np.diff(np.vstack([np.zeros((1, a.shape[1])), a]), axis=0)
                outcome = next((e for e in EVENT_NAMES if info[e]), "truncated")
                k = int(ep_of[i])
                done_eps[k] = Episode(
                    index=k,
                    wake_seed=int(info["wake_seed"]),
                    outcome=outcome,
                    captured=bool(info["captured"]),
                    steps=int(info["episode_steps"]),
                    time=float(info["time"]),
                    capture_time=float(info["time"]) if info["captured"] else None,
                    min_distance=float(mind[i]),
                    final_distance=float(info["distance"]),
                    peak_tension=float(peak[i]),
                    mean_abs_action=float(np.abs(a).mean()),
                    mean_abs_delta_action=float(np.abs(da).mean()),
                    episode_return=float(ret[i]),
                    trajectory=np.asarray(traj[i], dtype=np.float32),
                    parameters=params_of[i],
                    **_speeds(traj[i], float(info["time"]), int(info["episode_steps"])),
                )
                if bar is not None:
                    bar.update(1)
            if not dones.any() or len(done_eps) == stop - start:
                continue
            for i in np.flatnonzero(dones):
                k = next(pending, None)
                ep_of[i] = -1 if k is None else k
                if k is not None:
                    last[i] = k
                obs = env.start_episode(int(i), seed + int(last[i]), wake_of(int(last[i])))
                params_of[i] = env.episode_parameters(int(i))
            rel = env.true_boom_relative()
            for i in np.flatnonzero(dones):
                traj[i] = [-rel[i].astype(np.float32)]
                acts[i] = []
                mind[i] = np.linalg.norm(rel[i])
                peak[i] = 0.0
                ret[i] = 0.0
            start_policy_episodes(policy, dones, ep_of, last)
    finally:
        if bar is not None:
            bar.close()
        env.close()
    return [done_eps[k] for k in range(start, stop)]


def _speeds(traj: list[np.ndarray], time: float, steps: int) -> dict[str, Optional[float]]:
    """Relative speed (m/s) at the trajectory's closest point to the boom and at its end, by
    finite differences of the per-step positions (``time / steps`` apart)."""
    p = np.asarray(traj, dtype=np.float64)
    if len(p) < 2 or steps < 1 or time <= 0:
        return {"closest_speed": None, "final_speed": None}
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) / (time / steps)
    k = int(np.argmin(np.linalg.norm(p, axis=1)))
    return {"closest_speed": float(v[max(k - 1, 0)]), "final_speed": float(v[-1])}


def start_policy_episodes(policy: Any, rows: np.ndarray, ep_of: np.ndarray, last: np.ndarray) -> None:
    """Tells ``policy`` that the envs ``rows`` selects started new episodes: ``start_episodes(rows,
    indices)`` when it has it (a policy with per-episode random streams), else ``reset(rows)``."""
    if hasattr(policy, "start_episodes"):
        policy.start_episodes(rows.copy(), np.where(ep_of >= 0, ep_of, last).astype(np.int64))
    elif hasattr(policy, "reset"):
        policy.reset(rows.copy())
