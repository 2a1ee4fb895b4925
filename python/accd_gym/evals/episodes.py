"""The episodes of an evaluation, run in batches in one native vector env.

Episode ``k`` of an evaluation is the first episode of a single env seeded ``seed + k`` (initial
conditions and RLV motion; ``seed`` is :data:`EVAL_BASE_SEED` by default) with wake seed
``wake_seeds[k]``: it depends on neither the batch size nor how the index range is split (over
Ray workers, :mod:`accd_gym.evals.distributed`), see :func:`schedule_episodes`, the episode loop
that evaluation and recording share. A *policy* is an :class:`accd_gym.control.registry.Policy`:
``predict(obs_batch) -> actions`` ((N, 25) -> (N, 4)) and ``reset(mask)`` (or
``start_episodes(mask, episode_indices)``, :func:`start_policy_episodes`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional, Sequence, Iterator, Protocol

import numpy as np
from tqdm import tqdm

from accd_gym.control.registry import Policy
from accd_gym.envs.agent_io import physics_config
from accd_gym.envs.task import EVENT_NAMES, INFO_NAMES, MAX_ENVS, check_base_seed, check_count, check_actions
from accd_gym.envs.vector import InAirCaptureVectorEnv
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
    policy: Policy,
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


class EpisodeObserver(Protocol):
    """What one caller of :func:`schedule_episodes` keeps of its episodes (the evaluation's
    metrics, a recording's samples). Every call sees the vector env running them (its public
    methods only: ``true_boom_relative``, ``episode_parameters``, ``record_data``, ...)."""

    def started(self, env: InAirCaptureVectorEnv, rows: np.ndarray, episodes: np.ndarray, obs: np.ndarray) -> None:
        """The env rows ``rows`` (indices) started episodes ``episodes`` (-1: a repeat whose
        result is dropped); ``obs`` is the batch's observation after the starts."""

    def stepped(self, env: InAirCaptureVectorEnv, actions: np.ndarray, obs: np.ndarray, reward: np.ndarray,
                terminated: np.ndarray, truncated: np.ndarray, infos: dict[str, Any]) -> None:
        """Every row made one agent step with ``actions`` (the policy's, float32, unclipped)."""

    def ended(self, env: InAirCaptureVectorEnv, row: int, episode: int, infos: dict[str, Any]) -> Any:
        """Episode ``episode`` (a wanted one) ended in row ``row`` at the last step; returns
        what :func:`schedule_episodes` yields for it."""


