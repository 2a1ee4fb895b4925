"""Recorded episodes: the full trajectory of each episode at the agent rate, saved as ``.npz``.

:func:`record_episodes` runs a policy on chosen seeds and returns one :class:`Recording` per
episode; :class:`RecordEpisode` is a gymnasium wrapper that records whatever drives a single
:class:`~accd_gym.InAirCaptureEnv`. A recording holds, for the initial state and the state after
every agent step (``T + 1`` samples for ``T`` steps): the tether's joint positions and the
tension at each joint, the ACCD's position, velocity, attitude quaternion, Euler angles, body
rates, flap commands and deflections, angle of attack, sideslip, airspeed and aerodynamic
loads, the capture point and the boom tip with their velocities, distance, relative speed and
the observation; and per step the action, the reward and the env's info values (events
included). Everything comes from the env itself (``BatchEnv.record_data``, the step's outputs),
in the TA frame and SI units; reading it leaves the episode unchanged.

The file format (``Recording.save``) is a plain numpy ``.npz`` that loads without accd-gym:
``docs/recording-format.md`` lists every array with its shape and unit.

:func:`record_episodes` runs on the evaluation's episode scheduler
(:func:`accd_gym.evals.episodes.schedule_episodes`: same batch, seeds, episode order and policy
calls), so with the same arguments its episode ``k`` is the evaluation's episode ``k``, for
stateful and random policies too (``tests/test_recording.py``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterable, Iterator, Optional, Sequence

import gymnasium as gym
import numpy as np

from accd_gym import files
from accd_gym._core import __version__
from accd_gym.control.registry import Policy
from accd_gym.envs.env import InAirCaptureEnv
from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS, INFO_NAMES, MAX_ENVS, check_base_seed, check_count
from accd_gym.errors import ConfigError
from accd_gym.evals.episodes import EVAL_BASE_SEED, schedule_episodes
from accd_gym.evals.policies import load_policy

#: Name and version written into every file (``format``, ``version``).
FORMAT_NAME = "accd-gym-recording"
FORMAT_VERSION = 1

#: Per-sample arrays (``T + 1`` rows: the initial state, then after each agent step), from
#: ``BatchEnv.record_data``: name -> (unit, meaning). Vectors are in the TA frame.
SAMPLE_FIELDS: dict[str, tuple[str, str]] = {
    "time": ("s", "episode time"),
    "joints": ("m", "tether joints (n+1, 3): the inboard end of each segment, then the tip (the ACCD)"),
    "tensions": ("N", "tension at each joint (n+1,): entry 0 at the attachment, entry n the ACCD's pull"),
    "position": ("m", "ACCD centre of gravity (the tether tip)"),
    "velocity": ("m/s", "ACCD velocity relative to the aircraft"),
    "attitude": ("-", "attitude quaternion (w, x, y, z), body to TA frame"),
    "euler": ("rad", "roll, pitch, yaw (body to TA frame)"),
    "omega": ("rad/s", "body rates p, q, r"),
    "flap_deflection_deg": ("deg", "flap deflections: right, left, top, bottom"),
    "flap_command_deg": ("deg", "flap commands held over the last step: right, left, top, bottom"),
    "alpha": ("rad", "angle of attack"),
    "beta": ("rad", "sideslip angle"),
    "airspeed": ("m/s", "ACCD airspeed"),
    "force": ("N", "aerodynamic force on the ACCD (TA frame)"),
    "moment": ("N m", "aerodynamic moment on the ACCD (body axes)"),
    "capture_point": ("m", "capture point (the ACCD's tail)"),
    "capture_point_velocity": ("m/s", "its velocity"),
    "boom_tip": ("m", "RLV boom tip"),
    "boom_velocity": ("m/s", "its velocity"),
    "distance": ("m", "capture point to boom tip"),
    "relative_speed": ("m/s", "speed of the capture point relative to the boom tip"),
    "captured": ("-", "capture criteria met at this state"),
    "attachment_tension": ("N", "tension at the attachment (k s + c s')"),
    "aircraft_velocity": ("m/s", "towing aircraft's velocity relative to the air"),
}
#: Per-step arrays (``T`` rows): name -> (unit, meaning). ``info_*`` are the env's info values.
STEP_FIELDS: dict[str, tuple[str, str]] = {
    "action": ("-", "the policy's flap commands as the env applied them: float32, clipped to [-1, 1]"),
    "reward": ("-", "reward of the step"),
    "terminated": ("-", "the step ended the episode (capture, overload, envelope exit, divergence)"),
    "truncated": ("-", "the capture window ran out at this step"),
    "info_time": ("s", "info: time at the end of the step"),
    "info_distance": ("m", "info: distance at the end of the step"),
    "info_relative_speed": ("m/s", "info: relative speed at the end of the step"),
    "info_peak_tension": ("N", "info: highest attachment tension during the step"),
    "info_captured": ("-", "info: captured during the step"),
    "info_overload": ("-", "info: tether overload during the step"),
    "info_envelope_exit": ("-", "info: envelope exit during the step"),
    "info_diverged": ("-", "info: the simulation diverged during the step"),
    "info_episode_steps": ("-", "info: agent steps so far"),
}
_BOOL_INFO = ("captured", "overload", "envelope_exit", "diverged")


class Recording:
    """One recorded episode: named arrays (:data:`SAMPLE_FIELDS`, :data:`STEP_FIELDS`,
    ``observation`` (T+1, 25) float32, ``equilibrium`` (3,)) and metadata (:attr:`meta`: seeds,
    outcome, policy, configuration, ACCD geometry).

    ``rec["joints"]`` is an array; :attr:`steps`, :attr:`outcome` and :attr:`duration` summarise.
    """

    def __init__(self, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
        self.arrays = arrays
        self.meta = meta

    def __getitem__(self, name: str) -> np.ndarray:
        return self.arrays[name]

    def __contains__(self, name: object) -> bool:
        return name in self.arrays

    @property
    def steps(self) -> int:
        """Agent steps recorded (``T``)."""
        return int(self.arrays["reward"].shape[0])

    @property
    def duration(self) -> float:
        """Episode time at the last sample, s."""
        return float(self.arrays["time"][-1])

    @property
    def outcome(self) -> str:
        """``captured``, ``overload``, ``envelope_exit``, ``diverged`` or ``truncated`` (or
        ``running`` for an unfinished episode)."""
        return str(self.meta["outcome"])

    @property
    def min_distance(self) -> float:
        """Smallest capture-point-to-boom distance over the recorded samples, m."""
        return float(np.min(self.arrays["distance"]))

    def frame_data(self, k: int) -> dict[str, Any]:
        """Sample ``k`` in the form :func:`accd_gym.envs.render.render_frame` takes (what
        ``BatchEnv.render_data`` returns), for videos made from a recording."""
        a = self.arrays
        return {
            "joints": a["joints"][k],
            "accd_position": a["position"][k],
            "capture_point": a["capture_point"][k],
            "boom_tip": a["boom_tip"][k],
            "equilibrium": a["equilibrium"],
            "attitude": a["attitude"][k],
            "deflection_deg": a["flap_deflection_deg"][k],
            "time": float(a["time"][k]),
            "distance": float(a["distance"][k]),
            "tension": float(a["attachment_tension"][k]),
        }

    def save(self, path: str | Path) -> Path:
        """Writes the recording as a compressed ``.npz`` (``docs/recording-format.md``); returns
        the path. Strings are stored as numpy unicode scalars, so ``numpy.load`` needs no pickle."""
        p = Path(path)
        extra = {
            "format": np.array(FORMAT_NAME),
            "version": np.array(FORMAT_VERSION),
            "meta_json": np.array(json.dumps(self.meta, sort_keys=True)),
        }
        with files.atomic_open(p, "wb") as f:  # a full disk leaves the previous file, never half of one
            np.savez_compressed(f, **extra, **self.arrays)
        return p

    @classmethod
    def load(cls, path: str | Path) -> "Recording":
        """Reads a file written by :meth:`save`; raises ConfigError for another file (also one
        that is not a regular file, or is truncated)."""
        files.check_regular_file(path, "recording")
        try:
            return cls._from_npz(path, path)
        except ConfigError:
            raise
        except Exception as e:  # a truncated or foreign file fails in zipfile, zlib or numpy
            raise ConfigError(f"invalid config: {str(path)!r} is not a readable accd-gym recording "
                              f"({type(e).__name__}: {e})") from None

    @classmethod
    def _from_npz(cls, source: Any, path: str | Path) -> "Recording":
        """The recording in an open ``.npz`` (``path`` names it in the messages)."""
        with np.load(source, allow_pickle=False) as z:
            if "format" not in z.files or str(z["format"]) != FORMAT_NAME:
                raise ConfigError(f"invalid config: {str(path)!r} is not an accd-gym recording (no `format` = {FORMAT_NAME!r})")
            version = int(z["version"])
            if version != FORMAT_VERSION:
                raise ConfigError(
                    f"invalid config: recording {str(path)!r} has format version {version}, outside the allowed range "
                    f"[{FORMAT_VERSION}, {FORMAT_VERSION}]"
                )
            meta = json.loads(str(z["meta_json"]))
            arrays = {k: z[k] for k in z.files if k not in ("format", "version", "meta_json")}
        return cls(arrays, meta)

    def __repr__(self) -> str:
        return (f"Recording(policy={self.meta.get('policy')!r}, episode={self.meta.get('episode')}, "
                f"outcome={self.outcome!r}, steps={self.steps}, min_distance={self.min_distance:.3f} m)")


def accd_geometry(config: dict[str, Any]) -> dict[str, float]:
    """The ACCD's drawn geometry from a full env config, m: ``length``, ``diameter``,
    ``cg_from_nose`` and ``capture_offset`` (the capture point's distance behind the centre of
    gravity, along body -x: ``length - cg_from_nose``)."""
    a = config["accd"]
    return {
        "length": float(a["length"]),
        "diameter": float(a["diameter"]),
        "cg_from_nose": float(a["cg_from_nose"]),
        "capture_offset": float(a["length"]) - float(a["cg_from_nose"]),
    }


class _Builder:
    """Collects one episode's samples and steps."""

    def __init__(self, sample: dict[str, Any], obs: np.ndarray) -> None:
        self.samples: dict[str, list[Any]] = {k: [sample[k]] for k in SAMPLE_FIELDS}
        self.equilibrium = np.asarray(sample["equilibrium"], dtype=float)
        self.obs: list[np.ndarray] = [np.array(obs, dtype=np.float32)]
        self.steps: dict[str, list[Any]] = {k: [] for k in STEP_FIELDS}

    def add(self, sample: dict[str, Any], obs: np.ndarray, action: np.ndarray, reward: float,
            terminated: bool, truncated: bool, info: dict[str, Any]) -> None:
        for k in SAMPLE_FIELDS:
            self.samples[k].append(sample[k])
        self.obs.append(np.array(obs, dtype=np.float32))
        self.steps["action"].append(np.array(action, dtype=np.float32))
        self.steps["reward"].append(float(reward))
        self.steps["terminated"].append(bool(terminated))
        self.steps["truncated"].append(bool(truncated))
        for name in ("time", "distance", "relative_speed", "peak_tension", *_BOOL_INFO, "episode_steps"):
            self.steps[f"info_{name}"].append(info[name])

    def finish(self, meta: dict[str, Any]) -> Recording:
        arrays: dict[str, np.ndarray] = {}
        for k, values in self.samples.items():
            arrays[k] = np.asarray(values, dtype=bool if k == "captured" else np.float64)
        arrays["equilibrium"] = self.equilibrium
        arrays["observation"] = np.asarray(self.obs, dtype=np.float32)
        for k, values in self.steps.items():
            if k == "action":
                arrays[k] = np.asarray(values, dtype=np.float32).reshape(-1, 4)
            elif k in ("terminated", "truncated") or k.removeprefix("info_") in _BOOL_INFO:
                arrays[k] = np.asarray(values, dtype=bool)
            elif k == "info_episode_steps":
                arrays[k] = np.asarray(values, dtype=np.int64)
            else:
                arrays[k] = np.asarray(values, dtype=np.float64)
        meta = dict(meta)
        meta["outcome"] = _outcome(arrays)
        return Recording(arrays, meta)


