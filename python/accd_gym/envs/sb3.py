"""The native stable-baselines3 VecEnv: ``accd_gym.AccdVecEnv(num_envs=N, **config)``."""

from __future__ import annotations

import json

from typing import Any, Optional, Sequence, Union

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from accd_gym import _core
from accd_gym.envs.config import valid_config, with_arguments
from accd_gym.envs.core_env import CoreEnvMixin
from accd_gym.envs.agent_io import AgentIO, split_agent_options
from accd_gym.errors import ConfigError
from accd_gym.envs.task import (
    DIVERGED_COLUMN,
    MAX_ENVS,
    MAX_THREADS,
    action_space,
    check_actions,
    check_base_seed,
    check_count,
    check_flag,
    info_dicts,
    observation_space,
    random_seed,
)
from accd_gym.envs.render import render_frame


class AccdVecEnv(CoreEnvMixin, VecEnv):
    """``num_envs`` In-Air Capturing episodes as a stable-baselines3 ``VecEnv``, stepped by Rust.

    The task is that of :class:`accd_gym.envs.env.InAirCaptureEnv` (see its docstring for the
    observation, action, reward and episode-end tables). It behaves as SB3's ``DummyVecEnv`` of
    single envs (``tests/test_vector_equivalence.py`` compares them step by step,
    ``tests/test_vector_rollouts.py`` whole rollouts of every registered tier):

    * same-step autoreset: when an episode ends, ``step_wait`` returns the next episode's first
      observation, ``done=True``, and ``infos[i]["terminal_observation"]`` (a copy of the ended
      episode's last observation); ``reset_infos[i]`` becomes the new episode's reset info;
      ``infos[i]["TimeLimit.truncated"]`` is in every info (True when the capture window ran out
      without a termination);
    * ``seed(s)`` and ``set_options(...)`` apply at the next ``reset()``; env ``i`` then replays
      the single env seeded ``s + i``, automatic resets included; wake options (``wake_seed``,
      ``wake_seeds``) persist over later resets;
    * rewards are float32, dones bool, infos a list of dicts (``time``, ``distance``,
      ``relative_speed``, ``peak_tension``, ``captured``, ``overload``, ``envelope_exit``,
      ``diverged``, ``episode_steps``, ``wake_seed``, ``TimeLimit.truncated``, and
      ``divergence`` when the env diverged); ``reset_infos[i]`` is the single env's reset info
      (``wake_seed``, and with randomized physics the drawn ``parameters``), after ``reset()``
      and after each automatic reset;

    **Copies** (``copy=True``, the default, as ``DummyVecEnv``; the attribute ``copy``): the
    observations, rewards and dones ``step`` and ``reset`` return are new arrays, never changed
    by the env afterwards. ``copy=False`` returns the observation array that the Rust core writes
    in place instead, saving its copy: two sets are used alternately, so it stays valid through
    the next ``step`` or ``reset`` (what SB3's rollout collection needs: it copies the previous
    observation into its buffer) and is overwritten by the call after it. Rewards, dones, infos
    and ``terminal_observation`` entries are new in both modes. The GIL is released while the
    envs step on ``num_threads`` threads (0: one per core). Works under ``VecMonitor`` and
    ``VecNormalize``.

    Residual control and observation history (``residual=``, ``history=``; off by default): the
    env options of :mod:`accd_gym.envs.agent_io`; ``terminal_observation`` is then the agent's
    observation of the ended episode's last state.

    True observation (``true_observation=True``; off by default): every info has ``true_obs``,
    the noise-free, delay-free observation (:mod:`accd_gym.envs.agent_io`); for an ended episode
    it is its last step's (beside ``terminal_observation``) and ``reset_infos[i]["true_obs"]``
    is the new episode's first.

    Arguments besides ``num_envs``, ``seed``, ``num_threads``, ``copy``, ``render_mode``, ``residual`` and
    ``history``: the
    configuration keys (as for the single env), a section a dict of its keys, ``tether`` also a
    preset name:

    {CONFIG_ARGUMENTS}
    """

    _state_kind = "sb3"

    def __init__(
        self,
        num_envs: int = 1,
        *,
        seed: Optional[int] = None,
        num_threads: int = 0,
        copy: bool = True,
        render_mode: Optional[str] = None,
        **config: Any,
    ) -> None:
        n = check_count(num_envs, "num_envs", 1, MAX_ENVS)
        threads = check_count(num_threads, "num_threads", 0, MAX_THREADS)
        self.copy = check_flag(copy, "copy")
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(
                f"invalid config: `render_mode` = {render_mode!r} is outside the allowed range 'rgb_array' or None"
            )
        self.render_mode = render_mode
        # Validated once; a user aerodynamic table is kept as its contents: pickles and saved
        # states need no file.
        self.agent_options, config = split_agent_options(config)
        valid = valid_config(config)
        self._config = json.loads(valid.to_json())
        base = random_seed(n) if seed is None else check_base_seed(seed, n)
        self._core = _core.BatchEnv(valid, n, base, "same_step", threads)
        if self.agent_options.true_observation:
            self._core.set_true_observation(True)
        self._agent_io = AgentIO.create(self.agent_options, self._config, self._core.num_envs, self._core)
        self._actions: Optional[np.ndarray] = None
        self._base_seed: Optional[int] = None if seed is None else base
        self._pending_options: dict[str, Any] = {}
        space = observation_space() if self._agent_io is None else self._agent_io.observation_space
        super().__init__(self._core.num_envs, space, action_space())
        self.metadata["render_fps"] = 1.0 / self._config["agent_step"]

    def seed(self, seed: Optional[int] = None) -> Sequence[Optional[int]]:
        """Seeds the envs at the next ``reset()``: env ``i`` gets seed ``seed + i`` (as
        ``DummyVecEnv``); returns those seeds. ``seed`` is an integer in [0, 2^63 - num_envs], so
        that every env's seed lies in the seed range [0, 2^63) (ConfigError otherwise, here rather than at the reset where
        ``DummyVecEnv``'s single env would raise it)."""
        self._base_seed = random_seed(self.num_envs) if seed is None else check_base_seed(seed, self.num_envs)
        return [self._base_seed + i for i in range(self.num_envs)]

    def drop_pending_seed(self) -> None:
        """Makes the next ``reset()`` continue each env's episode sequence instead of reseeding it
        with the constructor's or :meth:`seed`'s seed (e.g. after :meth:`set_state` restored a run)."""
        self._base_seed = None

    def set_options(self, options: Optional[Union[list[dict], dict]] = None) -> None:
        """Wake options (``wake_seed``, ``wake_seeds``) applied at the next ``reset()``."""
        if isinstance(options, list):
            if any(o != options[0] for o in options):
                raise ConfigError("invalid config: per-env options differ; AccdVecEnv takes one options dict for all envs")
            options = options[0] if options else None
        self._pending_options = dict(options or {})

    def reset(self) -> np.ndarray:
        """Starts new episodes in every env (with the pending seed and options)."""
        obs, wake = self._reset_core(self._base_seed, self._pending_options)
        if self._agent_io is not None:
            obs = self._agent_io.begin(obs)
        self._pending_options = {}
        self._base_seed = None
        true_obs = self._true_observations()
        self.reset_infos = [self._reset_info(i, w, true_obs) for i, w in enumerate(wake.tolist())]
        return obs.copy() if self.copy else obs

    def step_async(self, actions: np.ndarray) -> None:
        """Stores the actions ((num_envs, 4); the shape is checked here, finiteness by the step)."""
        self._actions = check_actions(actions, self.num_envs)

    def step_wait(self) -> VecEnvStepReturn:
        """Steps every env with the stored actions; see the class docs for the returns."""
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async()")
        actions = self._actions if self._agent_io is None else self._agent_io.command(self._actions)
        obs, reward, terminated, truncated, final_obs, info, wake, _ = self._core.step(actions)
        self._actions = None
        dones = terminated | truncated
        if self._agent_io is not None:
            obs, final_obs = self._agent_io.advance(obs, dones, final_obs, dones)
        infos = info_dicts(info, wake)
        for i in np.flatnonzero(info[:, DIVERGED_COLUMN]):  # ended and replaced in this step
            infos[i]["divergence"] = self._core.final_divergence(int(i))
        for d, time_limit in zip(infos, (truncated & ~terminated).tolist()):
            d["TimeLimit.truncated"] = time_limit
        true_obs = self._true_observations()
        if true_obs is not None:
            final_true = self._core.final_true_observations() if np.count_nonzero(dones) else None
            for i, d in enumerate(infos):
                d["true_obs"] = (final_true if dones[i] else true_obs)[i].copy()
        for i in np.flatnonzero(dones):
            infos[i]["terminal_observation"] = final_obs[i].copy()
            self.reset_infos[i] = self._reset_info(int(i), self._core.episode_seeds(int(i))["wake"], true_obs)
        # (The rewards' conversion and the dones are new arrays already.)
        return (obs.copy() if self.copy else obs), reward.astype(np.float32), dones, infos

    def close(self) -> None:
        """Nothing to release: the Rust core frees its memory and threads when dropped."""

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute of this env (the same for every index), e.g. ``render_mode``."""
        return [getattr(self, attr_name) for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Sets an attribute of this env (shared by every index)."""
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any) -> list[Any]:
        """Calls a method of this env once per index."""
        return [getattr(self, method_name)(*method_args, **method_kwargs) for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """False: the native envs are never wrapped by gymnasium wrappers."""
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[Optional[np.ndarray]]:
        """An RGB picture of every env (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return [None for _ in range(self.num_envs)]

        return [render_frame(self._core.render_data(i)) for i in range(self.num_envs)]

    def __getstate__(self) -> dict[str, Any]:
        return {
            "num_envs": self.num_envs,
            "num_threads": self._core.num_threads,
            "copy": self.copy,
            "render_mode": self.render_mode,
            "config": self._config,
            "agent": self.agent_options.to_dict(),
            "state": self.get_state(),
            # What seed() and set_options() left for the next reset().
            "base_seed": self._base_seed,
            "pending_options": self._pending_options,
        }

    def __setstate__(self, d: dict[str, Any]) -> None:
        self.__init__(d["num_envs"], num_threads=d["num_threads"], copy=d.get("copy", True), render_mode=d["render_mode"],
                      **d["config"], **d.get("agent", {}))
        self.set_state(d["state"])
        self._base_seed = d["base_seed"]
        self._pending_options = d["pending_options"]


AccdVecEnv.__doc__ = with_arguments(AccdVecEnv.__doc__)
