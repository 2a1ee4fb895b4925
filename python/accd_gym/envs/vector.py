"""The native gymnasium VectorEnv of ``accd_gym/InAirCapture-v0`` (``gymnasium.make_vec``)."""

from __future__ import annotations

import json

from typing import Any, Optional, Sequence, Union

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from accd_gym import _core
from accd_gym.envs.config import valid_config, with_arguments
from accd_gym.envs.core_env import CoreEnvMixin
from accd_gym.envs.agent_io import AgentIO, split_agent_options
from accd_gym.errors import ConfigError
from accd_gym.envs.task import (
    EVENT_NAMES,
    INFO_NAMES,
    MAX_ENVS,
    MAX_THREADS,
    action_space,
    check_actions,
    check_base_seed,
    check_count,
    check_flag,
    check_max_episode_steps,
    check_seed,
    observation_space,
    random_seed,
)
from accd_gym.envs.task import WAKE_SEED_BOUND
from accd_gym.envs.render import render_frame

#: Per info column (``INFO_NAMES``): whether it is an event (reported as bool) or the step count
#: (int64); the others are float64.
_IS_EVENT = tuple(name in EVENT_NAMES for name in INFO_NAMES)
_IS_COUNT = tuple(name == "episode_steps" for name in INFO_NAMES)

_MODES = {
    AutoresetMode.NEXT_STEP: "next_step",
    AutoresetMode.SAME_STEP: "same_step",
    AutoresetMode.DISABLED: "disabled",
}