def _outcome(arrays: dict[str, np.ndarray]) -> str:
    """Why the episode ended, from its last step's info (as the evaluation names it)."""
    if arrays["reward"].shape[0] == 0:
        return "running"
    for name in _BOOL_INFO:
        if arrays[f"info_{name}"][-1]:
            return name
    return "truncated" if arrays["truncated"][-1] else "running"


def _policy_label(policy: Any) -> str:
    """A name for a policy object or spec."""
    if isinstance(policy, str):
        return policy
    return str(getattr(policy, "name", type(policy).__name__))


class _Recorder:
    """The recording's observer of :func:`accd_gym.evals.episodes.schedule_episodes`: a
    :class:`_Builder` per kept episode, finished into a :class:`Recording` when it ends."""

    def __init__(self, label: str, base: int, batch: int) -> None:
        self.label = label
        self.base = base
        self.batch = batch
        self.config: Optional[dict[str, Any]] = None  # the env's full configuration, read at the first start
        self.geometry: dict[str, float] = {}
        self.builders: dict[int, _Builder] = {}
        self.metas: dict[int, dict[str, Any]] = {}

    def started(self, env: Any, rows: np.ndarray, episodes: np.ndarray, obs: np.ndarray) -> None:
        """Starts a builder for each row that runs a kept episode (a repeat records nothing)."""
        if self.config is None:
            self.config = env.config
            self.geometry = accd_geometry(self.config)
        for i, k in zip(rows, episodes):
            i = int(i)
            if k < 0:
                self.builders.pop(i, None)
                continue
            self.builders[i] = _Builder(env.record_data(i), obs[i])
            self.metas[i] = {
                "policy": self.label,
                "episode": int(k),
                "env_index": i,
                "num_envs": self.batch,
                "base_seed": self.base,
                "seeds": env.episode_seeds(i),
                "config": self.config,
                "accd_geometry": self.geometry,
                "agent_step": float(self.config["agent_step"]),
                "accd_gym_version": __version__,
                "divergence": None,
            }

    def stepped(self, env: Any, actions: np.ndarray, obs: np.ndarray, reward: np.ndarray, terminated: np.ndarray,
                truncated: np.ndarray, infos: dict[str, Any]) -> None:
        """Adds the step to every recorded row."""
        for i, builder in self.builders.items():
            row = {name: infos[name][i] for name in INFO_NAMES}
            builder.add(env.record_data(i), obs[i], np.clip(actions[i], -1.0, 1.0), float(reward[i]),
                        bool(terminated[i]), bool(truncated[i]), row)

    def ended(self, env: Any, row: int, episode: int, infos: dict[str, Any]) -> Recording:
        """The ended episode's recording (with the reason of a divergence)."""
        meta = self.metas.pop(row)
        if self.builders[row].steps["info_diverged"][-1]:
            meta["divergence"] = env.divergence(row)
        return self.builders.pop(row).finish(meta)


