"""What every env class shares: the Rust batch core, its configuration, seeding on reset and
exact state snapshots."""

from __future__ import annotations

import copy
from typing import Any, Optional, Sequence, Union

import numpy as np

from accd_gym.errors import StateError
from accd_gym.envs.task import check_count, random_seed, wake_options


class CoreEnvMixin:
    """Methods of an env backed by ``self._core`` (an ``accd_gym._core.BatchEnv``) built from
    ``self._config``. Tracks whether the env was ever seeded and whether it must be reset."""

    _core: Any
    _config: dict[str, Any]
    _seeded: bool = False
    _needs_reset: bool = True
    #: The kind written into and required of a state: ``"single"``, ``"vector"`` or ``"sb3"``.
    _state_kind: str

    @property
    def config(self) -> dict[str, Any]:
        """The full configuration (defaults filled in; a copy)."""
        return copy.deepcopy(self._config)

    @property
    def num_threads(self) -> int:
        """Threads stepping the envs."""
        return self._core.num_threads

    def episode_parameters(self, i: int = 0) -> Optional[dict[str, float]]:
        """The physical parameters env ``i``'s current episode drew (randomized physics,
        ``randomization={"enabled": True}``), keyed by :data:`accd_gym.PARAMETER_NAMES`
        (``tether_length`` m, ``tether_diameter`` m, ``accd_mass`` kg,
        ``force_coefficient_scale``, ``moment_coefficient_scale``, ``wake_alpha_deg``,
        ``wake_strength``, ``airspeed`` m/s, ``ambient_sigma_mps``); None without randomization.
        They are a function of the episode's wake seed alone."""
        return self._core.episode_parameters(self._env_index(i))

    def _reset_info(self, i: int, wake_seed: int, true_obs: Optional[np.ndarray] = None) -> dict[str, Any]:
        """The info of env ``i``'s episode as the single env's ``reset`` reports it, for the
        episode's ``wake_seed``: ``wake_seed``, with randomized physics ``parameters`` (the
        drawn parameters, :meth:`episode_parameters`), and with ``true_observation`` the row
        ``i`` of ``true_obs`` (:meth:`_true_observations`) as ``true_obs``. The one place the
        reset info is built: every env class reports these keys."""
        info: dict[str, Any] = {"wake_seed": int(wake_seed)}
        parameters = self._core.episode_parameters(int(i))
        if parameters is not None:
            info["parameters"] = parameters
        if true_obs is not None:
            info["true_obs"] = true_obs[int(i)].copy()
        return info

    def true_observations(self) -> np.ndarray:
        """Every env's true observation of its current state ((num_envs, 25) float32): what
        perfect sensors would observe, noise-free and delay-free, scaled like the observation.
        Needs the ``true_observation=True`` env option (StateError otherwise)."""
        return self._core.true_observations()

    def _true_observations(self) -> Optional[np.ndarray]:
        """Every env's true observation ((num_envs, 25) float32) with the ``true_observation``
        env option, else None (and nothing is computed)."""
        return self._core.true_observations() if self.agent_options.true_observation else None

    def true_boom_relative(self) -> np.ndarray:
        """The boom tip minus the capture point of every env at its current state, (num_envs, 3) m,
        TA frame, from the physics: what ``boom_rel_x/y/z`` of the observation shows without
        sensors (with sensors the observation is the sensed value; evaluation metrics use this)."""
        return self._core.boom_relative()

    def episode_setup(self, i: int = 0) -> dict[str, np.ndarray]:
        """Where env ``i``'s current episode starts from (TA frame, m): ``equilibrium`` (the
        ACCD's open-loop equilibrium), ``capture_point`` (the capture point's) and
        ``boom_nominal`` (the boom tip's nominal formation position: ``boom.placement``)."""
        return self._core.episode_setup(self._env_index(i))

    def record_data(self, i: int = 0) -> dict[str, Any]:
        """Everything a recording keeps of env ``i``'s current state (TA frame, SI units; the
        sample fields of :data:`accd_gym.replays.recording.SAMPLE_FIELDS` and the ACCD's
        ``equilibrium``); reading it leaves the episode unchanged."""
        return self._core.record_data(self._env_index(i))

    def episode_seeds(self, i: int = 0) -> dict[str, int]:
        """The seeds of env ``i``'s current episode by stream (initial conditions, RLV motion, wake)."""
        return {name: int(v) for name, v in self._core.episode_seeds(self._env_index(i)).items()}

    def divergence(self, i: int = 0) -> Optional[str]:
        """Why env ``i``'s episode diverged (None when it did not)."""
        return self._core.divergence(self._env_index(i))

    def _env_index(self, i: Any) -> int:
        """``i`` checked as an env index: an integer in [0, num_envs - 1] (ConfigError naming it)."""
        return check_count(i, "i", 0, self._core.num_envs - 1, noun="env index")

    def _reset_core(
        self,
        seed: Optional[Union[int, Sequence[int]]],
        options: Optional[dict[str, Any]],
        mask: Optional[np.ndarray] = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Applies the wake options, seeds the core (from the operating system's entropy on a
        first reset without a seed) and starts new episodes (in the envs ``mask`` selects, or
        all); returns ``(obs, wake_seeds)`` of every env."""
        wake_options(self._core, options)
        if seed is None and not self._seeded:
            seed = random_seed(self._core.num_envs)
        obs, wake = self._core.reset(seed, None if mask is None else mask.tolist())
        self._seeded = True
        self._needs_reset = False
        return obs, wake

    def get_state(self) -> bytes:
        """The env's exact state (physics, random streams, seeds, counters) as bytes.

        The bytes are a header (magic ``ACCDSNAP``, format version, the kind of env, the number
        of envs, the SHA-256 of the configuration, a CRC-32 of everything) followed by the
        postcard-encoded state; the configuration itself is not included (pickles carry it)."""
        state = self._core.get_state(self._state_kind, self._needs_reset, self._seeded)
        agent = getattr(self, "_agent_io", None)  # residual control / history (accd_gym.envs.agent_io)
        return state if agent is None else agent.pack_state(state)

    def set_state(self, state: bytes) -> None:
        """Restores a state from :meth:`get_state` of an env of the same class, configuration and
        number of envs; it then continues bit for bit as the saved one would.

        Raises :class:`~accd_gym.StateError` (a ``ValueError``) naming what is wrong for anything
        else (a corrupted or truncated state, another env class, configuration or number of
        envs, random bytes, a state of another format version, e.g. one written before version 5),
        and then changes nothing."""
        if not isinstance(state, (bytes, bytearray, memoryview)):
            raise StateError(f"a state is bytes from {type(self).__name__}.get_state(), got {type(state).__name__}")
        state = bytes(state)
        agent = getattr(self, "_agent_io", None)  # residual control / history (accd_gym.envs.agent_io)
        arrays = None
        if agent is not None:
            state, arrays = agent.unpack_state(state)
        self._needs_reset, self._seeded = self._core.set_state(state, self._state_kind)
        if agent is not None:
            agent.set_state(arrays)