class InAirCaptureVectorEnv(CoreEnvMixin, VectorEnv):
    """``num_envs`` In-Air Capturing episodes stepped together by the Rust core, on threads.

    The task (actions, observations, reward, episode end, seeds) is that of
    :class:`accd_gym.envs.env.InAirCaptureEnv`. The vector env behaves as gymnasium's
    ``SyncVectorEnv`` of single envs (``gymnasium.make_vec(..., vectorization_mode="sync")``):
    the same observations, rewards, flags and infos, dtypes included, in every autoreset mode and
    with partial resets (``tests/test_vector_equivalence.py`` compares them step by step,
    ``tests/test_vector_rollouts.py`` whole rollouts of every registered tier).

    **Seeds**: ``reset(seed=s)`` gives env ``i`` the seed ``s + i``, ``seed=[s0, s1, ...]`` the
    seed ``s_i``: env ``i`` then replays the single env with that seed, whatever the batch size
    or thread count. Python and numpy integers are accepted; bools, floats and strings are not.
    Every seed lies in the one seed range [0, 2^63) (:data:`accd_gym.envs.task.SEED_END`: the
    wake seeds reported as int64 in the infos never wrap): an int ``s`` lies in
    [0, 2^63 - num_envs] (a larger one raises ConfigError naming the range, where
    ``SyncVectorEnv`` raises it from the env whose seed ``s + i`` passes 2^63 - 1), list entries
    in [0, 2^63).

    **Autoreset** (``metadata["autoreset_mode"]``, chosen with ``autoreset_mode=``, an
    ``AutoresetMode``, its value or ``"next_step"``/``"same_step"``/``"disabled"``):
    ``NEXT_STEP`` (default), ``SAME_STEP`` or ``DISABLED`` (a step of a batch with an ended env
    raises ``StateError``; reset it with ``options={"reset_mask": mask}``). Seeds and wake options
    given to ``reset`` persist: automatic resets continue the seeded episode sequence with the
    same wake schedule. ``reset(options={"reset_mask": mask})`` (a (num_envs,) bool array)
    resets only the selected envs, in every mode.

    **Infos**: a dict of arrays (num_envs,) with a ``_name`` mask each, as ``SyncVectorEnv``
    batches the single env's info dicts: ``time``, ``distance``, ``relative_speed``,
    ``peak_tension`` (float64), ``captured``, ``overload``, ``envelope_exit``, ``diverged``
    (bool), ``episode_steps`` (int64), ``divergence`` (object, only when an env diverged) are
    the step's; ``wake_seed`` (int64) is every env's. An env reset in this step (``NEXT_STEP``:
    the step after its episode ended; ``SAME_STEP``: the step that ended it) reports its new
    episode's reset info, as the single env's ``reset`` gives it: ``wake_seed`` and, with
    randomized physics, ``parameters`` (a dict of float64 arrays with their ``_name`` masks, the
    drawn parameters); its step entries are 0 with the mask False. With ``SAME_STEP``,
    ``final_obs`` (object array, the ended episodes' last observations) and ``final_info`` (the
    ended episodes' step infos, masked to the ended envs) are added. ``reset`` returns the reset
    info (``wake_seed``, ``parameters``) of the envs it reset.

    **Wake-seed lists** (``options={"wake_seeds": W}``): the batch covers the list, env ``i``'s
    episode ``e`` (counted from the last seeding) using ``W[(i + e * num_envs) % len(W)]``: a
    ``SyncVectorEnv`` would give every env the same entry, evaluating each wake ``num_envs``
    times. Wake options cannot be combined with a partial ``reset_mask`` (the schedule is the
    batch's).

    **Copies** (``copy=True``, the default, as ``SyncVectorEnv``; the attribute ``copy``): every
    array ``step`` and ``reset`` return is new, never changed by the env afterwards.
    ``copy=False`` (also through ``gymnasium.make_vec(..., copy=False)``) returns the
    observation, reward, termination and truncation arrays that the Rust core writes in place
    instead, saving their copy: two sets are used alternately, so such an array stays valid
    through the next ``step`` or ``reset`` and is overwritten by the call after it; copy what you
    keep longer. Info arrays and ``final_obs`` entries are new in both modes.

    ``max_episode_steps`` (passed by ``gymnasium.make_vec`` from the registered spec): at least
    the configuration's episode length (``capture_window / agent_step``), which ends episodes
    (truncation); a shorter limit raises ConfigError (pass ``max_episode_steps=`` with a longer
    ``capture_window``). ``num_envs``: an integer in [1, 65536]; ``num_threads``: threads
    stepping the envs, an integer in [0, 1024] (0: one per core); Python or numpy integers only
    (ConfigError naming the argument otherwise: ``"3"``, ``2.7`` and ``True`` are refused). ``render_mode="rgb_array"``:
    ``render()`` returns a tuple of one RGB frame per env, as ``SyncVectorEnv`` does.

    **Residual control and observation history** (``residual=``, ``history=``; off by default):
    the env options of :mod:`accd_gym.envs.agent_io` (the base controller and the history of each env
    restart with its episode, automatic resets included; ``final_obs`` are the agent's
    observations too). The observation then has the layout given there and in
    ``docs/environment.md``; the arrays are new each step.

    **True observation** (``true_observation=True``; off by default): ``infos["true_obs"]``
    ((num_envs, 25) float32, mask ``_true_obs``) is every env's noise-free, delay-free
    observation of the state its returned observation describes (:mod:`accd_gym.envs.agent_io`),
    in ``reset`` for the envs it reset; with ``SAME_STEP``, ``final_info["true_obs"]`` is the
    ended episodes' last.

    **Arguments** besides ``num_envs``, ``seed``, ``num_threads``, ``autoreset_mode``,
    ``copy``, ``render_mode``, ``max_episode_steps``, ``residual`` and ``history``: the configuration keys (as for the single env),
    a section a dict of its keys, ``tether`` also a preset name:

    {CONFIG_ARGUMENTS}
    """

    _state_kind = "vector"

    def __init__(
        self,
        num_envs: int = 1,
        *,
        autoreset_mode: Union[AutoresetMode, str] = AutoresetMode.NEXT_STEP,
        num_threads: int = 0,
        copy: bool = True,
        render_mode: Optional[str] = None,
        max_episode_steps: Optional[int] = None,
        **config: Any,
    ) -> None:
        n = check_count(num_envs, "num_envs", 1, MAX_ENVS)
        threads = check_count(num_threads, "num_threads", 0, MAX_THREADS)
        by_name = {name: m for m, name in _MODES.items()}
        if isinstance(autoreset_mode, str) and autoreset_mode in by_name:
            mode: Optional[AutoresetMode] = by_name[autoreset_mode]
        else:
            try:
                mode = AutoresetMode(autoreset_mode)
            except ValueError:
                mode = None
        if mode not in _MODES:
            raise ConfigError(
                f"invalid config: `autoreset_mode` = {autoreset_mode!r} is outside the allowed range: an AutoresetMode, "
                f"its value ({', '.join(repr(m.value) for m in _MODES)}) or {', '.join(map(repr, by_name))}"
            )
        self.copy = check_flag(copy, "copy")
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(
                f"invalid config: `render_mode` = {render_mode!r} is outside the allowed range 'rgb_array' or None"
            )
        # Validated once; a user aerodynamic table is kept as its contents: pickles and saved
        # states need no file.
        self.agent_options, config = split_agent_options(config)
        valid = valid_config(config)
        self._config = json.loads(valid.to_json())
        self._randomized = bool(self._config["randomization"]["enabled"])
        check_max_episode_steps(max_episode_steps, self._config)
        self._core = _core.BatchEnv(valid, n, random_seed(n), _MODES[mode], threads)
        if self.agent_options.true_observation:
            self._core.set_true_observation(True)
        self.num_envs = self._core.num_envs
        self._agent_io = AgentIO.create(self.agent_options, self._config, self.num_envs, self._core)
        self.render_mode = render_mode
        self.metadata = {
            "autoreset_mode": mode,
            "render_modes": ["rgb_array"],
            "render_fps": 1.0 / self._config["agent_step"],
        }
        self.single_observation_space = observation_space() if self._agent_io is None else self._agent_io.observation_space
        self.single_action_space = action_space()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    def reset(
        self,
        *,
        seed: Optional[Union[int, Sequence[int]]] = None,
        options: Optional[dict[str, Any]] = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Starts new episodes in every env (or those ``options["reset_mask"]`` selects); returns
        ``(observations, infos)``.

        ``seed``: an int (env ``i``: seed ``seed + i``; in [0, 2^63 - num_envs], so that every
        env's seed is in the seed range [0, 2^63): ConfigError otherwise), a list of ints in
        [0, 2^63) (one per env) or None
        (each env's next episode). ``options``: ``{"wake_seed": int | None}`` or
        ``{"wake_seeds": [int, ...]}`` (persist over later resets), ``{"reset_mask": mask}``
        (a (num_envs,) bool numpy array with at least one True: only those envs are reset).
        """
        options = dict(options) if options else {}
        mask = self._reset_mask(options.pop("reset_mask")) if "reset_mask" in options else None
        if mask is not None and options and not mask.all():
            raise ConfigError(
                f"invalid config: reset options {sorted(options)} with a partial `reset_mask`: the wake schedule is "
                "the whole batch's; set it in a reset of every env"
            )
        seeds = self._seeds(seed)
        if seeds is not None:
            first = seeds if isinstance(seeds, int) else seeds[0]
            self._np_random, self._np_random_seed = gym.utils.seeding.np_random(first)
            per_env = [seeds + i for i in range(self.num_envs)] if isinstance(seeds, int) else list(seeds)
            current = list(self.np_random_seed)
            for i in range(self.num_envs):
                if mask is None or mask[i]:
                    current[i] = per_env[i]
            self._env_seeds = tuple(current)
        obs, wake = self._reset_core(seeds, options or None, mask)
        if self._agent_io is not None:
            obs = self._agent_io.begin(obs, mask)
        selected = np.ones(self.num_envs, dtype=bool) if mask is None else mask.copy()
        wake_seed = wake.astype(np.int64)
        wake_seed[~selected] = 0
        infos = self._add_parameters({"wake_seed": wake_seed, "_wake_seed": selected}, selected)
        true_obs = self._true_observations()
        if true_obs is not None:
            true_obs[~selected] = 0
            infos["true_obs"] = true_obs
            infos["_true_obs"] = selected.copy()
        return (obs.copy() if self.copy else obs), infos

    def start_episode(self, i: int, seed: int, wake_seed: Optional[int] = None) -> np.ndarray:
        """Starts a new episode in env ``i`` alone and returns every env's observations (a copy).

        The new episode is the first one of a single env reset with ``seed=seed`` and
        ``options={"wake_seed": wake_seed}`` (``wake_seed=None``: a training draw of that seed),
        bit for bit; the other envs are left as they are and the batch's wake schedule for
        later resets is kept. Held-out evaluation (:mod:`accd_gym.evals.evaluation`) starts episode
        ``k`` this way, which makes it independent of the batch size and of its place in a batch.
        """
        i = self._env_index(i)

        seed = check_seed(seed)
        wake = None if wake_seed is None else check_seed(wake_seed, "wake_seed", WAKE_SEED_BOUND)
        kind, kept = self._core.wake_schedule()
        self._core.set_wake_schedule("training", []) if wake is None else self._core.set_wake_schedule("fixed", [wake])
        try:
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[i] = True
            seeds = list(self.np_random_seed)
            seeds[i] = seed
            obs, _ = self.reset(seed=seeds, options={"reset_mask": mask})
        finally:
            self._core.set_wake_schedule(kind, kept)
        return obs if self.copy else obs.copy()

    def set_controller(self, policy: Any) -> None:
        """Runs ``policy``'s Rust stepper (an :class:`~accd_gym.control.lqr.LqrPolicy` or
        :class:`~accd_gym.control.mpc.MpcPolicy` designed for this env's configuration; its
        ``batch_stepper()``) per env in the batch's own threads: from the next reset on, each
        env's command for its new observation is computed right after the env's reset or step,
        with the GIL released, and each step tells it the action sent. Read the commands with
        :meth:`controller_commands`; they are the bits the policy's ``predict`` would give. None
        removes it. Not with the ``residual`` env option (whose base runs there already)."""
        if self._agent_io is not None and self.agent_options.residual is not None:
            raise ConfigError("invalid config: `set_controller` on an env with the `residual` option, whose base "
                              "controller the batch steps already")
        self._core.set_controller(None if policy is None else policy.batch_stepper())

    def controller_commands(self) -> np.ndarray:
        """The commands ((num_envs, 4) float32) of :meth:`set_controller`'s controller for every
        env's latest observation (StateError without one)."""
        return self._core.controller_commands()

    def controller_stats(self) -> tuple[int, int, int, int]:
        """``(steps, constrained, inexact, fallbacks)`` of :meth:`set_controller`'s MPC solves,
        summed over the envs (zeros for the LQR)."""
        return self._core.controller_stats()

    @property
    def np_random_seed(self) -> tuple[int, ...]:  # type: ignore[override]
        """The seed of each env's episodes, as ``SyncVectorEnv`` reports its envs' seeds: ``s + i``
        after ``reset(seed=s)``, the list entries after a list, unchanged by unseeded resets; a
        random seed per env before the first seeded reset."""
        seeds = getattr(self, "_env_seeds", None)
        if seeds is None:
            seeds = tuple(int(gym.utils.seeding.np_random(None)[1]) for _ in range(self.num_envs))
            self._env_seeds = seeds
        return seeds

    def _seeds(self, seed: Any) -> Union[None, int, list[int]]:
        """``reset``'s seed argument, checked: None, an int, or a list of num_envs ints."""
        if seed is None:
            return None
        if isinstance(seed, (list, tuple, np.ndarray)):
            if len(seed) != self.num_envs:
                raise ConfigError(
                    f"invalid config: `seed` has {len(seed)} values, expected num_envs = {self.num_envs}"
                )
            return [check_seed(s) for s in seed]
        return check_base_seed(seed, self.num_envs)

    def _reset_mask(self, mask: Any) -> np.ndarray:
        """``options["reset_mask"]``, checked as ``SyncVectorEnv`` checks it."""
        if not isinstance(mask, np.ndarray):
            raise TypeError(f"`options['reset_mask']` must be a numpy array, got {type(mask)}")
        if mask.shape != (self.num_envs,):
            raise ValueError(f"`options['reset_mask']` must have shape `({self.num_envs},)`, got {mask.shape}")
        if mask.dtype != np.bool_:
            raise TypeError(f"`options['reset_mask']` must have `dtype=np.bool_`, got {mask.dtype}")
        if not mask.any():
            raise ValueError(
                f"`options['reset_mask']` must contain a boolean array with at least one True value, got reset_mask={mask}"
            )
        return mask

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One agent step of every env; returns ``(obs, rewards, terminations, truncations, infos)``."""
        if self._needs_reset:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = check_actions(actions, self.num_envs)
        if self._agent_io is not None:
            a = self._agent_io.command(a)
        obs, reward, terminated, truncated, final_obs, info, wake, autoreset = self._core.step(a)
        mode = self.metadata["autoreset_mode"]
        if self._agent_io is not None:
            ended = (terminated | truncated) if mode == AutoresetMode.SAME_STEP else None
            started = autoreset if mode == AutoresetMode.NEXT_STEP else ended
            obs, final_obs = self._agent_io.advance(obs, started, final_obs, ended)
        wake_seed = wake.astype(np.int64)
        if mode == AutoresetMode.NEXT_STEP:
            stepped = ~autoreset
        elif mode == AutoresetMode.SAME_STEP:
            stepped = ~(terminated | truncated)
        else:
            stepped = np.ones(self.num_envs, dtype=bool)
        infos = self._step_infos(info, wake_seed, stepped)
        if mode == AutoresetMode.SAME_STEP and not stepped.all():
            done = ~stepped
            finals = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(done):
                finals[i] = final_obs[i].copy()
                wake_seed[i] = self._core.episode_seeds(int(i))["wake"]
            infos["final_obs"] = finals
            infos["_final_obs"] = done.copy()
            infos["final_info"] = self._step_infos(info, wake.astype(np.int64), done, ended=True)
            infos["_final_info"] = done.copy()
            if self.agent_options.true_observation:
                final_true = self._core.final_true_observations()
                final_true[stepped] = 0
                infos["final_info"]["true_obs"] = final_true
                infos["final_info"]["_true_obs"] = done.copy()
        infos["wake_seed"] = wake_seed
        infos["_wake_seed"] = np.ones(self.num_envs, dtype=bool)
        true_obs = self._true_observations()
        if true_obs is not None:
            infos["true_obs"] = true_obs
            infos["_true_obs"] = np.ones(self.num_envs, dtype=bool)
        if self._randomized and mode != AutoresetMode.DISABLED:
            self._add_parameters(infos, ~stepped)
        if self.copy:
            return obs.copy(), reward.copy(), terminated.copy(), truncated.copy(), infos
        return obs, reward, terminated, truncated, infos

    def _add_parameters(self, infos: dict[str, Any], rows: np.ndarray) -> dict[str, Any]:
        """``infos`` with the reset info that the rows' new episodes have beyond ``wake_seed``
        (randomized physics: the drawn ``parameters``), batched by ``VectorEnv._add_info`` as
        ``SyncVectorEnv`` batches the single env's reset infos."""
        if not self._randomized or not np.count_nonzero(rows):
            return infos
        for i in np.flatnonzero(rows).tolist():
            infos = self._add_info(infos, {"parameters": self._core.episode_parameters(i)}, i)
        return infos

    def _step_infos(
        self, info: np.ndarray, wake_seed: np.ndarray, rows: np.ndarray, ended: bool = False
    ) -> dict[str, Any]:
        """The step infos of the envs ``rows`` selects, batched as ``SyncVectorEnv`` batches the
        single env's info dicts (other entries 0 with the mask False; no keys if none).
        ``ended``: the rows' episodes ended and were replaced in this step (``SAME_STEP``)."""
        out: dict[str, Any] = {}
        # (np.count_nonzero is several times cheaper than .any()/.all() on a small bool array.)
        selected = np.count_nonzero(rows)
        if selected == 0:
            return out
        # Every column at once: the info transposed, each key's values one contiguous row of it
        # (each key its own memory, as SyncVectorEnv gives each its own array).
        values = info.T.copy()
        seeds = wake_seed.astype(np.int64)
        if selected < rows.size:
            unselected = ~rows
            values[:, unselected] = 0
            seeds[unselected] = 0
        events = values > 0.5
        for k, name in enumerate(INFO_NAMES):
            if _IS_EVENT[k]:
                out[name] = events[k]
            elif _IS_COUNT[k]:
                out[name] = values[k].astype(np.int64)
            else:
                out[name] = values[k]
            out["_" + name] = rows.copy()
        out["wake_seed"] = seeds
        out["_wake_seed"] = rows.copy()
        diverged = out["diverged"]
        if np.count_nonzero(diverged):
            messages = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(diverged):
                messages[i] = (self._core.final_divergence if ended else self._core.divergence)(int(i))
            out["divergence"] = messages
            out["_divergence"] = diverged.copy()
        return out

    def render(self) -> Optional[tuple[np.ndarray, ...]]:
        """One RGB frame per env (``render_mode="rgb_array"``), as ``SyncVectorEnv`` returns them."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None

        return tuple(render_frame(self._core.render_data(i)) for i in range(self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release: the Rust core frees its memory and threads when dropped."""

    def __getstate__(self) -> dict[str, Any]:
        return {
            "num_envs": self.num_envs,
            "autoreset_mode": self.metadata["autoreset_mode"],
            "num_threads": self._core.num_threads,
            "copy": self.copy,
            "render_mode": self.render_mode,
            "config": self._config,
            "agent": self.agent_options.to_dict(),
            "state": self.get_state(),
        }

    def __setstate__(self, d: dict[str, Any]) -> None:
        self.__init__(
            d["num_envs"],
            autoreset_mode=d["autoreset_mode"],
            num_threads=d["num_threads"],
            copy=d.get("copy", True),
            render_mode=d["render_mode"],
            **d["config"],
            **d.get("agent", {}),
        )
        self.set_state(d["state"])


InAirCaptureVectorEnv.__doc__ = with_arguments(InAirCaptureVectorEnv.__doc__)