def iter_recordings(
    policy: Policy | str,
    episodes: Optional[int] = None,
    *,
    config: Optional[dict[str, Any]] = None,
    seed: Optional[int] = None,
    wake_seeds: Optional[Sequence[int]] = None,
    num_envs: int = 16,
    num_threads: int = 0,
    keep: Optional[Iterable[int]] = None,
    policy_seed: int = 0,
) -> Iterator[Recording]:
    """Like :func:`record_episodes`, yielding each recording as its episode ends (in the order
    the episodes end; ``rec.meta["episode"]`` is its index), so that callers can write and drop
    them one at a time."""
    if episodes is None:
        episodes = len(wake_seeds) if wake_seeds is not None else 1
    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or episodes < 1:
        raise ConfigError(f"invalid config: `episodes` = {episodes!r} is outside the allowed range: an int >= 1")
    episodes = int(episodes)
    if wake_seeds is None:
        if episodes > len(HELD_OUT_WAKE_SEEDS):
            raise ConfigError(
                f"invalid config: `episodes` = {episodes} is outside the allowed range 1..{len(HELD_OUT_WAKE_SEEDS)} "
                "(held-out wake seeds; pass wake_seeds for more)"
            )
        wake_seeds = list(HELD_OUT_WAKE_SEEDS[:episodes])
    if len(wake_seeds) < episodes:
        raise ConfigError(f"invalid config: {len(wake_seeds)} wake seeds for {episodes} episodes; need at least as many")
    base = EVAL_BASE_SEED if seed is None else check_base_seed(seed, episodes, count="episodes")
    wanted = set(range(episodes)) if keep is None else {int(k) for k in keep}
    bad = sorted(k for k in wanted if not 0 <= k < episodes)
    if bad:
        raise ConfigError(f"invalid config: `keep` has episode {bad[0]}, outside the allowed range [0, {episodes})")
    label = _policy_label(policy)
    if isinstance(policy, str):
        policy = load_policy(policy, seed=policy_seed, config=config)
    batch = min(check_count(num_envs, "num_envs", 1, MAX_ENVS), episodes)  # the evaluation's batch: the policy sees the same rows
    recorder = _Recorder(label, base, batch)
    for _, rec in schedule_episodes(policy, wanted, recorder, seed=base, wake_seeds=wake_seeds, batch=batch,
                                    num_threads=num_threads, config=config):
        yield rec


