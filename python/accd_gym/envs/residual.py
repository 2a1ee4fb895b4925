"""Residual control: the flap command sent is a base controller's plus the agent's bounded correction.

An env option of every env class (``residual={"base": "lqr", "scale": 0.3}``; see
:mod:`accd_gym.envs.agent_io`, which applies it together with the observation history)::

    u_sent = clip(u_base(obs history) + scale * clip(a, -1, 1), -1, 1)

``a`` is the agent's action (the env's action space is unchanged, [-1, 1]^4), ``u_base`` the
command of the base controller (a registered controller that may serve as a base,
:func:`accd_gym.control.registry.residual_bases`: ``"lqr"``, :class:`accd_gym.control.lqr.LqrPolicy`
designed for the env's configuration, or ``"guidance"``, :class:`accd_gym.control.baselines.GuidancePolicy`
with its tuned gains) computed from the observations the agent gets (with sensors, the sensed
ones: the base controllers read nothing else). The base controller's state (the LQR's Kalman
filter, the guidance's integrators) starts afresh with every episode of its env, automatic
resets included, is told the command actually sent (the LQR's filter predicts with it), and is
part of the env's pickles and ``get_state()``. A zero action reproduces the base controller's
episodes bit for bit. The env's Rust batch steps an ``"lqr"`` or ``"mpc"`` base per env in its
own threads, right after each env's step (:class:`BatchBaseController`), with the bits of the
controller's own ``predict``. With ``observe_base`` (default) the base command is appended to the
observation (the agent sees what it corrects; the LQR's command carries its filter's estimate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional

import numpy as np

from accd_gym.control.registry import make_controller, residual_bases
from accd_gym.envs.task import ACT_DIM
from accd_gym.errors import ConfigError

#: The allowed range of ``residual.scale`` (flap-limit units): (0, SCALE_MAX]; 2 lets a
#: correction reach any command from any base command.
SCALE_MAX = 2.0


@dataclass(frozen=True)
class ResidualOptions:
    """The ``residual`` env option, validated: ``base`` (a name of :func:`accd_gym.control.registry.residual_bases`), ``scale``
    (the bound of the correction, flap-limit units, in (0, 2]) and ``observe_base`` (whether the
    base command is appended to the observation)."""

    base: str = "lqr"
    scale: float = 0.3
    observe_base: bool = True

    @classmethod
    def parse(cls, value: Any) -> "ResidualOptions | None":
        """The options from the env argument ``residual``: None or False (off), True (the
        defaults), a base name, or a dict of the fields; ConfigError naming the field, the value
        and the allowed range otherwise."""
        if value is None or value is False:
            return None
        if value is True:
            return cls()
        if isinstance(value, str):
            value = {"base": value}
        if not isinstance(value, Mapping):
            raise ConfigError(f"invalid config: `residual` = {value!r} is outside the allowed range: None, a base name "
                              f"({', '.join(map(repr, residual_bases()))}) or a dict with keys 'base', 'scale', 'observe_base'")
        unknown = set(value) - {"base", "scale", "observe_base"}
        if unknown:
            raise ConfigError(f"invalid config: `residual` key(s) {sorted(unknown)} outside the allowed set "
                              "['base', 'observe_base', 'scale']")
        base = value.get("base", cls.base)
        if base not in residual_bases():
            raise ConfigError(f"invalid config: `residual.base` = {base!r} is outside the allowed range: one of "
                              f"{', '.join(map(repr, residual_bases()))}")
        scale = value.get("scale", cls.scale)
        if (isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating))
                or not math.isfinite(float(scale)) or not 0.0 < float(scale) <= SCALE_MAX):
            raise ConfigError(f"invalid config: `residual.scale` = {scale!r} is outside the allowed range (0, {SCALE_MAX:g}] "
                              "(flap-limit units)")
        observe = value.get("observe_base", cls.observe_base)
        if not isinstance(observe, (bool, np.bool_)):
            raise ConfigError(f"invalid config: `residual.observe_base` = {observe!r} is outside the allowed range: "
                              "true or false")
        return cls(base=str(base), scale=float(scale), observe_base=bool(observe))

    def to_dict(self) -> dict[str, Any]:
        """The options as the env argument (JSON values)."""
        return {"base": self.base, "scale": self.scale, "observe_base": self.observe_base}


class BaseController:
    """A base controller of a batch of ``num_envs`` envs: a registered controller
    (:data:`accd_gym.control.registry.CONTROLLERS`, one with ``residual_base``) with the
    row bookkeeping residual control needs (restart rows, partial starts, state snapshots)."""

    #: Whether :meth:`sent` must be told the corrections (a batch-run base learns them itself).
    needs_sent = True

    def __init__(self, options: ResidualOptions, config: Mapping[str, Any]) -> None:
        self.options = options
        self.policy = make_controller(options.base, 0, dict(config))

    def restart(self, rows: "np.ndarray | None") -> None:
        """Rows (a bool mask; None: all) whose next observation starts an episode."""
        self.policy.reset(rows)

    def command(self, obs: np.ndarray) -> np.ndarray:
        """The base commands (N, 4) float32 for the batch's observations; advances every row
        (the LQR's filter steps in Rust with the GIL released; the guidance is element-wise
        numpy: neither calls BLAS)."""
        return self.policy.predict(obs)

    def command_rows(self, obs: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The base commands of the batch with only the rows ``rows`` selects advanced (the
        others keep their state; their commands in the result are meaningless). Computed on the
        whole batch, as :meth:`command` does, so that a row's command has the bits it would have
        there."""
        if hasattr(self.policy, "predict_rows"):  # the LQR: rows are independent in its Rust filter
            return self.policy.predict_rows(obs, rows)
        before = self.policy.get_state()
        u = self.command(obs)
        if before and not rows.all():
            after = self.policy.get_state()
            merged = {}
            for k, new in after.items():
                old = before[k]
                sel = rows.reshape((-1,) + (1,) * (new.ndim - 1))
                merged[k] = np.where(sel, new, old) if old.shape == new.shape else new
            self.policy.set_state(merged)
        return u

    def peek(self, obs: np.ndarray) -> np.ndarray:
        """The base commands for ``obs`` without advancing any row (e.g. for an ended episode's
        last observation)."""
        if hasattr(self.policy, "peek"):
            return self.policy.peek(obs)
        before = self.policy.get_state()
        u = self.command(obs)
        self.policy.set_state(before)
        return u

    def sent(self, offset: np.ndarray) -> None:
        """The commands sent differ from the last ones by ``offset`` (N, 4); nothing when zero."""
        if hasattr(self.policy, "sent") and np.count_nonzero(offset):
            self.policy.sent(offset)

    def get_state(self) -> dict[str, np.ndarray]:
        """The controller's per-row state arrays (copies)."""
        return self.policy.get_state()

    def set_state(self, state: Mapping[str, np.ndarray], commands: Optional[np.ndarray] = None) -> None:
        """Restores :meth:`get_state`'s arrays (``commands``, the last base commands, are the
        env's to keep here)."""
        self.policy.set_state(dict(state))


