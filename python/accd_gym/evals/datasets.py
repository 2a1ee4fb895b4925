"""Expert datasets in the Farama standard: episodes of any policy as a Minari dataset.

``accd-gym dataset --policy NAME --tier TIER --episodes N --out DIR`` calls :func:`record_dataset`:
the policy (anything :func:`accd_gym.evals.policies.load_policy` resolves: a controller, a shipped
or trained policy) runs ``N`` episodes of the tier on the one episode loop
(:func:`accd_gym.evals.episodes.schedule_episodes`), and Minari's own
``minari.create_dataset_from_buffers`` stores them under ``DIR`` (Minari's dataset root, as
``MINARI_DATASETS_PATH`` would set it) with the id ``accd/<tier>/<policy>-v0``.

**Episodes.** Episode k: initial conditions and RLV motion from seed ``seed + k`` and wake seed
:data:`DATASET_WAKE_SEEDS` ``[k]``, the training wake seeds without the validation ones (never a
held-out or validation wake seed: a dataset is training data). Episode k is, bit for bit, episode
k of ``run_episodes(policy, N, seed=seed, wake_seeds=DATASET_WAKE_SEEDS)``.

**Contents** (per episode, Minari's layout): ``observations`` (steps + 1, 25) float32, the tier's
observation (sensed on the sensor tiers), first the reset's; ``actions`` (steps, 4) float32, the
flap commands the env applied (the policy's action clipped to [-1, 1]); ``rewards`` float64;
``terminations``, ``truncations``; ``infos`` with ``true_obs`` (steps + 1, 25) float32, the
noise-free, delay-free observation (the env option ``true_observation``), when
``true_observation``. The dataset's env spec is the tier's registered id, so
``dataset.recover_environment()`` makes the env.

Needs the ``dataset`` extra (``pip install 'accd-gym[dataset]'``: minari with its HDF5 storage).
Minari writes the dataset's files itself; the output folder is checked writable before any
episode runs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
from pathlib import Path
from typing import Any, Iterator, Optional

import gymnasium as gym
import numpy as np

from accd_gym import files
from accd_gym.envs.task import ACT_DIM, MAX_ENVS, OBS_DIM, TRAINING_WAKE_SEEDS, VALIDATION_WAKE_SEEDS, check_count
from accd_gym.envs.tiers import TIERS
from accd_gym.envs.vector import InAirCaptureVectorEnv
from accd_gym.errors import ConfigError
from accd_gym.evals.episodes import schedule_episodes
from accd_gym.evals.policies import load_policy

#: The wake seeds of dataset episodes: the training wake seeds without the validation ones
#: (:data:`accd_gym.envs.task.VALIDATION_WAKE_SEEDS`, the tail of the training range).
DATASET_WAKE_SEEDS: range = TRAINING_WAKE_SEEDS[: len(TRAINING_WAKE_SEEDS) - len(VALIDATION_WAKE_SEEDS)]
#: Base seed of dataset episodes (initial conditions and RLV motion), by default.
DATASET_BASE_SEED: int = 0
#: The namespace of the datasets' ids.
NAMESPACE = "accd"


def dataset_id(tier: str, policy: str) -> str:
    """The Minari id of a tier's dataset of ``policy``: ``accd/<tier>/<policy>-v0`` (the policy's
    name, or a path's last part, in Minari's allowed characters)."""
    name = re.sub(r"[^A-Za-z0-9_]+", "_", Path(policy).name.removesuffix(".zip").removesuffix(".json")).strip("_")
    return f"{NAMESPACE}/{tier}/{name or 'policy'}-v0"


class _Buffers:
    """The episode loop's observer that keeps every sample of each episode in Minari's layout."""

    def __init__(self, batch: int, true_observation: bool) -> None:
        self.true_observation = true_observation
        self.rows: list[Optional[dict[str, list[Any]]]] = [None] * batch

    def started(self, env: InAirCaptureVectorEnv, rows: np.ndarray, episodes: np.ndarray, obs: np.ndarray) -> None:
        """Starts a buffer for each row that runs a wanted episode (none for a repeat)."""
        true_obs = env.true_observations() if self.true_observation else None
        for i, k in zip(rows, episodes):
            if k < 0:
                self.rows[i] = None
                continue
            self.rows[i] = {"observations": [obs[i].copy()], "actions": [], "rewards": [], "terminations": [],
                            "truncations": [], "true_obs": [] if true_obs is None else [true_obs[i].copy()]}

    def stepped(self, env: InAirCaptureVectorEnv, actions: np.ndarray, obs: np.ndarray, reward: np.ndarray,
                terminated: np.ndarray, truncated: np.ndarray, infos: dict[str, Any]) -> None:
        """Appends every wanted row's step: the action the env applied, its outcome."""
        true_obs = infos["true_obs"] if self.true_observation else None
        applied = np.clip(actions, -1.0, 1.0)
        for i, buf in enumerate(self.rows):
            if buf is None:
                continue
            buf["observations"].append(obs[i].copy())
            buf["actions"].append(applied[i].copy())
            buf["rewards"].append(float(reward[i]))
            buf["terminations"].append(bool(terminated[i]))
            buf["truncations"].append(bool(truncated[i]))
            if true_obs is not None:
                buf["true_obs"].append(true_obs[i].copy())

    def ended(self, env: InAirCaptureVectorEnv, row: int, episode: int, infos: dict[str, Any]) -> dict[str, Any]:
        """The ended episode in Minari's buffer layout."""
        buf = self.rows[row]
        self.rows[row] = None
        assert buf is not None  # a wanted episode's row always has a buffer
        out = {"observations": np.asarray(buf["observations"], dtype=np.float32).reshape(-1, OBS_DIM),
               "actions": np.asarray(buf["actions"], dtype=np.float32).reshape(-1, ACT_DIM),
               "rewards": np.asarray(buf["rewards"], dtype=np.float64),
               "terminations": np.asarray(buf["terminations"], dtype=bool),
               "truncations": np.asarray(buf["truncations"], dtype=bool),
               "infos": {}}
        if self.true_observation:
            out["infos"]["true_obs"] = np.asarray(buf["true_obs"], dtype=np.float32).reshape(-1, OBS_DIM)
        return out