def record_episodes(
    policy: Policy | str,
    episodes: Optional[int] = None,
    *,
    config: Optional[dict[str, Any]] = None,
    seed: Optional[int] = None,
    wake_seeds: Optional[Sequence[int]] = None,
    num_envs: int = 16,
    num_threads: int = 0,
    keep: Optional[Iterable[int]] = None,
    policy_seed: int = 0,
) -> list[Recording]:
    """Runs ``policy`` for ``episodes`` episodes and returns their recordings in index order.

    ``policy``: an :class:`accd_gym.control.registry.Policy`, or a spec for
    :func:`accd_gym.evals.policies.load_policy` (a controller's name, a tuning file, a shipped
    policy or a trained model; ``policy_seed`` seeds the random baseline). ``config``: env config
    overrides; the episodes run its physics, as the evaluation's do, and its env options
    (``residual``, ``history``) are the policy's (a trained model's own run options apply). ``seed``: the base seed of initial conditions and RLV
    motion (default the evaluation's, 20240607); ``wake_seeds``: episode ``k`` uses
    ``wake_seeds[k]`` (default the first ``episodes`` held-out wake seeds). ``num_envs``
    episodes run side by side on ``num_threads`` threads, as in
    :func:`accd_gym.evals.evaluation.run_episodes` with the same arguments, whose episodes these are.
    ``keep``: indices of the episodes to return (the others run, unrecorded).
    """
    recs = list(iter_recordings(policy, episodes, config=config, seed=seed, wake_seeds=wake_seeds,
                                num_envs=num_envs, num_threads=num_threads, keep=keep, policy_seed=policy_seed))
    return sorted(recs, key=lambda r: int(r.meta["episode"]))


