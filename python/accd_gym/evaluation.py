"""Held-out evaluation of policies: episodes on fixed wake and initial-condition seeds, metrics, plots.

Every policy sees the same episodes: episode ``k`` is the first episode of a single env seeded
``seed + k`` (initial conditions and RLV motion; ``seed`` is :data:`EVAL_BASE_SEED` by default)
with wake seed ``wake_seeds[k]``, by default the first ``K`` of
:data:`accd_gym.HELD_OUT_WAKE_SEEDS`, which training never draws. That definition depends on
nothing else: not on ``num_envs`` (earlier versions gave env ``i``'s ``e``-th episode the seeds of
``(seed + i, e)``, so their results changed with ``num_envs``), and not on how the episodes are
split over Ray workers (:mod:`accd_gym.distributed`), which therefore reproduce the local results
bit for bit (see :func:`run_episode_range` for the one condition on the policy).

A *policy* is any object with ``predict(obs_batch) -> actions`` ((N, 25) -> (N, 4)) and
optionally ``reset(mask)`` (or ``start_episodes(mask, episode_indices)``): the baselines of :mod:`accd_gym.baselines` and :class:`SB3Policy`
(a stable-baselines3 model with its VecNormalize statistics).
"""

from __future__ import annotations

import json
import math
import pickle
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

from accd_gym.errors import ConfigError
from accd_gym.task import EVENT_NAMES, HELD_OUT_WAKE_SEEDS, INFO_NAMES

#: Base seed of evaluation episodes (initial conditions and RLV motion); fixed so runs compare.
EVAL_BASE_SEED: int = 20_240_607


