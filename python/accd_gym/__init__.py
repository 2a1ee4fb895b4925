"""accd-gym: a fast, physically honest simulation of DLR's In-Air Capturing capture system.

The physics (Rust) follows Singh et al., "Multibody modelling of tether and capture system for
dynamic simulations of In-Air Capturing": a 3D chain of rigid tether segments with nonlinear bending
springs, joint damping, per-segment aerodynamics and one axial visco-elastic element, hung from the
towing aircraft, with the capturing device at its tip.

Frames and units: SI; the towing-aircraft (TA) frame has its origin at the tether attachment,
x forward, y to starboard, z down.

Public API:

* ``gymnasium.make("accd_gym/InAirCapture-v0", **config)`` -- the single env
  (:class:`InAirCaptureEnv`); ``gymnasium.make_vec("accd_gym/InAirCapture-v0", num_envs=N)`` --
  the native vector env (:class:`InAirCaptureVectorEnv`); :class:`AccdVecEnv` -- the native
  stable-baselines3 VecEnv (imports stable-baselines3 on first use).
* :func:`env_config`, :func:`default_config` -- validated environment configurations;
  :data:`TRAINING_WAKE_SEEDS`, :data:`HELD_OUT_WAKE_SEEDS`, :data:`VALIDATION_WAKE_SEEDS` -- the
  wake-seed sets (validation: training wake seeds that tuning evaluates on);
  :func:`reward_bounds`.
* :class:`CaptureSim` -- one capture episode's physics (tether, 6-DoF capturing device, towing
  aircraft, RLV boom) for scripted runs; :func:`mix_flaps` turns pitch/yaw/roll into flaps.
* :func:`record_episodes`, :class:`RecordEpisode`, :class:`Recording` -- recorded episodes
  (``.npz``, :mod:`accd_gym.replays.recording`); :mod:`accd_gym.replays.replay` -- their self-contained 3D replay
  pages and MP4 videos (``accd-gym replay``).
* :class:`Tether` -- the tether model alone, for design studies and validation.
* :func:`tether_config` -- validated tether configurations from the paper's presets.
* :func:`towed_tether`, :func:`stand_in_body` -- the towed reference case (a stand-in capturing
  device at the tip, 185 m/s, 6000 m).
* :func:`isa` -- the International Standard Atmosphere.
* :mod:`accd_gym.zoo` -- rl-zoo3 hyperparameters (``--conf-file accd_gym.zoo.ppo``).
* :class:`AccdError` and its subclasses :class:`ConfigError`, :class:`StateError`,
  :class:`SimulationError`, :class:`OutputError`.
"""

from typing import TYPE_CHECKING, Any, Optional

from accd_gym._core import (
    CaptureSim,
    Tether,
    __version__,
    arithmetic,
    default_aero_table_json,
    isa,
    mix_flaps,
    stand_in_body,
    tether_config,
    towed_tether,
)
from accd_gym._core import reward_bounds as _core_reward_bounds
from accd_gym.errors import AccdError, ConfigError, OutputError, SimulationError, StateError
from accd_gym.envs.config import EXACT_AIR_SCHEME, default_config, env_config, config_json
from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS, PARAMETER_NAMES, TRAINING_WAKE_SEEDS, VALIDATION_WAKE_SEEDS
from accd_gym.envs.env import InAirCaptureEnv
from accd_gym.envs.vector import InAirCaptureVectorEnv
from accd_gym.replays.recording import Recording, RecordEpisode, record_episodes
from accd_gym.envs.tiers import TIERS
from accd_gym.envs.tiers import register_tiers as _register_tiers
from accd_gym.control.lqr import LqrPolicy, linearize

#: The registered id of the nominal env (``gymnasium.make(ENV_ID)``, ``gymnasium.make_vec(ENV_ID, n)``);
#: the benchmark tiers' ids are in :data:`accd_gym.envs.tiers.TIERS`. A ``str`` whose pickle imports
#: ``accd_gym`` (:class:`accd_gym.envs.tiers.EnvId`), so that it also works in subprocess vector envs
#: started with ``spawn`` or ``forkserver``, which a plain string id does not (use
#: ``"accd_gym:accd_gym/InAirCapture-v0"`` there).
ENV_ID: str = TIERS["nominal"].id
_register_tiers()


def reward_bounds(config: Optional[dict[str, Any]] = None, **overrides: Any) -> tuple[float, float]:
    """Lowest and highest reward of one agent step under a configuration (keyword overrides)."""
    return _core_reward_bounds(config_json(env_config(config, **overrides)))


if TYPE_CHECKING:
    from accd_gym.envs.sb3 import AccdVecEnv
else:

    def __getattr__(name: str) -> Any:
        """Imports :class:`AccdVecEnv` (and with it stable-baselines3) on first use; hidden from
        type checkers, which see the import above and nothing else."""
        if name == "AccdVecEnv":
            try:
                # deferred: stable-baselines3, an optional dependency (accd_gym.envs.sb3 imports it)
                from accd_gym.envs.sb3 import AccdVecEnv
            except ModuleNotFoundError as e:
                raise ModuleNotFoundError(
                    f"accd_gym.AccdVecEnv needs stable-baselines3 ({e}): pip install 'accd-gym[sb3]'", name=e.name
                ) from e
            return AccdVecEnv
        raise AttributeError(f"module 'accd_gym' has no attribute {name!r}")


# A misspelt ACCD_GYM_ARITHMETIC fails here, naming its value, rather than being ignored.
arithmetic()

__all__ = [
    "AccdError",
    "AccdVecEnv",
    "ENV_ID",
    "EXACT_AIR_SCHEME",
    "HELD_OUT_WAKE_SEEDS",
    "PARAMETER_NAMES",
    "InAirCaptureEnv",
    "InAirCaptureVectorEnv",
    "TIERS",
    "LqrPolicy",
    "TRAINING_WAKE_SEEDS",
    "VALIDATION_WAKE_SEEDS",
    "default_config",
    "env_config",
    "reward_bounds",
    "CaptureSim",
    "ConfigError",
    "OutputError",
    "SimulationError",
    "StateError",
    "Tether",
    "__version__",
    "default_aero_table_json",
    "arithmetic",
    "isa",
    "linearize",
    "mix_flaps",
    "record_episodes",
    "Recording",
    "RecordEpisode",
    "stand_in_body",
    "tether_config",
    "towed_tether",
]