class RecordEpisode(gym.Wrapper):
    """Records every episode of a single :class:`~accd_gym.InAirCaptureEnv` (also inside other
    wrappers such as ``TimeLimit``), whatever drives it.

    After each episode ends, its :class:`Recording` is appended to :attr:`recordings` (at most
    ``keep_last`` are kept, None for all) and, with ``folder``, saved as
    ``folder/episode_<n>.npz``. :attr:`current` is the episode being recorded. The env's own
    outputs pass through unchanged.
    """

    def __init__(self, env: gym.Env, folder: Optional[str | Path] = None, keep_last: Optional[int] = 10) -> None:
        super().__init__(env)
        if not isinstance(env.unwrapped, InAirCaptureEnv):
            raise ConfigError(
                f"invalid config: RecordEpisode wraps an accd_gym InAirCaptureEnv, got {type(env.unwrapped).__name__}"
            )
        self._core_env = env.unwrapped
        self.folder = None if folder is None else Path(folder)
        self.keep_last = keep_last
        #: Finished episodes (the last ``keep_last``).
        self.recordings: list[Recording] = []
        #: The episode being recorded, or None before the first reset.
        self.current: Optional[_Builder] = None
        self._meta: dict[str, Any] = {}
        self._count = 0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        """Resets the env and starts recording the new episode."""
        obs, info = self.env.reset(**kwargs)
        cfg = self._core_env.config
        self.current = _Builder(self._core_env.record_data(0), obs)
        self._meta = {
            "policy": "RecordEpisode",
            "episode": self._count,
            "env_index": 0,
            "num_envs": 1,
            "base_seed": None,
            "seeds": {k: int(v) for k, v in self._core_env.episode_seeds().items()},
            "config": cfg,
            "accd_geometry": accd_geometry(cfg),
            "agent_step": float(cfg["agent_step"]),
            "accd_gym_version": __version__,
            "divergence": None,
        }
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Steps the env and records the step (the action as the env received it, float32)."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.current is not None:
            a = np.clip(np.asarray(action, dtype=np.float32).reshape(4), -1.0, 1.0)
            self.current.add(self._core_env.record_data(0), obs, a, float(reward), bool(terminated),
                             bool(truncated), info)
            if terminated or truncated:
                meta = dict(self._meta, divergence=info.get("divergence"))
                rec = self.current.finish(meta)
                self.current = None
                self._count += 1
                if self.folder is not None:
                    rec.save(self.folder / f"episode_{rec.meta['episode']:04d}.npz")
                self.recordings.append(rec)
                if self.keep_last is not None and len(self.recordings) > self.keep_last:
                    del self.recordings[: len(self.recordings) - self.keep_last]
        return obs, reward, terminated, truncated, info


