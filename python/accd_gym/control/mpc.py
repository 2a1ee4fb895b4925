"""A linear MPC baseline on the LQR's linearization and Kalman filter.

:class:`MpcPolicy` plans over ``horizon`` agent steps from the estimate of the LQR's steady-state
Kalman filter (:class:`accd_gym.control.lqr.LqrPolicy`; the same filter, stepped by the same
Rust code) with the LQR's cost as its stage cost and the LQR's Riccati solution as its terminal
cost, so that without active constraints its command is the LQR's. Constraints:

* **flap limits** (hard): every planned command in [-1, 1];
* **closing speed** (soft, a quadratic slack penalty ``slack_weight``): near the boom's predicted
  arrival (the predicted along-track distance under ``window`` m, or past it) the capture point's
  lateral velocity relative to the boom tip stays, per axis, within
  ``speed_margin * sqrt((max_closing_speed^2 - approach_speed^2) / 2)`` (the box inside the
  closing-speed sphere the boom's approach leaves), the limits read from the env's ``boom``
  configuration.

The condensed QP (``4 horizon`` variables) is solved in Rust (``accd_sim::control::mpc``): the
unconstrained optimum is one matrix product; where it breaks an active bound, a dense ADMM
iteration (OSQP's) with its matrix factored once per design, started from that optimum clipped
to the flap box. A solve that reaches ``iterations`` without converging, or meets a non-finite
estimate or iterate, falls back to the LQR's command for that step; :attr:`MpcPolicy.stats`
counts the constrained solves, the unconverged ones and the non-finite ones. Every row is stepped in fixed-order arithmetic with the GIL released:
the same bits whatever the batch size or CPU.

Defaults (:class:`MpcTuning`): set by hand, ADMM's ``rho`` from a comparison of unconverged
solves on four training-seed episodes; ``training/mpc_tuning.json`` (``scripts/tune_mpc.py``, on
validation wake seeds only) records the horizon of 20 against the LQR: 47 of 50 precision
episodes captured (the LQR 47), 44 of 50 hard (the LQR 47). No horizon sweep is recorded yet.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields
from typing import Any, Mapping, Optional

import numpy as np

from accd_gym import _core
from accd_gym.control.lqr import LqrDesign, LqrPolicy, LqrTuning, design_key, plant_key, default_tuning
from accd_gym.envs.config import valid_config
from accd_gym.errors import ConfigError


@dataclass(frozen=True)
class MpcTuning:
    """Settings of :class:`MpcPolicy` (see the module docstring).

    ``horizon`` (agent steps, >= 1), ``speed_margin`` (fraction of the lateral closing-speed
    bound, (0, 1]), ``window`` (m: the along-track distance to the boom under which the speed
    rows are active), ``slack_weight`` (per (m/s)^2 of speed-bound violation), ``rho`` (ADMM's
    penalty relative to the QP's mean Hessian diagonal), ``iterations`` (ADMM's limit).
    """

    horizon: int = 20
    speed_margin: float = 0.8
    window: float = 1.0
    slack_weight: float = 1000.0
    rho: float = 0.003
    iterations: int = 300

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> "MpcTuning":
        """A tuning from a mapping of its fields (ConfigError naming unknown fields; the Rust
        core checks the ranges)."""
        names = {f.name for f in fields(cls)}
        unknown = set(values) - names
        if unknown:
            raise ConfigError(f"invalid config: MPC tuning key(s) {sorted(unknown)} outside the allowed set {sorted(names)}")
        out: dict[str, Any] = {}
        for k, v in values.items():
            kind = int if k in ("horizon", "iterations") else float
            try:
                out[k] = kind(v)
            except (TypeError, ValueError):
                raise ConfigError(f"invalid config: `mpc.{k}` = {v!r} is not a number") from None
        return cls(**out)

    def settings(self) -> tuple[int, float, float, float, float, int]:
        """The values in the order the Rust core takes them."""
        return (int(self.horizon), float(self.speed_margin), float(self.window), float(self.slack_weight),
                float(self.rho), int(self.iterations))


@dataclass
class MpcParts:
    """What the MPC reads of an LQR design beyond :class:`~accd_gym.control.lqr.LqrDesign`: the
    LQR's state weight ``q`` and Riccati solution ``p`` (n x n), the reference ``x_ss`` (n x 4)
    and ``u_ss`` (4 x 4) per unit of ``w_y, w_z, r_y, r_z``, and the agent step ``dt`` (s)."""

    q: np.ndarray
    p: np.ndarray
    x_ss: np.ndarray
    u_ss: np.ndarray
    dt: float


#: Designs and parts by (plant digest, LQR tuning), as the LQR's.
_PLANTS: dict[tuple[str, LqrTuning], tuple[LqrDesign, MpcParts]] = {}
_CONFIGS: dict[tuple[str, LqrTuning], tuple[LqrDesign, MpcParts]] = {}


def _design(cfg: "_core.EnvConfig", tuning: LqrTuning) -> tuple[LqrDesign, MpcParts]:
    key = (design_key(cfg), tuning)
    if key not in _CONFIGS:
        lin = _core.linearize(cfg)
        plant = (plant_key(lin), tuning)
        if plant not in _PLANTS:
            d = _core.lqr_design(lin, [float(getattr(tuning, f.name)) for f in fields(LqrTuning)])
            design = LqrDesign(tuning=tuning, f=d.f, g=d.g, h=d.h, l=d.l, k=d.k, k_ff=d.k_ff, y_trim=d.y_trim,
                               n=d.n, closed_loop_radius=d.closed_loop_radius, observer_radius=d.observer_radius,
                               residuals=d.residuals, doublings=d.doublings)
            _PLANTS[plant] = (design, MpcParts(q=d.q, p=d.lqr_solution, x_ss=d.x_ss, u_ss=d.u_ss, dt=float(lin.dt)))
        _CONFIGS[key] = _PLANTS[plant]
    return _CONFIGS[key]


class MpcPolicy(LqrPolicy):
    """Linear MPC on the LQR's Kalman filter estimate (see the module docstring).

    Build it for the env configuration it runs on: ``MpcPolicy.for_config(config)``. The same
    interface as :class:`~accd_gym.control.lqr.LqrPolicy` (``predict``, ``predict_rows``,
    ``peek``, ``sent``, ``reset``, ``get_state``/``set_state``, pickling): the per-env state is
    the filter's, since each solve starts afresh from the unconstrained optimum.
    """

    name = "mpc"

    def __init__(self, design: LqrDesign, parts: MpcParts, tuning: MpcTuning, limits: tuple[float, float]) -> None:
        self.design = design
        self.parts = parts
        self.tuning = tuning
        self.limits = (float(limits[0]), float(limits[1]))
        d = design
        self._filter = _core.Mpc(d.n, d.f, d.g, d.h, d.l, d.k, d.k_ff, d.y_trim, parts.q, parts.p, parts.x_ss,
                                 parts.u_ss, float(d.tuning.r_flap), float(parts.dt), tuning.settings(), self.limits)

    def __getstate__(self) -> dict[str, Any]:
        return {"design": self.design, "parts": self.parts, "tuning": self.tuning, "limits": self.limits,
                "name": self.name, "state": self.get_state()}

    def __setstate__(self, state: Mapping[str, Any]) -> None:
        self.__init__(state["design"], state["parts"], state["tuning"], state["limits"])
        self.name = state.get("name", type(self).name)
        self.set_state(state["state"])

    @classmethod
    def for_config(cls, config: Any = None, tuning: Optional[MpcTuning | Mapping[str, Any]] = None,
                   lqr_tuning: Optional[LqrTuning | Mapping[str, Any]] = None, **overrides: Any) -> "MpcPolicy":
        """The MPC designed for an env configuration (as :meth:`LqrPolicy.for_config`) with
        ``tuning`` (default :class:`MpcTuning`'s defaults) on the LQR design of ``lqr_tuning``
        (default the LQR's). The capture limits come from the configuration's ``boom``. Raises
        ConfigError for a bad configuration or setting (a zero horizon among them)."""
        if isinstance(config, _core.EnvConfig):
            cfg = config if not overrides else valid_config(json.loads(config.to_json()), **overrides)
        else:
            cfg = valid_config(config, **overrides)
        t = tuning if isinstance(tuning, MpcTuning) else (MpcTuning.from_mapping(tuning) if tuning else MpcTuning())
        lt = (lqr_tuning if isinstance(lqr_tuning, LqrTuning)
              else (LqrTuning.from_mapping(lqr_tuning) if lqr_tuning else default_tuning()))
        boom = json.loads(cfg.to_json())["boom"]
        design, parts = _design(cfg, lt)
        return cls(design, parts, t, (boom["max_closing_speed"], boom["approach_speed"]))

    @property
    def stats(self) -> dict[str, int]:
        """Counts since construction: ``steps`` (env steps planned), ``constrained`` (solved to
        tolerance with an active constraint), ``inexact`` (the solve reached ``iterations``
        unconverged: the LQR's command was sent), ``fallbacks`` (a non-finite estimate or
        iterate: the LQR's command was sent); with the solves of batches that ran it in their
        threads (:meth:`add_batch_stats`)."""
        counts = [a + b for a, b in zip(self._filter.stats, getattr(self, "_batch_stats", (0, 0, 0, 0)))]
        steps, constrained, inexact, fallbacks = counts
        return {"steps": steps, "constrained": constrained, "inexact": inexact, "fallbacks": fallbacks}

    def add_batch_stats(self, counts: tuple[int, int, int, int]) -> None:
        """Adds a batch's counts of :meth:`batch_stepper`'s solves (its envs' controllers) to :attr:`stats`."""
        self._batch_stats = tuple(a + int(b) for a, b in zip(getattr(self, "_batch_stats", (0, 0, 0, 0)), counts))

    def tuning_dict(self) -> dict[str, Any]:
        """The MPC settings as a plain mapping (for records)."""
        return asdict(self.tuning)


__all__ = ["MpcParts", "MpcPolicy", "MpcTuning"]