def schedule_episodes(
    policy: Policy,
    episodes: Sequence[int],
    observer: EpisodeObserver,
    *,
    seed: int = EVAL_BASE_SEED,
    wake_seeds: Optional[Sequence[int]] = None,
    batch: int = 16,
    num_threads: int = 0,
    config: Optional[dict[str, Any]] = None,
    true_observation: bool = False,
) -> Iterator[tuple[int, Any]]:
    """Runs the evaluation episodes ``episodes`` (distinct indices) of ``policy`` and yields
    ``(k, observer.ended(...))`` as each ends (in the order they end). The one episode loop of
    the package: evaluation (:func:`run_episode_range`) and recording
    (:func:`accd_gym.replays.recording.iter_recordings`) both run on it, so their episode ``k``
    is the same episode, bit for bit.

    **Episode k** is the first episode of a single env seeded ``seed + k`` (its initial
    conditions and RLV motion) with wake seed ``wake_seeds[k]`` (``wake_seeds`` is indexed by the
    episode index; ``None``: that env's training draw). Its physics depends on nothing else: the
    episodes run ``batch`` at a time in one native vector env
    (:meth:`~accd_gym.InAirCaptureVectorEnv.start_episode` starts the next episode, in increasing
    index order, in whichever env finished), and an env with no episode left runs a repeat of
    its last one, whose result is dropped, so the policy always sees batches of exactly
    ``batch`` rows. The env runs the configuration's physics without the env options
    (``residual``, ``history``): those are the policy's (an :class:`SB3Policy` applies its run's).
    The policy is told of each start (:func:`start_policy_episodes`) with the episode index.
    ``true_observation``: the env keeps the true observation (its env option of that name; the
    observer reads it with ``env.true_observations()`` and in the step's ``infos``); the
    episodes are the same.
    """
    wanted = sorted({int(k) for k in episodes})
    if not wanted:
        return
    batch = check_count(batch, "batch", 1, MAX_ENVS)

    def wake_of(k: int) -> Optional[int]:
        return None if wake_seeds is None else int(wake_seeds[k])

    options = {"true_observation": True} if true_observation else {}
    env = InAirCaptureVectorEnv(batch, autoreset_mode="disabled", num_threads=num_threads, **physics_config(config),
                                **options)
    pending = iter(wanted)
    ep_of = np.full(batch, -1)  # episode index each env runs; -1: a repeat whose result is dropped
    last = np.full(batch, wanted[0], dtype=np.int64)  # the last real episode each env ran (repeated when idle)
    remaining = set(wanted)

    def start(rows: np.ndarray) -> np.ndarray:
        obs = None
        for i in rows:
            k = next(pending, None)
            ep_of[i] = -1 if k is None else k
            if k is not None:
                last[i] = k
            obs = env.start_episode(int(i), seed + int(last[i]), wake_of(int(last[i])))
        observer.started(env, rows, ep_of[rows].copy(), obs)
        mask = np.zeros(batch, dtype=bool)
        mask[rows] = True
        start_policy_episodes(policy, mask, ep_of, last)
        return obs

    # A policy with a Rust stepper (the LQR, the MPC) runs in the batch's threads, each env's
    # command computed right after its step: the same bits as its predict.
    in_batch = hasattr(policy, "batch_stepper")
    if in_batch:
        env.set_controller(policy)
    try:
        env.reset(seed=[seed + wanted[0]] * batch)
        obs = start(np.arange(batch))
        while remaining:
            if in_batch:
                actions = env.controller_commands()
            else:
                actions = check_actions(np.asarray(policy.predict(obs), dtype=np.float32), batch)
            obs, reward, terminated, truncated, infos = env.step(actions)
            observer.stepped(env, actions, obs, reward, terminated, truncated, infos)
            dones = np.flatnonzero(terminated | truncated)
            for i in dones:
                k = int(ep_of[i])
                if k >= 0:
                    remaining.discard(k)
                    yield k, observer.ended(env, int(i), k, infos)
            if remaining and len(dones):
                obs = start(dones)
    finally:
        if in_batch:
            policy.add_batch_stats(env.controller_stats())
        env.close()


class _Metrics:
    """The evaluation's observer: an :class:`Episode` per ended episode."""

    def __init__(self, batch: int, bar: Any) -> None:
        self.bar = bar
        self.traj: list[list[np.ndarray]] = [[] for _ in range(batch)]
        self.acts: list[list[np.ndarray]] = [[] for _ in range(batch)]
        self.params: list[Optional[dict[str, float]]] = [None] * batch
        self.mind = np.zeros(batch)
        self.peak = np.zeros(batch)
        self.ret = np.zeros(batch)

    def started(self, env: InAirCaptureVectorEnv, rows: np.ndarray, episodes: np.ndarray, obs: np.ndarray) -> None:
        """Starts each row's trajectory at the true boom-relative position (with sensors the
        observation shows the sensed one)."""
        rel = env.true_boom_relative()
        for i in rows:
            self.params[i] = env.episode_parameters(int(i))
            self.traj[i] = [-rel[i].astype(np.float32)]
            self.acts[i] = []
            self.mind[i] = np.linalg.norm(rel[i])
            self.peak[i] = 0.0
            self.ret[i] = 0.0

    def stepped(self, env: InAirCaptureVectorEnv, actions: np.ndarray, obs: np.ndarray, reward: np.ndarray,
                terminated: np.ndarray, truncated: np.ndarray, infos: dict[str, Any]) -> None:
        """Extends every row's trajectory, actions, closest approach, peak tension and return."""
        rel = env.true_boom_relative()
        reward = reward.astype(np.float32)  # as stable-baselines3 reports it (returns unchanged)
        for i in range(len(self.traj)):
            self.traj[i].append(-rel[i].astype(np.float32))
            self.acts[i].append(np.clip(actions[i], -1, 1))
            self.mind[i] = min(self.mind[i], infos["distance"][i])
            self.peak[i] = max(self.peak[i], infos["peak_tension"][i])
            self.ret[i] += float(reward[i])

    def ended(self, env: InAirCaptureVectorEnv, row: int, episode: int, infos: dict[str, Any]) -> Episode:
        """The ended episode's :class:`Episode`."""
        i = row
        info = {k: infos[k][i] for k in (*INFO_NAMES, "wake_seed")}
        a = np.asarray(self.acts[i])
        da = np.diff(np.vstack([np.zeros((1, a.shape[1])), a]), axis=0)
        outcome = next((e for e in EVENT_NAMES if info[e]), "truncated")
        if self.bar is not None:
            self.bar.update(1)
        return Episode(
            index=episode,
            wake_seed=int(info["wake_seed"]),
            outcome=outcome,
            captured=bool(info["captured"]),
            steps=int(info["episode_steps"]),
            time=float(info["time"]),
            capture_time=float(info["time"]) if info["captured"] else None,
            min_distance=float(self.mind[i]),
            final_distance=float(info["distance"]),
            peak_tension=float(self.peak[i]),
            mean_abs_action=float(np.abs(a).mean()),
            mean_abs_delta_action=float(np.abs(da).mean()),
            episode_return=float(self.ret[i]),
            trajectory=np.asarray(self.traj[i], dtype=np.float32),
            parameters=self.params[i],
            **_speeds(self.traj[i], float(info["time"]), int(info["episode_steps"])),
        )