class BatchBaseController(BaseController):
    """A base controller that the env's Rust batch steps (``_core.BatchEnv.set_controller``):
    each env's filter step (and MPC solve) runs in the thread that steps the env, right after
    its step or reset, with the GIL released, in parallel across envs; the batch restarts it
    with each new episode (automatic resets included) and tells it the action sent. The same
    bits as :class:`BaseController` on the same policy: the per-row arithmetic is the same
    Rust step. Here the methods read the batch's results."""

    needs_sent = False

    def __init__(self, base: BaseController, core: Any) -> None:
        self.options = base.options
        self.policy = base.policy
        self._core = core
        core.set_controller(self.policy.batch_stepper())

    def restart(self, rows: "np.ndarray | None") -> None:
        """Nothing: the batch restarts an env's controller with its episode."""

    def command(self, obs: np.ndarray) -> np.ndarray:
        """The commands the batch computed for its latest observations (``obs``)."""
        return self._core.controller_commands()

    def command_rows(self, obs: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """As :meth:`command`: the batch advanced exactly the rows it reset."""
        return self._core.controller_commands()

    def peek(self, obs: np.ndarray) -> np.ndarray:
        """The commands for the last observations of the episodes that ended in the last step
        (same-step autoreset; computed by the batch without advancing anything)."""
        return self._core.final_controller_commands()

    def sent(self, offset: np.ndarray) -> None:
        """Nothing: the batch tells each env's controller the action it steps with."""

    def get_state(self) -> dict[str, np.ndarray]:
        """The batch's controller state per env: ``z``, ``u``, ``fresh`` (as the policy's)."""
        z, u, fresh, _ = self._core.controller_state()
        return {"z": z, "u": u, "fresh": fresh}

    def set_state(self, state: Mapping[str, np.ndarray], commands: Optional[np.ndarray] = None) -> None:
        """Restores :meth:`get_state`'s arrays and the last base commands ``commands`` (N, 4)
        into the batch (an empty state: every env starts afresh at its next reset)."""
        n = self._core.num_envs
        cmd = np.zeros((n, ACT_DIM), dtype=np.float32) if commands is None else commands
        if state:
            z, u, fresh = (np.asarray(state[k]) for k in ("z", "u", "fresh"))
        else:
            nz = self.policy.design.f.shape[0]
            z, u, fresh = np.zeros((n, nz)), np.zeros((n, ACT_DIM)), np.ones(n, dtype=bool)
        self._core.set_controller_state(np.ascontiguousarray(z, dtype=np.float64),
                                        np.ascontiguousarray(u, dtype=np.float64),
                                        np.ascontiguousarray(fresh, dtype=bool),
                                        np.ascontiguousarray(cmd, dtype=np.float32))


def base_controller(options: ResidualOptions, config: Mapping[str, Any], core: Any = None) -> BaseController:
    """The base controller of ``options`` for a batch: run by the Rust batch ``core`` in its
    threads where the controller has a Rust stepper (its policy's ``batch_stepper``: the LQR,
    the MPC) and a core is given, else stepped from Python on the calling thread."""
    controller = BaseController(options, config)
    if (core is not None and hasattr(controller.policy, "batch_stepper")
            and (BATCH_BASES is None or options.base in BATCH_BASES)):
        return BatchBaseController(controller, core)
    return controller


#: The residual bases a Rust batch may run: None (the default) for every base whose policy has a
#: Rust stepper (``batch_stepper``); a tuple of names limits it (``()``: the calling-thread path
#: for every base, which benchmarks and tests compare the batch against).
BATCH_BASES: Optional[tuple[str, ...]] = None


__all__ = ["BATCH_BASES", "SCALE_MAX", "BaseController", "BatchBaseController", "ResidualOptions", "base_controller"]