__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "Recording", "RecordEpisode", "SAMPLE_FIELDS", "STEP_FIELDS",
           "accd_geometry", "fields_markdown", "iter_recordings", "record_episodes"]


def fields_markdown() -> str:
    """The table of every array of a recording file (name, rows, unit, meaning), as in
    ``docs/recording-format.md`` (a test keeps the two equal)."""
    rows = ["| array | shape | dtype | unit | meaning |", "|---|---|---|---|---|"]
    shapes = {"joints": "(T+1, n+1, 3)", "tensions": "(T+1, n+1)", "attitude": "(T+1, 4)",
              "flap_deflection_deg": "(T+1, 4)", "flap_command_deg": "(T+1, 4)"}
    vectors = {"position", "velocity", "euler", "omega", "force", "moment", "capture_point", "capture_point_velocity",
               "boom_tip", "boom_velocity", "aircraft_velocity"}
    for name, (unit, meaning) in SAMPLE_FIELDS.items():
        shape = shapes.get(name, "(T+1, 3)" if name in vectors else "(T+1,)")
        rows.append(f"| `{name}` | {shape} | {'bool' if name == 'captured' else 'float64'} | {unit} | {meaning} |")
    rows.append("| `observation` | (T+1, 25) | float32 | - | the env's observation (scaled; `docs/environment.md`) |")
    rows.append("| `equilibrium` | (3,) | float64 | m | the ACCD's open-loop equilibrium |")
    for name, (unit, meaning) in STEP_FIELDS.items():
        if name == "action":
            shape, dtype = "(T, 4)", "float32"
        else:
            shape = "(T,)"
            dtype = ("bool" if name in ("terminated", "truncated") or name.removeprefix("info_") in _BOOL_INFO
                     else "int64" if name == "info_episode_steps" else "float64")
        rows.append(f"| `{name}` | {shape} | {dtype} | {unit} | {meaning} |")
    return "\n".join(rows)