def run_episode_range(
    policy: Policy,
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
    """Runs episodes ``start .. stop - 1`` of an evaluation (:func:`schedule_episodes`); returns
    them in index order. ``wake_seeds`` needs at least ``stop`` entries (``None``: training draws).

    A split of the index range into parts (:mod:`accd_gym.evals.distributed`) gives the same
    episodes bit for bit, provided each part uses the same ``batch`` and the policy's action for
    a row depends on that row alone at a fixed batch size: true of the baselines (``random``
    draws from a stream per episode index) and, as measured here, of PyTorch's MLPs on CPU
    (``tests/test_distributed.py`` checks both; PyTorch gives other last bits for batches of
    1-3 rows than for 4 or more, which is why the batch size is fixed).
    """
    start, stop = check_count(start, "start", 0), check_count(stop, "stop", 0)
    batch = check_count(batch, "batch", 1, MAX_ENVS)
    if not 0 <= start < stop:
        raise ConfigError(f"invalid config: episode range {start}..{stop} is empty or negative; need 0 <= start < stop")
    seed = check_base_seed(seed, stop, count="episodes")  # episode k is seeded seed + k
    if wake_seeds is not None and len(wake_seeds) < stop:
        raise ConfigError(f"invalid config: {len(wake_seeds)} wake seeds for episodes up to {stop - 1}; need at least {stop}")
    bar = tqdm(total=stop - start, desc=desc, unit="ep") if progress else None
    try:
        done = dict(schedule_episodes(policy, range(start, stop), _Metrics(batch, bar), seed=seed,
                                      wake_seeds=wake_seeds, batch=batch, num_threads=num_threads, config=config))
    finally:
        if bar is not None:
            bar.close()
    return [done[k] for k in range(start, stop)]


def _speeds(traj: list[np.ndarray], time: float, steps: int) -> dict[str, Optional[float]]:
    """Relative speed (m/s) at the trajectory's closest point to the boom and at its end, by
    finite differences of the per-step positions (``time / steps`` apart)."""
    p = np.asarray(traj, dtype=np.float64)
    if len(p) < 2 or steps < 1 or time <= 0:
        return {"closest_speed": None, "final_speed": None}
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) / (time / steps)
    k = int(np.argmin(np.linalg.norm(p, axis=1)))
    return {"closest_speed": float(v[max(k - 1, 0)]), "final_speed": float(v[-1])}


def start_policy_episodes(policy: Policy, rows: np.ndarray, ep_of: np.ndarray, last: np.ndarray) -> None:
    """Tells ``policy`` that the envs ``rows`` selects started new episodes: ``start_episodes(rows,
    indices)`` when it has it (a policy with per-episode random streams), else ``reset(rows)``."""
    if hasattr(policy, "start_episodes"):
        policy.start_episodes(rows.copy(), np.where(ep_of >= 0, ep_of, last).astype(np.int64))
    elif hasattr(policy, "reset"):
        policy.reset(rows.copy())