def wilson_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % for the default ``z``); (0, 1) for n = 0."""
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


class SB3Policy:
    """A trained stable-baselines3 model (PPO or SAC) with its VecNormalize statistics, deterministic.

    ``path``: a run folder (``final_model.zip`` and ``vecnormalize.pkl`` in it; for a run that was
    interrupted or is still training, its latest checkpoint, which :attr:`note` and a warning
    say), or a model ``.zip`` (its statistics: ``vecnormalize.pkl`` beside it, or for a
    checkpoint ``<prefix>_vecnormalize_<steps>_steps.pkl``). The algorithm is read from the run's
    ``run.json`` when there is one, else from the zip's stored policy class.

    A model trained with VecNormalize acts on normalised observations: without its statistics it
    would see raw ones and act wrongly, so a missing statistics file is a ConfigError unless
    ``allow_unnormalized=True`` (then observations are passed raw, with a warning).

    A model trained with the env options ``residual``/``history`` (:mod:`accd_gym.agent_io`, read
    from the run's ``run.json``) gets the observations it was trained on and its actions are
    turned into flap commands as in training: the policy keeps the base controller (designed
    for ``config``, the env configuration it runs on) and the history per env, restarted by
    :meth:`reset`, so it runs on the plain env. :attr:`agent_options` holds them.
    """

    def __init__(self, path: str | Path, device: str = "cpu", *, allow_unnormalized: bool = False,
                 config: Optional[Any] = None) -> None:
        import warnings

        p = Path(path)
        #: How the model was found, e.g. that a run's latest checkpoint stands in for its final model.
        self.note: Optional[str] = None
        if p.is_dir():
            model_path, stats_path = p / "final_model.zip", p / "vecnormalize.pkl"
            if not model_path.is_file():
                from accd_gym.training import latest_checkpoint

                ckpt = latest_checkpoint(p)
                status = _run_status(p)
                if ckpt is None:
                    raise ConfigError(
                        f"invalid config: policy path {str(path)!r}: no final model and no checkpoint in "
                        f"{str(p / 'checkpoints')!r} (run status: {status})"
                    )
                model_path = ckpt["model"]
                stats_path = ckpt["vecnormalize"] or model_path.with_name("vecnormalize.pkl")
                self.note = (f"run {str(path)!r} has no final model (status: {status}); evaluating its latest "
                             f"checkpoint {model_path.name} ({ckpt['steps']} steps)")
                warnings.warn(self.note, stacklevel=2)
        else:
            model_path = p
            stats_path = p.with_name("vecnormalize.pkl")
            if "_steps" in p.stem:  # CheckpointCallback: <prefix>_<steps>_steps.zip
                prefix, steps = p.stem.rsplit("_", 2)[0], p.stem.rsplit("_", 2)[1]
                stats_path = p.with_name(f"{prefix}_vecnormalize_{steps}_steps.pkl")
        if not model_path.is_file():
            raise ConfigError(f"invalid config: policy path {str(path)!r}: no model file {str(model_path)!r}")
        if not stats_path.is_file() and not allow_unnormalized:
            raise ConfigError(
                f"invalid config: policy {str(path)!r}: its VecNormalize statistics {str(stats_path)!r} are missing; "
                "the model would see unnormalised observations (pass allow_unnormalized=True, or "
                "--allow-unnormalized on the command line, if it was trained without VecNormalize)"
            )
        self.name = str(path)
        self.algo = _algo_of(model_path)
        try:
            from stable_baselines3 import PPO, SAC
        except ModuleNotFoundError as e:
            raise ModuleNotFoundError(
                f"loading the trained model {str(path)!r} needs stable-baselines3 ({e}): pip install 'accd-gym[sb3]'",
                name=e.name,
            ) from e

        self._device = device
        self.agent_options = _agent_options_of(model_path)
        self._config = _physics_config(config)
        self._io: Any = None
        self._started: Optional[np.ndarray] = None
        self._model_bytes = model_path.read_bytes()
        self._stats_bytes = stats_path.read_bytes() if stats_path.is_file() else None
        self._load()
        expected = self.agent_options.observation_space().shape
        if self.model.observation_space.shape != expected:
            raise ConfigError(
                f"invalid config: policy {str(path)!r} observes shape {self.model.observation_space.shape}, the env "
                f"options {self.agent_options.to_dict() or 'none'} give {expected}; a model trained with residual/history "
                "options is evaluated from its run folder (run.json holds them)"
            )
        if self._stats_bytes is None:
            warnings.warn(f"policy {str(path)!r}: no VecNormalize statistics; observations are passed unnormalised",
                          stacklevel=2)

    def _load(self) -> None:
        """Builds the model and the normalizer from the files' bytes (kept for pickling)."""
        import io

        from stable_baselines3 import PPO, SAC

        cls = {"ppo": PPO, "sac": SAC}[self.algo]
        self.model = cls.load(io.BytesIO(self._model_bytes), device=self._device)
        self.normalizer = None
        if self._stats_bytes is not None:
            self.normalizer = pickle.loads(self._stats_bytes)
            self.normalizer.training = False

    def __getstate__(self) -> dict[str, Any]:
        """Pickles as the model's and statistics' file contents (for Ray tasks): a copy acts bit for bit alike."""
        return {k: v for k, v in self.__dict__.items() if k not in ("model", "normalizer")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._load()

    def predict(self, obs: Any) -> np.ndarray:
        """Deterministic flap commands (N, 4) for raw observations (N, 25), normalised as in
        training (with residual/history options: augmented, and the actions made commands, as
        the env did in training)."""
        o = np.asarray(obs, dtype=np.float32)
        if self.agent_options.enabled:
            o = self._agent_observation(o)
        if self.normalizer is not None and self.normalizer.norm_obs:
            o = self.normalizer.normalize_obs(o)
        actions, _ = self.model.predict(o, deterministic=True)
        actions = np.clip(np.asarray(actions, dtype=np.float32), -1.0, 1.0)
        return actions if self._io is None else self._io.command(actions)

    def _agent_observation(self, obs: np.ndarray) -> np.ndarray:
        """The observations the model was trained on, advancing the per-env agent state (a new
        batch size starts every env afresh)."""
        from accd_gym.agent_io import AgentIO

        if obs.ndim != 2:
            raise ValueError(f"observations have shape {obs.shape}, expected (N, 25)")
        if self._io is None or self._io.num_envs != obs.shape[0]:
            self._io = AgentIO(self.agent_options, self._config, obs.shape[0])
            self._started = None
            return self._io.begin(obs)
        started, self._started = self._started, None
        return self._io.advance(obs, started)[0]

    def reset(self, mask: Optional[np.ndarray] = None) -> None:
        """The envs ``mask`` selects (all when None) start new episodes: their base controller and
        history restart at the next :meth:`predict` (nothing to do without env options)."""
        if self._io is None:
            return
        rows = np.ones(self._io.num_envs, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        if rows.shape != (self._io.num_envs,):
            self._io = None  # another batch: every env starts afresh
            return
        self._started = rows if self._started is None else (self._started | rows)


def _run_status(run: Path) -> str:
    """The ``status`` of a run folder's run.json ("unknown" without one)."""
    try:
        return str(json.loads((run / "run.json").read_text()).get("status", "unknown"))
    except (OSError, ValueError, AttributeError):
        return "unknown"


def _run_meta(model_path: Path) -> Optional[dict[str, Any]]:
    """The run.json beside or above a saved model, or None."""
    for folder in (model_path.parent, model_path.parent.parent):
        meta = folder / "run.json"
        if meta.is_file():
            try:
                return json.loads(meta.read_text())
            except ValueError:
                return None
    return None


def _agent_options_of(model_path: Path) -> Any:
    """The env options (residual, history) the model was trained with, from its run.json."""
    from accd_gym.agent_io import AgentOptions, split_agent_options

    meta = _run_meta(model_path)
    env = (meta or {}).get("config", {}).get("env", {}) if isinstance(meta, dict) else {}
    return split_agent_options(env)[0] if isinstance(env, dict) else AgentOptions()


def _physics_config(config: Optional[Any]) -> Any:
    """An evaluation's env configuration without the env options of :mod:`accd_gym.agent_io`
    (a trained policy carries its own; see :class:`SB3Policy`)."""
    from collections.abc import Mapping

    from accd_gym.agent_io import split_agent_options

    if config is not None and not isinstance(config, Mapping):
        return config  # a validated EnvConfig holds no env options
    return split_agent_options(dict(config or {}))[1]


def _algo_of(model_path: Path) -> str:
    """'ppo' or 'sac' for a saved model: from run.json beside or above it, else the zip's data."""
    for folder in (model_path.parent, model_path.parent.parent):
        meta = folder / "run.json"
        if meta.is_file():
            return json.loads(meta.read_text())["algo"]
    try:
        with zipfile.ZipFile(model_path) as z:
            data = z.read("data").decode()
    except (zipfile.BadZipFile, KeyError) as e:
        raise ConfigError(f"invalid config: {str(model_path)!r} is not a stable-baselines3 model ({e})") from None
    if "sac.policies" in data:
        return "sac"
    if "policies.ActorCriticPolicy" in data or "ppo" in data.lower():
        return "ppo"
    raise ConfigError(f"invalid config: cannot tell the algorithm of {str(model_path)!r} (allowed: PPO, SAC)")


def load_policy(spec: str, seed: int = 0, *, allow_unnormalized: bool = False, config: Optional[Any] = None) -> Any:
    """A policy from a baseline name (``zero``, ``random``, ``guidance``, ``lqr``), a tuning file
    (``training/guidance_tuning*.json``: the guidance controller with its winning gains;
    ``training/lqr_tuning.json``: the LQR with its winning tuning) or a model path (see
    :class:`SB3Policy` for ``allow_unnormalized``; an RLlib run or checkpoint folder gives an
    :class:`accd_gym.rllib.RLlibPolicy`). ``config``: the env configuration (overrides) the
    policy will run on; the LQR is designed for it."""
    from accd_gym.baselines import BASELINES, guidance_from_tuning, make_baseline

    config = _physics_config(config)
    if spec in BASELINES:
        return make_baseline(spec, seed, config)
    if spec.endswith(".json") and Path(spec).is_file():
        from accd_gym.lqr import is_lqr_tuning, lqr_from_tuning

        if is_lqr_tuning(spec):
            return lqr_from_tuning(spec, config)
        return guidance_from_tuning(spec)
    if Path(spec).exists():
        from accd_gym.rllib import RLlibPolicy, is_rllib_run

        if is_rllib_run(spec):
            return RLlibPolicy(spec)
        return SB3Policy(spec, allow_unnormalized=allow_unnormalized, config=config)
    return make_baseline(spec, seed, config)  # raises ConfigError naming the allowed names


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
    if episodes < 1:
        raise ConfigError(f"invalid config: `episodes` = {episodes} is outside the allowed range >= 1")
    return run_episode_range(policy, 0, episodes, seed=seed, wake_seeds=wake_seeds, batch=min(int(num_envs), episodes),
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
    split of the index range into parts (:mod:`accd_gym.distributed`) therefore gives the same
    episodes bit for bit, provided each part uses the same ``batch`` and the policy's action for
    a row depends on that row alone at a fixed batch size: true of the baselines (``random``
    draws from a stream per episode index) and, as measured here, of PyTorch's MLPs on CPU
    (``tests/test_distributed.py`` checks both; PyTorch gives other last bits for batches of
    1-3 rows than for 4 or more, which is why the batch size is fixed).
    """
    from accd_gym.vector import InAirCaptureVectorEnv

    start, stop, batch = int(start), int(stop), int(batch)
    if not 0 <= start < stop:
        raise ConfigError(f"invalid config: episode range {start}..{stop} is empty or negative; need 0 <= start < stop")
    if batch < 1:
        raise ConfigError(f"invalid config: `batch` = {batch} is outside the allowed range >= 1")
    if wake_seeds is not None and len(wake_seeds) < stop:
        raise ConfigError(f"invalid config: {len(wake_seeds)} wake seeds for episodes up to {stop - 1}; need at least {stop}")
    # The env options (residual control, history) are the policy's (SB3Policy applies those of its
    # run): the episodes run on the plain env.
    env = InAirCaptureVectorEnv(batch, autoreset_mode="disabled", num_threads=num_threads, **_physics_config(config))
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
    _policy_starts(policy, started, ep_of, last)
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
            _policy_starts(policy, dones, ep_of, last)
    finally:
        if bar is not None:
            bar.close()
        env.close()
    return [done_eps[k] for k in range(start, stop)]


def _policy_starts(policy: Any, rows: np.ndarray, ep_of: np.ndarray, last: np.ndarray) -> None:
    """Tells ``policy`` that the envs ``rows`` selects started new episodes: ``start_episodes(rows,
    indices)`` when it has it (a policy with per-episode random streams), else ``reset(rows)``."""
    if hasattr(policy, "start_episodes"):
        policy.start_episodes(rows.copy(), np.where(ep_of >= 0, ep_of, last).astype(np.int64))
    elif hasattr(policy, "reset"):
        policy.reset(rows.copy())


def mcnemar_exact(only_a: int, only_b: int) -> float:
    """Two-sided exact McNemar test of paired outcomes: the probability, if both policies
    captured equally often, of a split of the ``only_a + only_b`` discordant episodes (captured
    by one policy only) at least as uneven as the one seen: ``min(1, 2 P(X <= min))`` for
    ``X ~ Binomial(only_a + only_b, 1/2)``; 1 when no episode is discordant. Exact in integer
    arithmetic up to the final division."""
    if only_a < 0 or only_b < 0:
        raise ConfigError(f"invalid config: discordant counts {only_a}, {only_b} are outside the allowed range >= 0")
    n = only_a + only_b
    if n == 0:
        return 1.0
    from math import comb

    tail = sum(comb(n, k) for k in range(min(only_a, only_b) + 1))
    return min(1.0, 2 * tail / 2**n)


def paired_comparisons(runs: dict[str, list["Episode"]]) -> list[dict[str, Any]]:
    """Every pair of policies evaluated on the same episodes: the episodes captured by both, by
    the first only, by the second only, and the exact McNemar p-value (:func:`mcnemar_exact`)."""
    specs = list(runs)
    out = []
    for i, a in enumerate(specs):
        for b in specs[i + 1:]:
            pa = [e.captured for e in runs[a]]
            pb = [e.captured for e in runs[b]]
            both = sum(x and y for x, y in zip(pa, pb))
            only_a = sum(x and not y for x, y in zip(pa, pb))
            only_b = sum(y and not x for x, y in zip(pa, pb))
            out.append({"a": a, "b": b, "both": both, "only_a": only_a, "only_b": only_b,
                        "mcnemar_p": mcnemar_exact(only_a, only_b)})
    return out


def summarize(episodes: Sequence[Episode]) -> dict[str, Any]:
    """Capture rate with its Wilson 95 % interval, miss distance, capture time, tension, flap usage."""
    n = len(episodes)
    caught = [e for e in episodes if e.captured]
    lo, hi = wilson_interval(len(caught), n)
    miss = np.array([e.min_distance for e in episodes])
    times = np.array([e.capture_time for e in caught]) if caught else np.array([])
    peak = np.array([e.peak_tension for e in episodes])
    return {
        "episodes": n,
        "captures": len(caught),
        "capture_rate": len(caught) / n,
        "capture_rate_ci95": [lo, hi],
        "outcomes": {o: sum(e.outcome == o for e in episodes) for o in (*EVENT_NAMES, "truncated")},
        "miss_distance_m": {
            "mean": float(miss.mean()),
            "median": float(np.median(miss)),
            "p90": float(np.percentile(miss, 90)),
            "max": float(miss.max()),
        },
        "capture_time_s": {
            "mean": float(times.mean()) if caught else None,
            "median": float(np.median(times)) if caught else None,
        },
        "peak_tension_N": {"median": float(np.median(peak)), "max": float(peak.max())},
        "mean_abs_action": float(np.mean([e.mean_abs_action for e in episodes])),
        "mean_abs_delta_action": float(np.mean([e.mean_abs_delta_action for e in episodes])),
        "mean_return": float(np.mean([e.episode_return for e in episodes])),
    }


def evaluate(
    policies: Sequence[str],
    episodes: int,
    out: str | Path,
    *,
    wake_seeds: Optional[Sequence[int]] = None,
    seed: int = EVAL_BASE_SEED,
    num_envs: int = 16,
    num_threads: int = 0,
    config: Optional[dict[str, Any]] = None,
    progress: bool = True,
    dpi: int = 90,
    allow_unnormalized: bool = False,
    replay: int = 0,
    ray_address: Optional[str] = None,
    ray_chunk: Optional[int] = None,
) -> dict[str, Any]:
    """Evaluates each policy spec on the same episodes; writes results.json, summary.md and plots.

    ``wake_seeds`` defaults to the first ``episodes`` held-out wake seeds. Returns the results
    document (also in ``out/results.json``). ``replay`` = K > 0 also writes replay pages and
    recordings of K episodes per policy (best, median, worst, ...;
    :func:`accd_gym.replay.write_evaluation_replays`) under ``out/replays/``. ``ray_address``
    (``"local"``, ``"auto"`` or ``HOST:PORT``) runs the episodes as Ray tasks of ``ray_chunk``
    episodes each (:mod:`accd_gym.distributed`): the same results bit for bit, plus
    ``out/ray_tasks.json`` (where each task ran, timings). ``num_threads`` is then per task (0:
    the task's CPUs).
    """
    if not policies:
        raise ConfigError("invalid config: `policy` is empty; give at least one baseline name or model path")
    if episodes > len(HELD_OUT_WAKE_SEEDS) and wake_seeds is None:
        raise ConfigError(
            f"invalid config: `episodes` = {episodes} is outside the allowed range 1..{len(HELD_OUT_WAKE_SEEDS)} (held-out wake seeds)"
        )
    seeds = list(wake_seeds) if wake_seeds is not None else list(HELD_OUT_WAKE_SEEDS[:episodes])
    loaded = [(spec, load_policy(spec, allow_unnormalized=allow_unnormalized, config=config)) for spec in policies]  # fail early
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {
        "episodes": episodes,
        "base_seed": seed,
        "wake_seeds": [seeds[0], seeds[episodes - 1]] if episodes else [],
        "wake_seeds_held_out": all(s in HELD_OUT_WAKE_SEEDS for s in seeds[:episodes]),
        "num_envs": min(num_envs, episodes),
        "config": config or {},
        "policies": {},
    }
    runs: dict[str, list[Episode]] = {}
    if ray_address is not None:
        from accd_gym import distributed

        runs, ray_info = distributed.run_policies(dict(loaded), episodes, seed=seed, wake_seeds=seeds, num_envs=num_envs,
                                                  config=config, address=ray_address, chunk=ray_chunk,
                                                  cpus_per_task=max(1, num_threads), progress=progress)
        (out / "ray_tasks.json").write_text(json.dumps(ray_info, indent=1))
    for spec, policy in loaded:
        if ray_address is None:
            runs[spec] = run_episodes(policy, episodes, seed=seed, wake_seeds=seeds, num_envs=num_envs,
                                      num_threads=num_threads, config=config, progress=progress, desc=_label(spec))
        eps = runs[spec]
        results["policies"][spec] = {"summary": summarize(eps), "episodes": [e.metrics() for e in eps]}
        if getattr(policy, "note", None):
            results["policies"][spec]["note"] = policy.note
    results["paired"] = paired_comparisons(runs)
    if replay:
        from accd_gym.replay import write_evaluation_replays

        results["replays"] = {
            spec: write_evaluation_replays(spec, _label(spec), eps, replay, out / "replays", seed=seed,
                                           wake_seeds=seeds[:episodes], num_envs=num_envs, num_threads=num_threads,
                                           config=config, allow_unnormalized=allow_unnormalized)
            for spec, eps in runs.items()
        }
    (out / "results.json").write_text(json.dumps(results, indent=1))
    np.savez_compressed(out / "trajectories.npz", **{f"{_label(s)}__{e.index}": e.trajectory for s, eps in runs.items() for e in eps})
    plot_trajectories(runs, out / "trajectories.png", dpi=dpi)
    from accd_gym.config import env_config

    radius = env_config(config or {})["boom"]["capture_radius"]
    plot_miss_cdf(runs, out / "miss_distance_cdf.png", dpi=dpi, capture_radius=radius)
    (out / "summary.md").write_text(summary_markdown(results))
    return results


def _label(spec: str) -> str:
    """A short name for a policy spec (a path's run folder or file stem)."""
    p = Path(spec)
    from accd_gym.baselines import BASELINES

    if spec in BASELINES or not p.exists():
        return spec
    if p.suffix == ".json":
        from accd_gym.lqr import is_lqr_tuning

        return f"{'lqr' if is_lqr_tuning(spec) else 'guidance'} ({p.stem})"
    return p.name if p.is_dir() else f"{p.parent.name}/{p.stem}"


def summary_markdown(results: dict[str, Any]) -> str:
    """The markdown table comparing the policies of an :func:`evaluate` results document."""
    lines = [
        f"# Held-out evaluation: {results['episodes']} episodes",
        "",
        f"Wake seeds {results['wake_seeds'][0]}..{results['wake_seeds'][1]} "
        f"({'held out' if results['wake_seeds_held_out'] else 'NOT held out'}), base seed {results['base_seed']}; "
        "every policy sees the same episodes.",
        "",
        "| policy | capture rate | 95 % CI (Wilson) | miss distance median / p90 (m) | time to capture median (s) "
        "| peak tension median / max (kN) | mean abs action | mean abs delta action | outcomes |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for spec, doc in results["policies"].items():
        s = doc["summary"]
        lo, hi = s["capture_rate_ci95"]
        ct = s["capture_time_s"]["median"]
        outcomes = ", ".join(f"{k} {v}" for k, v in s["outcomes"].items() if v)
        lines.append(
            f"| {_label(spec)} | {s['captures']}/{s['episodes']} = {s['capture_rate']:.1%} | {lo:.1%} - {hi:.1%} "
            f"| {s['miss_distance_m']['median']:.2f} / {s['miss_distance_m']['p90']:.2f} "
            f"| {'-' if ct is None else f'{ct:.1f}'} "
            f"| {s['peak_tension_N']['median'] / 1e3:.2f} / {s['peak_tension_N']['max'] / 1e3:.2f} "
            f"| {s['mean_abs_action']:.3f} | {s['mean_abs_delta_action']:.3f} | {outcomes} |"
        )
    if results.get("paired"):
        lines += ["", "Paired on the same episodes (captured by both / by the first only / by the second only; "
                  "exact McNemar test, two-sided):", "",
                  "| policies | both | first only | second only | McNemar p |", "|---|---|---|---|---|"]
        for c in results["paired"]:
            lines.append(f"| {_label(c['a'])} vs {_label(c['b'])} | {c['both']} | {c['only_a']} | {c['only_b']} "
                         f"| {c['mcnemar_p']:.3g} |")
    notes = [f"- {_label(spec)}: {doc['note']}" for spec, doc in results["policies"].items() if doc.get("note")]
    if notes:
        lines += ["", "Notes:", *notes]
    lines += ["", "Plots: `trajectories.png` (capture point minus boom tip, side and top views), "
              "`miss_distance_cdf.png` (minimum distance over each episode)."]
    return "\n".join(lines) + "\n"


def plot_trajectories(runs: dict[str, list[Episode]], path: Path, max_episodes: int = 20, dpi: int = 90) -> None:
    """Side (x, height) and top (x, y) views of capture point minus boom tip, one row per policy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = len(runs)
    fig, axes = plt.subplots(rows, 2, figsize=(11, 3.2 * rows), squeeze=False)
    for r, (spec, eps) in enumerate(runs.items()):
        side, top = axes[r]
        for e in eps[:max_episodes]:
            t = e.trajectory
            colour = "tab:green" if e.captured else "tab:red"
            side.plot(t[:, 0], -t[:, 2], color=colour, lw=0.7, alpha=0.7)
            top.plot(t[:, 0], t[:, 1], color=colour, lw=0.7, alpha=0.7)
            side.plot(t[0, 0], -t[0, 2], "o", color=colour, ms=2)
            top.plot(t[0, 0], t[0, 1], "o", color=colour, ms=2)
        for ax, ylabel in ((side, "height above boom tip, -z (m)"), (top, "starboard of boom tip, y (m)")):
            ax.plot(0, 0, "k+", ms=12, mew=2)
            ax.set_xlabel("ahead of boom tip, x (m)")
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
        side.set_title(f"{_label(spec)}: side view (green captured, red not)", fontsize=9)
        top.set_title(f"{_label(spec)}: top view", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def plot_miss_cdf(runs: dict[str, list[Episode]], path: Path, dpi: int = 90, capture_radius: float = 0.5) -> None:
    """Empirical CDF of the minimum capture-point-to-boom distance per episode, per policy, with the
    capture radius (m) of the evaluated config marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4))
    for spec, eps in runs.items():
        d = np.sort([e.min_distance for e in eps])
        ax.step(d, np.arange(1, len(d) + 1) / len(d), where="post", label=_label(spec))
    ax.axvline(capture_radius, color="k", ls=":", lw=1, label=f"capture radius ({capture_radius:g} m)")
    ax.set_xscale("log")
    ax.set_xlabel("miss distance: minimum distance to the boom tip (m)")
    ax.set_ylabel("fraction of episodes")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


__all__ = ["EVAL_BASE_SEED", "Episode", "SB3Policy", "evaluate", "load_policy", "run_episode_range", "run_episodes", "summarize", "wilson_interval"]
