"""A linear MPC baseline on the LQR's linearization and Kalman filter.

:class:`MpcPolicy` plans over ``horizon`` agent steps from the estimate of the LQR's steady-state
Kalman filter (:class:`accd_gym.control.lqr.LqrPolicy`; the same filter, stepped by the same
Rust code) with the LQR's cost as its stage cost and the LQR's Riccati solution as its terminal
cost, so that without active constraints its command is the LQR's. Constraints:

* **flap limits** (hard): every planned command in [-1, 1];
* **capture conditions** (a terminal set, softened): at the steps from ``lead`` on and from the
  boom's predicted arrival on (the predicted along-track distance changing sign or coming within
  the capture radius), the capture point's y-z offset from the boom
  tip within ``margin * capture_radius`` and its y-z velocity relative to the tip within
  ``margin * max_closing_speed`` (each disk kept by its inscribed octagon); before the arrival,
  at the steps (from ``lead`` on) whose predicted along-track distance is under ``window`` m, the
  velocity within
  ``margin * sqrt(max_closing_speed^2 - a^2)`` (``a``: the boom's closing speed, at most
  ``approach_speed``). The limits are read from the env's ``boom`` configuration. One slack per
  condition with the exact penalty ``slack_weight`` keeps the problem feasible where the set
  cannot be reached in time.

The condensed QP (``4 horizon + 2`` variables) is solved exactly in Rust
(``accd_sim::control::qp``, the Goldfarb-Idnani dual active-set method, started from the
unconstrained optimum, which is one matrix product and the answer when it keeps every
constraint). A solve that reaches ``iterations`` active-set steps, or meets a non-finite
estimate or an infeasible problem, falls back to the LQR's command for that step;
:attr:`MpcPolicy.stats` counts the constrained solves and both fallbacks. Every row is stepped
in fixed-order arithmetic with the GIL released: the same bits whatever the batch size or CPU.

Defaults (:class:`MpcTuning`): horizon 20 agent steps (2 s), lead 15, margin 0.8, chosen on
validation wake seeds only by ``scripts/tune_mpc.py`` (horizons 10 and 20, leads of half and
three quarters of the horizon); ``training/mpc_tuning.json`` records the sweep and the choice.
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

    ``horizon`` (agent steps, >= 1), ``lead`` (the first step of the horizon the capture
    conditions hold at, [1, horizon]), ``margin`` (fraction of the closing-speed limit and of the
    capture radius the prediction keeps, (0, 1]), ``window`` (m: the along-track distance to the
    boom under which the speed rows hold before the arrival), ``slack_weight`` (the exact
    penalty per m/s or m of violation of the capture conditions), ``iterations`` (the
    active-set step limit of one solve).
    """

    horizon: int = 20
    lead: int = 15
    margin: float = 0.8
    window: float = 1.0
    slack_weight: float = 1000.0
    iterations: int = 1000

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
            kind = int if k in ("horizon", "lead", "iterations") else float
            try:
                out[k] = kind(v)
            except (TypeError, ValueError):
                raise ConfigError(f"invalid config: `mpc.{k}` = {v!r} is not a number") from None
        return cls(**out)

    def settings(self) -> tuple[int, int, float, float, float, int]:
        """The values in the order the Rust core takes them."""
        return (int(self.horizon), int(self.lead), float(self.margin), float(self.window), float(self.slack_weight),
                int(self.iterations))


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

    def __init__(self, design: LqrDesign, parts: MpcParts, tuning: MpcTuning,
                 limits: tuple[float, float, float]) -> None:
        self.design = design
        self.parts = parts
        self.tuning = tuning
        self.limits = (float(limits[0]), float(limits[1]), float(limits[2]))
        d = design
        self._filter = _core.Mpc(d.n, d.f, d.g, d.h, d.l, d.k, d.k_ff, d.y_trim, parts.q, parts.p, parts.x_ss,
                                 parts.u_ss, float(d.tuning.r_flap), float(parts.dt), tuning.settings(), self.limits)
        self._batch_stats: tuple[int, int, int, int] = (0, 0, 0, 0)  # solves run by batches (add_batch_stats)

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
        return cls(design, parts, t, (boom["max_closing_speed"], boom["capture_radius"], boom["approach_speed"]))

    @property
    def stats(self) -> dict[str, int]:
        """Counts since construction: ``steps`` (env steps planned), ``constrained`` (solved to
        optimality with an active constraint), ``inexact`` (the solve reached ``iterations``
        active-set steps: the LQR's command was sent), ``fallbacks`` (a non-finite estimate or
        an infeasible problem: the LQR's command was sent); with the solves of batches that ran it
        in their threads (:meth:`add_batch_stats`)."""
        counts = [a + b for a, b in zip(self._filter.stats, self._batch_stats)]
        steps, constrained, inexact, fallbacks = counts
        return {"steps": steps, "constrained": constrained, "inexact": inexact, "fallbacks": fallbacks}

    def add_batch_stats(self, counts: tuple[int, int, int, int]) -> None:
        """Adds a batch's counts of :meth:`batch_stepper`'s solves (its envs' controllers) to :attr:`stats`."""
        a, b, c, d = (x + int(y) for x, y in zip(self._batch_stats, counts))
        self._batch_stats = (a, b, c, d)

    def tuning_dict(self) -> dict[str, Any]:
        """The MPC settings as a plain mapping (for records)."""
        return asdict(self.tuning)


__all__ = ["MpcParts", "MpcPolicy", "MpcTuning"]
