"""The single gymnasium environment ``accd_gym/InAirCapture-v0``."""

from __future__ import annotations

import json

from typing import Any, Optional

import gymnasium as gym
import numpy as np

from accd_gym import _core
from accd_gym.envs.config import valid_config, with_arguments
from accd_gym.envs.tables import with_task_tables
from accd_gym.envs.core_env import CoreEnvMixin
from accd_gym.envs.task import (
    action_space,
    check_actions,
    check_seed,
    info_dicts,
    observation_space,
    random_seed,
)
from accd_gym.envs.agent_io import AgentIO, split_agent_options
from accd_gym.errors import ConfigError
from accd_gym.envs.render import HumanViewer, render_frame


class InAirCaptureEnv(CoreEnvMixin, gym.Env):
    """Guide the capturing device (ACCD) at the end of a towed tether onto the RLV's boom.

    ## Description

    DLR's *In-Air Capturing*: an A340-600 towing aircraft (TA) flies at 185 m/s and 6000 m with a
    250 m UHMWPE tether; the 1.5 m ACCD at its end steers with four flaps (+-15 deg) through the
    TA's wake and its turbulence. A reusable launch vehicle (RLV) flies in formation behind and
    below; its boom tip drifts and is perturbed. The agent must bring the ACCD's rear capture point
    onto the boom tip within the capture window (70 s). Physics: a 30-segment multibody tether
    (RK4, 0.01 s), the ACCD as a 6-DoF body, mean wake and frozen turbulence, ISA atmosphere.
    Frames: TA frame, origin at the tether attachment, x forward, y starboard, z down; SI units.

    ## Action Space

    ``Box(-1, 1, (4,), float32)``: flap commands, scaled by ``accd.flap_limit_deg`` (15 deg),
    held for one agent step (``agent_step``, 0.1 s). Values outside [-1, 1] are clipped;
    non-finite values, values beyond float32's range, non-real values (bool, complex, str) and
    any other shape than (4,) raise ``StateError`` (a ``ValueError``). Pitch moves both horizontal flaps together, yaw both
    vertical flaps, roll all four differentially (``accd_gym.mix_flaps`` does the mixing).

    {ACTION_TABLE}

    ## Observation Space

    ``Box(-10, 10, (25,), float32)``. Each value is a physical quantity times the scale below,
    clipped to [-10, 10]; vectors in the TA frame. ``accd_gym.envs.task.OBSERVATION_TABLE`` holds this
    table in code.

    {OBSERVATION_TABLE}

    **Sensors** (``sensors={"enabled": True, ...}``; off by default, and then the observation is
    the true state). The same layout then holds what an onboard sensor suite measures: the boom
    position from a vision sensor (noise growing with range, ``sensors.vision.update_rate`` with
    the last value held between updates, ``latency``, Markov dropouts that hold the last received
    value), its rate as the finite difference of the last two received measurements, attitude and
    body rates with per-episode biases and white noise, position/velocity and tension with white
    noise, and the whole vector ``sensors.delay_steps`` agent steps old. The reward, the episode
    end and ``info`` use the true state; the physics is bitwise that of the same seeds without
    sensors (the sensors draw from their own stream). ``accd_gym.envs.config.SENSORS_TIER`` is the
    recommended benchmark setting. Models, assumptions and sources: ``docs/environment.md``,
    "Sensors", and the keys ``sensors.*`` below.

    ## Rewards

    Summed per agent step; ``steps_left`` counts the agent steps left in the window, so capturing
    always beats hovering next to the boom. Bounds per step: ``accd_gym.reward_bounds()``.

    {REWARD_TABLE}

    ## Starting State

    The open-loop equilibrium (neutral flaps, mean wake, no turbulence, settled for
    ``initial.settle_time`` = 40 s from the straight trailing tether), with the whole tether
    rotated about the attachment to move the ACCD by up to +-5 m laterally and vertically
    (``initial.offset``) and the ACCD tilted by up to +-3 deg about each axis
    (``initial.attitude_deg``), drawn from the episode's *initial* seed. The boom tip starts
    laterally and vertically at its formation offset (y, z) = (3, 62) m plus up to +-(3, 3) m and
    10 m behind the capture point; the RLV then closes along track at up to 0.5 m/s and keeps
    station with the capture point (``boom.approach_distance``, ``boom.approach_speed``); the ACCD
    must meet it laterally and vertically. Wake turbulence starts from its stationary
    distribution, drawn from the episode's *wake seed*.

    ## Episode End

    {EPISODE_END_TABLE}

    The registered spec has ``max_episode_steps`` = 700 (the default window), so
    ``gymnasium.make`` adds a ``TimeLimit`` of 700 steps; with another ``capture_window`` pass
    ``max_episode_steps=capture_window / agent_step`` to ``gymnasium.make`` as well.

    ## Info

    ``time`` (s), ``distance`` (m), ``relative_speed`` (m/s), ``peak_tension`` (N, highest
    attachment tension during the step), ``captured``, ``overload``, ``envelope_exit``,
    ``diverged`` (bool), ``episode_steps``, ``wake_seed``.

    ## Seeds

    ``reset(seed=s)`` seeds the env: episode ``e`` after it draws its initial-condition, wake and
    RLV seeds from ``(s, env index 0, e)`` (see ``accd_gym.envs.task``). Training wake seeds come from
    ``TRAINING_WAKE_SEEDS`` = [0, 10^9); ``HELD_OUT_WAKE_SEEDS`` = [10^9, 10^9 + 1000) are never
    drawn. ``reset(options={"wake_seed": w})`` fixes the wake seed, ``{"wake_seeds": [...]}``
    cycles through a list, ``{"wake_seed": None}`` returns to training draws; options persist over
    later resets. The config keys ``wake_seed``/``wake_seeds`` do the same from the start.

    ## Arguments

    ``render_mode``: ``"rgb_array"`` (side and top views, off-screen) or ``"human"`` (a window);
    ``residual``, ``history``: residual control on a base controller and observation history
    (:mod:`accd_gym.envs.agent_io`; off by default; they change the observation's layout);
    ``true_observation=True``: ``info["true_obs"]`` in ``reset`` and ``step``, the noise-free,
    delay-free observation (:mod:`accd_gym.envs.agent_io`; off by default);
    ``**config``: the configuration keys below (e.g. ``capture_window=60.0``,
    ``tether="uhmwpe-300m-24mm"``, ``wake={"enabled": False}``): a section takes a dict of its
    keys (merged with the defaults), ``tether`` also a preset name. Unknown keys and values
    outside the range raise ``ConfigError`` naming the dotted key, the value and the range.

    {CONFIG_ARGUMENTS}

    ## State

    ``get_state()``/``set_state()`` snapshot and restore the env exactly (random streams
    included); the env pickles. A state is bytes: a header (magic, format version, the kind of
    env, the number of envs, the configuration's SHA-256, a CRC-32) and the encoded state.
    ``set_state`` raises ``StateError`` naming what is wrong for anything but a state of this
    class, configuration and size (a corrupted or truncated state, random bytes, a state of a
    format version other than this build's, 5), and then changes nothing.

    ## Version History

    * v0: first release. Later, same id and the same episodes for every existing configuration:
      the opt-in ``sensors`` section (state format 4). Then each sensor its own random stream:
      with ``sensors.enabled`` (the sensors and hard tiers) the observations' noise changed once,
      the physics did not (state format 5).
    """

    _state_kind = "single"

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 10}

    def __init__(self, render_mode: Optional[str] = None, **config: Any) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(
                f"invalid config: `render_mode` = {render_mode!r} is outside the allowed range {self.metadata['render_modes']} or None"
            )
        self.render_mode = render_mode
        # Validated once; a user aerodynamic table is kept as its contents: pickles and saved
        # states need no file.

        self.agent_options, config = split_agent_options(config)
        valid = valid_config(config)
        self._config = json.loads(valid.to_json())
        self.metadata = dict(self.metadata, render_fps=1.0 / self._config["agent_step"])
        self._core = _core.BatchEnv(valid, 1, random_seed(), "next_step", 1)
        if self.agent_options.true_observation:
            self._core.set_true_observation(True)
        self._agent_io = AgentIO.create(self.agent_options, self._config, 1, self._core)
        self.observation_space = observation_space() if self._agent_io is None else self._agent_io.observation_space
        self.action_space = action_space()
        self._viewer = None

    def reset(
        self, *, seed: Optional[int] = None, options: Optional[dict[str, Any]] = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Starts a new episode; returns ``(observation, info)`` (info: ``wake_seed``, and with
        randomized physics ``parameters``, the episode's drawn parameters).

        ``seed``: a Python or numpy integer in the seed range [0, 2^63), or None (the next episode of the seeded
        sequence); bools, floats and strings raise ConfigError.
        """
        if seed is not None:
            seed = check_seed(seed)
        super().reset(seed=seed)
        obs, wake = self._reset_core(seed, options)
        if self._agent_io is not None:
            obs = self._agent_io.begin(obs)
        info = self._reset_info(0, wake[0], self._true_observations())
        if self.render_mode == "human":
            self.render()
        return obs[0].copy(), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One agent step; returns ``(observation, reward, terminated, truncated, info)``."""
        if self._needs_reset:
            raise gym.error.ResetNeeded("call reset() before step() (at the start and after an episode ends)")
        a = check_actions(action, 1, single=True)
        if self._agent_io is not None:
            a = self._agent_io.command(a)
        obs, reward, terminated, truncated, _final, info, wake, _reset = self._core.step(a)
        if self._agent_io is not None:
            obs, _ = self._agent_io.advance(obs)
        term, trunc = bool(terminated[0]), bool(truncated[0])
        self._needs_reset = term or trunc
        out_info = info_dicts(info, wake)[0]
        if out_info["diverged"]:
            out_info["divergence"] = self._core.divergence(0)
        if self.agent_options.true_observation:
            out_info["true_obs"] = self._core.true_observations()[0]
        if self.render_mode == "human":
            self.render()
        return obs[0].copy(), float(reward[0]), term, trunc, out_info

    def episode_seeds(self) -> dict[str, int]:
        """The current episode's seeds: ``{"initial", "wake", "rlv"}`` (64-bit)."""
        return self._core.episode_seeds(0)

    def render(self) -> Optional[np.ndarray]:
        """The current state as an RGB array (``rgb_array``) or in a window (``human``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None

        frame = render_frame(self._core.render_data(0))
        if self.render_mode == "rgb_array":
            return frame
        if self._viewer is None:
            self._viewer = HumanViewer()
        self._viewer.show(frame, self.metadata["render_fps"])
        return None

    def close(self) -> None:
        """Closes the window of ``human`` rendering, if any."""
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

    def __getstate__(self) -> dict[str, Any]:
        return {
            "render_mode": self.render_mode,
            "config": self._config,
            "agent": self.agent_options.to_dict(),
            "state": self.get_state(),
            "np_random": self._np_random,
        }

    def __setstate__(self, d: dict[str, Any]) -> None:
        self.__init__(render_mode=d["render_mode"], **d["config"], **d.get("agent", {}))
        self.set_state(d["state"])
        self._np_random = d["np_random"]


InAirCaptureEnv.__doc__ = with_task_tables(with_arguments(InAirCaptureEnv.__doc__))
