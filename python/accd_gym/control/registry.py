"""The :class:`Policy` interface and the registry of controllers by name.

Every policy the package runs (a controller of this subpackage, a shipped or trained model, an
RLlib run) has one interface, :class:`Policy`: it acts on a batch of observations, restarts the
envs whose episode ended, and hands out its per-env state. A *controller* is a policy built from
code alone (no model file); :data:`CONTROLLERS` holds each under its name, and
:func:`accd_gym.evals.policies.load_policy` (which also resolves shipped policies, tuning files
and model paths) builds them from there. The residual env option takes its base controller from
here too (the entries with ``residual_base``).

Adding a controller is one file and one registration: the policy class in its own module of
``accd_gym/control/`` and one :class:`Controller` entry below.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping, Optional, Protocol, runtime_checkable

import numpy as np

from accd_gym.control.baselines import GuidancePolicy, RandomPolicy, ZeroPolicy
from accd_gym.control.lqr import LqrPolicy
from accd_gym.control.mpc import MpcPolicy
from accd_gym.errors import ConfigError


@runtime_checkable
class Policy(Protocol):
    """What evaluation, benchmark, rollouts, recordings, replays and the residual env option run.

    * ``name``: a label for reports.
    * ``predict(obs)``: flap commands (N, 4) float32 in [-1, 1] for observations (N, 25) of a
      batch of N envs; advances the per-env state (row i belongs to env i; a new batch size
      starts every env afresh).
    * ``reset(mask=None)``: the envs ``mask`` selects (a bool array of N; all when None) start
      new episodes.
    * ``get_state()`` / ``set_state(state)``: the per-env state as arrays whose first axis is the
      env (empty for a stateless policy); the residual option snapshots and merges it row by
      row. A policy pickles whole (``pickle.dumps``), and a copy acts bit for bit alike.

    Optionally ``start_episodes(mask, episodes)`` instead of ``reset``: told the evaluation's
    episode index of each restarted env (a policy with random streams per episode).
    """

    name: str

    def predict(self, obs: Any) -> np.ndarray:
        """Flap commands (N, 4) for observations (N, 25)."""

    def reset(self, mask: Optional[np.ndarray] = None) -> None:
        """Restarts the envs ``mask`` selects (all when None)."""

    def get_state(self) -> dict[str, np.ndarray]:
        """The per-env state arrays (copies)."""

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restores a state of :meth:`get_state`."""


@dataclass(frozen=True)
class Controller:
    """One registered controller.

    ``make(seed, config)`` builds it for the env configuration ``config`` it will run on
    (overrides, a validated ``accd_gym._core.EnvConfig`` or None for the defaults; a model-based
    controller is designed for its physics) with ``seed`` for any random draws. ``residual_base``:
    whether it may serve as the residual env option's base controller (deterministic, with its
    state in :meth:`Policy.get_state`). ``classical``: a control design that the benchmark sets
    learned policies against (its best classical controller per tier is chosen among these), as
    opposed to a trivial reference such as neutral or random flaps. ``summary``: one line for
    listings and errors.
    """

    name: str
    make: Callable[[int, Any], Policy]
    summary: str
    residual_base: bool = False
    classical: bool = False


#: Registered controllers by name, in registration order.
CONTROLLERS: dict[str, Controller] = {}


def register_controller(controller: Controller) -> Controller:
    """Adds ``controller`` under its name; ConfigError when the name is taken or would be read as
    a path (contains a slash or ends in ``.json``/``.zip``)."""
    name = controller.name
    if not isinstance(name, str) or not name or "/" in name or "\\" in name or name.endswith((".json", ".zip")):
        raise ConfigError(f"invalid config: controller name {name!r} is outside the allowed range: a non-empty name "
                          "without slashes that is not a file name")
    if name in CONTROLLERS:
        raise ConfigError(f"invalid config: controller name {name!r} is already registered")
    CONTROLLERS[name] = controller
    return controller


def make_controller(name: str, seed: int = 0, config: Any = None) -> Policy:
    """The registered controller ``name`` built for ``config`` (see :class:`Controller`);
    ConfigError naming the registered names otherwise."""
    if name not in CONTROLLERS:
        raise ConfigError(f"invalid config: controller {name!r} is outside the allowed range {list(CONTROLLERS)}")
    return CONTROLLERS[name].make(seed, config)


def residual_bases() -> list[str]:
    """The names of the controllers that may serve as a residual base, in registration order."""
    return [c.name for c in CONTROLLERS.values() if c.residual_base]


register_controller(Controller("zero", lambda seed, config: ZeroPolicy(), "neutral flaps throughout"))
register_controller(Controller("random", lambda seed, config: RandomPolicy(seed), "uniform random flaps"))
register_controller(Controller("guidance", lambda seed, config: GuidancePolicy(), "cascaded PID guidance",
                               residual_base=True, classical=True))
register_controller(Controller("lqr", lambda seed, config: LqrPolicy.for_config(config),
                               "LQR with a Kalman filter, designed for the env's configuration", residual_base=True,
                               classical=True))
register_controller(Controller("mpc", lambda seed, config: MpcPolicy.for_config(config),
                               "linear MPC on the LQR's Kalman filter, flap and closing-speed constraints",
                               residual_base=True, classical=True))

__all__ = ["CONTROLLERS", "Controller", "Policy", "make_controller", "register_controller", "residual_bases"]
