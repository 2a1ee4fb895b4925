"""The native gymnasium VectorEnv of ``accd_gym/InAirCapture-v0`` (``gymnasium.make_vec``)."""

from __future__ import annotations

from typing import Any, Optional, Sequence, Union

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from accd_gym import _core
from accd_gym.config import config_json, env_config
from accd_gym.core_env import CoreEnvMixin
from accd_gym.errors import ConfigError
from accd_gym.task import (
    EVENT_NAMES,
    INFO_NAMES,
    action_space,
    check_actions,
    observation_space,
    random_seed,
)

_MODES = {AutoresetMode.NEXT_STEP: "next_step", AutoresetMode.SAME_STEP: "same_step"}


class InAirCaptureVectorEnv(CoreEnvMixin, VectorEnv):
    """``num_envs`` In-Air Capturing episodes stepped together by the Rust core, on threads.

    The task (actions, observations, reward, episode end, seeds) is that of
    :class:`accd_gym.env.InAirCaptureEnv`; env ``i`` of a vector env seeded ``s`` is identical to
    env ``i`` of any other batch size or thread count seeded ``s``, and with ``seed=[s0, s1, ...]``
    env ``i`` replays the single env seeded ``s_i``.

    **Autoreset** (``metadata["autoreset_mode"]``): ``NEXT_STEP`` (default, gymnasium's own) or
    ``SAME_STEP``, chosen with ``autoreset_mode=``. Seeds and wake options given to ``reset``
    persist: automatic resets continue the seeded episode sequence with the same wake schedule.

    **Infos**: a dict of arrays (num_envs,) with a ``_name`` mask each: ``time``, ``distance``,
    ``relative_speed``, ``peak_tension``, ``episode_steps``, ``wake_seed`` and the flags
    ``captured``, ``overload``, ``envelope_exit``, ``diverged``. For an env whose episode ended,
    they describe the ending step. With ``SAME_STEP``, ``final_obs`` (object array, the ended
    episodes' last observations) and ``final_info`` (the same arrays, masked to the ended envs)
    are added, as gymnasium's own vector envs do.

    **Buffers (copy versus view)**: the arrays ``step`` and ``reset`` return are numpy arrays the
    Rust core writes in place (no copy per step). Two sets are used alternately, so an array stays
    valid through the next ``step`` and is overwritten by the one after; copy what you keep
    longer. ``final_obs`` entries are copies.

    ``num_threads``: threads stepping the envs (0: one per core). ``render_mode="rgb_array"``
    renders env 0 (``render()``) off-screen.
    """

    def __init__(
        self,
        num_envs: int = 1,
        *,
        autoreset_mode: Union[AutoresetMode, str] = AutoresetMode.NEXT_STEP,
        num_threads: int = 0,
        render_mode: Optional[str] = None,
        **config: Any,
    ) -> None:
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            mode = None
        if mode not in _MODES:
            raise ConfigError(
                f"invalid config: `autoreset_mode` = {autoreset_mode!r} is outside the allowed range NEXT_STEP or SAME_STEP"
            )
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(
                f"invalid config: `render_mode` = {render_mode!r} is outside the allowed range 'rgb_array' or None"
            )
        self._config = env_config(config)
        self._core = _core.BatchEnv(config_json(self._config), int(num_envs), random_seed(), _MODES[mode], int(num_threads))
        self.num_envs = self._core.num_envs
        self.render_mode = render_mode
        self.metadata = {
            "autoreset_mode": mode,
            "render_modes": ["rgb_array"],
            "render_fps": 1.0 / self._config["agent_step"],
        }
        self.single_observation_space = observation_space()
        self.single_action_space = action_space()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    def reset(
        self,
        *,
        seed: Optional[Union[int, Sequence[int]]] = None,
        options: Optional[dict[str, Any]] = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Starts new episodes in every env; returns ``(observations, infos)``.

        ``seed``: an int (env ``i``: base seed, index ``i``), a list of ints (one per env) or None
        (each env's next episode). ``options``: ``{"wake_seed": int | None}`` or
        ``{"wake_seeds": [int, ...]}`` (persist over later resets).
        """
        if seed is not None:
            self._np_random, self._np_random_seed = gym.utils.seeding.np_random(
                seed if isinstance(seed, int) else int(seed[0])
            )
        if seed is not None and not isinstance(seed, int):
            seed = [int(s) for s in seed]
            if len(seed) != self.num_envs:
                raise ConfigError(
                    f"invalid config: `seed` has {len(seed)} values, expected num_envs = {self.num_envs}"
                )
        obs, wake = self._reset_core(seed, options)
        mask = np.ones(self.num_envs, dtype=bool)
        return obs, {"wake_seed": wake, "_wake_seed": mask}

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One agent step of every env; returns ``(obs, rewards, terminations, truncations, infos)``."""
        if self._needs_reset:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = check_actions(actions, self.num_envs)
        obs, reward, terminated, truncated, final_obs, info, wake, autoreset = self._core.step(a)
        mask = np.ones(self.num_envs, dtype=bool)
        infos: dict[str, Any] = {}
        for k, name in enumerate(INFO_NAMES):
            column = info[:, k]
            if name in EVENT_NAMES:
                column = column > 0.5
            elif name == "episode_steps":
                column = column.astype(np.int64)
            infos[name] = column
            infos["_" + name] = mask
        infos["wake_seed"] = wake
        infos["_wake_seed"] = mask
        if self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP:
            done = terminated | truncated
            if done.any():
                finals = np.full(self.num_envs, None, dtype=object)
                for i in np.flatnonzero(done):
                    finals[i] = final_obs[i].copy()
                infos["final_obs"] = finals
                infos["_final_obs"] = done.copy()
                final_info: dict[str, Any] = {}
                for key, value in infos.items():
                    if key not in ("final_obs", "_final_obs"):
                        final_info[key] = done.copy() if key.startswith("_") else value
                infos["final_info"] = final_info
        return obs, reward, terminated, truncated, infos

    def render(self) -> Optional[np.ndarray]:
        """Env 0 as an RGB array (``render_mode="rgb_array"``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        from accd_gym.render import render_frame

        return render_frame(self._core.render_data(0))

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release: the Rust core frees its memory and threads when dropped."""

    def __getstate__(self) -> dict[str, Any]:
        return {
            "num_envs": self.num_envs,
            "autoreset_mode": self.metadata["autoreset_mode"],
            "num_threads": self._core.num_threads,
            "render_mode": self.render_mode,
            "config": self._config,
            "state": self.get_state(),
        }

    def __setstate__(self, d: dict[str, Any]) -> None:
        self.__init__(
            d["num_envs"],
            autoreset_mode=d["autoreset_mode"],
            num_threads=d["num_threads"],
            render_mode=d["render_mode"],
            **d["config"],
        )
        self.set_state(d["state"])