def dataset_episodes(policy: Any, tier: str, episodes: int, *, seed: int = DATASET_BASE_SEED,
                     true_observation: bool = False, num_envs: int = 16,
                     num_threads: int = 0) -> Iterator[tuple[int, dict[str, Any]]]:
    """Runs ``episodes`` dataset episodes of ``policy`` (a :class:`~accd_gym.control.registry.Policy`)
    on ``tier`` (see the module docs) and yields ``(k, buffer)`` in index order, each buffer in
    Minari's layout."""
    if tier not in TIERS:
        raise ConfigError(f"invalid config: --tier {tier!r} is outside the allowed values {list(TIERS)}")
    episodes = check_count(episodes, "episodes", 1, len(DATASET_WAKE_SEEDS))
    batch = min(check_count(num_envs, "num_envs", 1, MAX_ENVS), episodes)
    observer = _Buffers(batch, true_observation)
    done = dict(schedule_episodes(policy, range(episodes), observer, seed=seed,
                                  wake_seeds=list(DATASET_WAKE_SEEDS[:episodes]), batch=batch,
                                  num_threads=num_threads, config={"tier": tier},
                                  true_observation=true_observation))
    for k in range(episodes):
        yield k, done[k]


@contextlib.contextmanager
def _datasets_root(folder: Path) -> Iterator[None]:
    """Minari's dataset root set to ``folder`` (its ``MINARI_DATASETS_PATH``) while in the block."""
    before = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(folder)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = before


def record_dataset(policy: str, tier: str, episodes: int, out: str | Path, *, seed: int = DATASET_BASE_SEED,
                   true_observation: bool = False, num_envs: int = 16, num_threads: int = 0,
                   author: Optional[str] = None) -> dict[str, Any]:
    """Records ``episodes`` episodes of ``policy`` (a spec for
    :func:`~accd_gym.evals.policies.load_policy`) on ``tier`` as the Minari dataset
    :func:`dataset_id` in the dataset root ``out``; returns ``{"id", "path", "episodes",
    "steps"}``. ConfigError before any episode runs for a bad tier or count, an output folder that
    cannot be written, or a dataset of that id already there."""
    # deferred: minari is the optional dataset extra
    import minari
    from minari.data_collector import EpisodeBuffer

    if tier not in TIERS:
        raise ConfigError(f"invalid config: --tier {tier!r} is outside the allowed values {list(TIERS)}")
    check_count(episodes, "episodes", 1, len(DATASET_WAKE_SEEDS))
    root = files.writable_folder(Path(out).resolve(), "--out")
    ident = dataset_id(tier, policy)
    target = root.joinpath(*ident.split("/"))
    if target.exists():
        raise ConfigError(f"invalid config: --out {str(out)!r} already holds the dataset {ident!r} ({target}); "
                          "choose another folder or remove it")
    config = {"tier": tier}
    agent = load_policy(policy, seed, config=config)
    # Each episode with the reset that replays it in the single env: env.reset(seed=..., options=...).
    buffers = [EpisodeBuffer(id=k, seed=seed + k, options={"wake_seed": int(DATASET_WAKE_SEEDS[k])}, **b)
               for k, b in dataset_episodes(agent, tier, episodes, seed=seed, true_observation=true_observation,
                                            num_envs=num_envs, num_threads=num_threads)]
    env_id = TIERS[tier].id
    env_kwargs = {"true_observation": True} if true_observation else {}
    spec = gym.spec(env_id)
    if env_kwargs:
        spec = dataclasses.replace(spec, kwargs={**spec.kwargs, **env_kwargs})
    with _datasets_root(root):
        dataset = minari.create_dataset_from_buffers(
            dataset_id=ident, buffer=buffers, env=spec, algorithm_name=policy, author=author or "accd-gym",
            data_format="hdf5",
            description=(f"{episodes} episodes of `{policy}` on the {tier} tier ({env_id}); episode k: seed {seed} + k, "
                         f"training wake seed {DATASET_WAKE_SEEDS.start} + k (accd_gym.evals.datasets)."
                         + (" infos['true_obs']: the noise-free, delay-free observation." if true_observation else "")),
        )
        steps = int(dataset.total_steps)
    return {"id": ident, "path": str(target), "episodes": episodes, "steps": steps}


__all__ = ["DATASET_BASE_SEED", "DATASET_WAKE_SEEDS", "NAMESPACE", "dataset_episodes", "dataset_id", "record_dataset"]
