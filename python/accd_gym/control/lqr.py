"""The linearized capture dynamics and an LQR baseline with a disturbance observer.

:func:`linearize` returns the discrete-time model of one agent step of a configuration about
its open-loop trim (the Rust core's ``accd_sim::linearize``)::

    x+ - x* = A (x - x*) + B u + E w        y - y* = C (x - x*)

``x``: the tether's coordinates and rates, the ACCD's attitude error (a rotation vector, body
axes) and body rates, the four flap deflections (``state_names``); ``u``: the four flap
commands in units of the flap limit (the env's action), held for ``agent_step``; ``w``: a wind
bias at the ACCD (m/s, y and z); ``y``: the 25 observations (scaled, before clipping) with the
boom tip held fixed at the trim capture point. Central differences with a stated step per
component (``steps``); turbulence off; the trim is the Rust ``Equilibrium::settle`` state
refined by Newton iterations to a fixed point (``trim_residual``).

:class:`LqrPolicy` is the classical baseline of the published In-Air Capturing work in its
simplest honest form: an LQR on a steady-state Kalman filter's estimate, with disturbance
states, designed per configuration (gain scheduling by config: :meth:`LqrPolicy.for_config`).

Design (per configuration; ``T`` = ``agent_step``)
--------------------------------------------------
* **Plant**: the full linear model above (2 n + 11 = 132 states for the default 30 segments;
  nothing reduced).
* **Observer state** ``z = (dx, w, r, r')``: the plant state, the wind bias ``w`` at the ACCD
  (y, z; a random walk, standing for the mean wake's error and slow turbulence), the boom tip
  relative to the trim capture point ``r`` and its velocity ``r'`` (constant velocity driven by
  white acceleration: the boom drifts, and approaches along track). Observations: all but
  ``time_left`` (24); ``boom_rel`` rows read ``r - (capture point - trim capture point)``.
* **Kalman filter**: steady-state gain from the filter's discrete Riccati equation on the
  augmented model with process noise ``wind_white^2 E E^T`` (turbulence as white wind at the ACCD) plus
  ``(model_noise * 1000 h_i)^2`` on each plant state (``h_i`` its finite-difference step: 1 mm of
  the elongation, 1 mrad of each angle, 0.01 rad/s of each rate, per step), ``wind_walk^2`` on
  ``w``, ``boom_accel^2`` on ``r'``; measurement noise ``meas_noise`` times 1 cm (positions),
  1 cm/s (velocities), 1e-4 (quaternion, flaps), 1e-3 rad/s (rates), 100 N (tension).
  Prediction uses the flap command actually sent (clipped).
* **Reference** (offset-free tracking): the steady state ``(dx_ss, u_ss)`` with
  ``(A - I) dx_ss + B u_ss + E w = 0`` that puts the capture point's y and z on the boom tip
  (``r_y, r_z``), the minimum-norm one (states in units of their steps, commands in flap-limit
  units: the roll angle is neutral, so there is a family). Along track (x) nothing is tracked:
  the ACCD has almost no authority there (docs/decisions.md, "The RLV approaches along track"); the RLV closes it.
* **LQR** on ``dx - dx_ss``: ``u = u_ss - K (dx - dx_ss)``, clipped to [-1, 1], ``K`` from the
  DARE with ``Q = q_position P_yz^T P_yz + q_velocity V^T V + q_attitude (attitude error)
  + q_rate (body rates) + 1e-9 I`` (``P_yz``: the capture point's y, z per state; ``V``: its
  velocity, all three axes, since the closing speed counts) and ``R = r_flap I``.
* **Start**: an episode's first observation sets the estimate by one filter update from zero.

Both Riccati equations are solved by the Rust core (``accd_sim::control``) with a structured
doubling algorithm, the reference by a Householder factorization, and the filter and control law
are stepped there too: every operation in one fixed order, with no BLAS, so the design and every
command are the same bits on every CPU, with any batch size and any number of threads
(docs/decisions.md, "The LQR in fixed-order Rust"). ``tests/test_lqr_design.py`` checks the
Riccati solutions against SciPy's ``solve_discrete_are``.

Limits: a linear model of one trim. Large excursions (several metres, tens of degrees of roll)
leave its validity; the filter knows no clipping of the observation (at +-10: 200 m, 100 m/s);
a scripted aircraft profile is frozen at time 0; the kinks of the tables (aerodynamic nodes at
sideslip and deflection 0, trilinear wake) make the model the mean of the one-sided slopes.

Tuning (``scripts/tune_lqr.py``, training wake seeds 2000.. with base seed 7 only; the result and
how it was found in ``training/lqr_tuning.json``; :class:`LqrTuning`'s defaults are its winner):
three grid stages on the precision scenario (LQR weights, then the filter's wind noise), winner
q_position 3, q_velocity 0.1, r_flap 0.1, wind_white 3, wind_walk 0.03 (93/96 training
episodes there; 48/48 on the default task). Held out (100 episodes, ``accd-gym evaluate``):
100 % on the default task, 91 % (83.8 - 95.2 %) in the precision scenario against the guidance
controller's 52 %. No rate cost: the flaps move more from step to step than the guidance's.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, fields
from typing import Any, Mapping, Optional

import numpy as np

from accd_gym import _core
from accd_gym.errors import ConfigError
from accd_gym.envs.task import ACT_DIM, check_observations
from accd_gym.envs.config import valid_config
from accd_gym.files import read_user_json


def linearize(config: Optional[Mapping[str, Any]] = None, **overrides: Any) -> "_core.Linearization":
    """The discrete-time linear model of one agent step of a configuration about its trim.

    ``config`` and ``overrides`` as for the envs (:func:`accd_gym.env_config`; a
    :class:`accd_gym._core.EnvConfig` is taken as it is). Returns an
    ``accd_gym._core.Linearization`` with ``a`` (n x n), ``b`` (n x 4, per unit of flap command),
    ``e`` (n x 2, per m/s of wind bias at the ACCD, y and z), ``c`` (25 x n: the observation,
    scaled, before clipping, the boom held fixed), ``trim`` (x*), ``trim_observation`` (y*, the
    boom tip at the trim capture point), ``trim_attitude``, ``state_names``, ``steps`` (the
    finite-difference step of each component), ``capture_point``, ``position``,
    ``equilibrium_position``, ``settle_residual``, ``trim_residual``, ``dt``, and the nonlinear
    step it came from (``step(dx, u, wind)``, ``observe(dx)``). Raises
    :class:`~accd_gym.ConfigError` for a bad configuration.
    """
    if isinstance(config, _core.EnvConfig) and not overrides:
        cfg = config
    else:
        if isinstance(config, _core.EnvConfig):
            config = json.loads(config.to_json())
        cfg = valid_config(config, **overrides)
    return _core.linearize(cfg)


@dataclass(frozen=True)
class LqrTuning:
    """Weights and noise levels of :class:`LqrPolicy` (see the module docstring for each).

    ``q_position`` (1/m^2), ``q_velocity`` (s^2/m^2), ``q_attitude`` (1/rad^2), ``q_rate``
    (s^2/rad^2), ``r_flap`` (per flap-limit unit squared): LQR weights per agent step.
    ``wind_white`` (m/s), ``wind_walk`` (m/s per step), ``boom_accel`` (m/s per step),
    ``model_noise`` (-), ``meas_noise`` (-): the Kalman filter's noise model.
    """

    q_position: float = 3.0
    q_velocity: float = 0.1
    q_attitude: float = 10.0
    q_rate: float = 0.1
    r_flap: float = 0.1
    wind_white: float = 3.0
    wind_walk: float = 0.03
    boom_accel: float = 0.02
    model_noise: float = 1.0
    meas_noise: float = 1.0

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> "LqrTuning":
        """A tuning from a mapping of its fields (ConfigError naming unknown or non-positive ones)."""
        names = {f.name for f in fields(cls)}
        unknown = set(values) - names
        if unknown:
            raise ConfigError(f"invalid config: LQR tuning key(s) {sorted(unknown)} outside the allowed set {sorted(names)}")
        out = {}
        for k, v in values.items():
            try:
                x = float(v)
            except (TypeError, ValueError):
                raise ConfigError(f"invalid config: LQR tuning `{k}` = {v!r} is outside the allowed range (0, inf)") from None
            if not (np.isfinite(x) and x > 0.0):
                raise ConfigError(f"invalid config: LQR tuning `{k}` = {v!r} is outside the allowed range (0, inf)")
            out[k] = x
        return cls(**out)


@dataclass
class LqrDesign:
    """The matrices of one design (see the module docstring): the observer ``z+ = F z + G u``,
    ``z = z- + L (y_m - y*_m - H z-)`` over ``z = (dx, w, r, r')``, and the control law
    ``u = clip(-K dx + K_ff (w, r_y, r_z))``. ``closed_loop_radius``: the spectral radius of
    ``A - B K``; ``observer_radius``: of ``(I - L H) F``; ``residuals``: the relative residuals
    of the LQR's and the filter's Riccati equations; ``doublings``: the doubling steps their
    solves took."""

    tuning: LqrTuning
    f: np.ndarray
    g: np.ndarray
    h: np.ndarray
    l: np.ndarray
    k: np.ndarray
    k_ff: np.ndarray
    y_trim: np.ndarray
    n: int
    closed_loop_radius: float
    observer_radius: float
    residuals: tuple[float, float] = (0.0, 0.0)
    doublings: tuple[int, int] = (0, 0)

    def filter(self) -> "_core.LqrFilter":
        """A new Rust stepper of this design (its Kalman filter and control law, no env state yet)."""
        return _core.LqrFilter(self.n, self.f, self.g, self.h, self.l, self.k, self.k_ff, self.y_trim)


def design(lin: Any, tuning: LqrTuning) -> LqrDesign:
    """The LQR and Kalman gains for a linearization ``lin`` (:func:`linearize`) and ``tuning``,
    computed by the Rust core (``accd_sim::control::lqr``): both Riccati equations by the
    structured doubling algorithm and the reference by a Householder factorization, every
    operation in one fixed order with no BLAS, so every machine and thread count gives the
    same bits. ConfigError when either Riccati equation has no stabilizing solution (or its
    residual is too large) or the reference problem is rank deficient."""
    d = _core.lqr_design(lin, [float(getattr(tuning, f.name)) for f in fields(LqrTuning)])
    return LqrDesign(tuning=tuning, f=d.f, g=d.g, h=d.h, l=d.l, k=d.k, k_ff=d.k_ff, y_trim=d.y_trim, n=d.n,
                     closed_loop_radius=d.closed_loop_radius, observer_radius=d.observer_radius,
                     residuals=d.residuals, doublings=d.doublings)


#: Designs by (configuration JSON without its seeds, tuning): the look-up that skips the
#: linearization.
_DESIGNS: dict[tuple[str, LqrTuning], LqrDesign] = {}
#: Designs by (plant digest, tuning): configurations that differ only where the plant does not
#: (the capture limits, the turbulence, the sensors: every registered tier) share one design.
_PLANT_DESIGNS: dict[tuple[str, LqrTuning], LqrDesign] = {}

#: What :func:`design` reads of a linearization, the arrays of the plant key.
_PLANT_ARRAYS = ("a", "b", "c", "e", "steps", "trim_observation")


def plant_key(lin: Any) -> str:
    """SHA-256 of everything :func:`design` reads of ``lin``: equal keys, equal designs."""
    h = hashlib.sha256()
    for name in _PLANT_ARRAYS:
        arr = np.ascontiguousarray(np.asarray(getattr(lin, name), dtype=np.float64))
        h.update(f"{name}{arr.shape}".encode())
        h.update(arr.tobytes())
    h.update(float(lin.dt).hex().encode())
    h.update("\0".join(lin.state_names).encode())
    return h.hexdigest()


def design_key(cfg: "_core.EnvConfig") -> str:
    """The configuration's JSON without what does not change the plant (wake seeds)."""
    doc = json.loads(cfg.to_json())
    doc.pop("wake_seed", None)
    doc.pop("wake_seeds", None)
    return json.dumps(doc, sort_keys=True)


def default_tuning() -> LqrTuning:
    """:class:`LqrTuning`'s defaults (the winner recorded in ``training/lqr_tuning.json``)."""
    return LqrTuning()


class LqrPolicy:
    """LQR with a steady-state Kalman filter and disturbance states (see the module docstring).

    Build it for the env configuration it runs on: ``LqrPolicy.for_config(config)``; designs
    are cached by configuration (seeds aside) and tuning, and shared by configurations with one
    plant (the same linearization). ``predict(obs)`` takes observations
    of shape (N, 25) and returns flap commands (N, 4) in [-1, 1]; ``reset(mask)`` restarts the
    estimates of the envs in ``mask`` (their next observation initialises them).
    """

    name = "lqr"

    def __init__(self, design: LqrDesign) -> None:
        self.design = design
        self._filter = design.filter()

    def __getstate__(self) -> dict[str, Any]:
        return {"design": self.design, "name": self.name, "state": self.get_state()}

    def __setstate__(self, state: Mapping[str, Any]) -> None:
        self.__init__(state["design"])
        self.name = state.get("name", type(self).name)
        if "state" in state:
            self.set_state(state["state"])
        elif state.get("_z") is not None:  # the numpy filter's attributes
            self.set_state({"z": state["_z"], "u": state["_u"], "fresh": state["_fresh"]})

    @classmethod
    def for_config(cls, config: Any = None, tuning: Optional[LqrTuning | Mapping[str, Any]] = None,
                   **overrides: Any) -> "LqrPolicy":
        """The policy designed for an env configuration (a mapping of overrides, an
        ``accd_gym._core.EnvConfig`` or None for the defaults, plus keyword overrides) with
        ``tuning`` (default :func:`default_tuning`). Raises ConfigError for a bad configuration
        or one with no stabilizing design."""
        if isinstance(config, _core.EnvConfig):
            cfg = config if not overrides else valid_config(json.loads(config.to_json()), **overrides)
        else:
            cfg = valid_config(config, **overrides)
        t = tuning if isinstance(tuning, LqrTuning) else (LqrTuning.from_mapping(tuning) if tuning else default_tuning())
        key = (design_key(cfg), t)
        if key not in _DESIGNS:
            lin = _core.linearize(cfg)
            plant = (plant_key(lin), t)
            if plant not in _PLANT_DESIGNS:
                _PLANT_DESIGNS[plant] = design(lin, t)
            _DESIGNS[key] = _PLANT_DESIGNS[plant]
        return cls(_DESIGNS[key])

    def reset(self, mask: Optional[np.ndarray] = None) -> None:
        """Restarts the estimates of the envs in ``mask`` (all when None)."""
        if self._filter.num_envs == 0:
            return
        if mask is None:
            self._filter.restart()
            return
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != (self._filter.num_envs,):
            self._filter.clear()  # another batch: every estimate starts afresh at the next predict
        else:
            self._filter.restart(mask)

    def predict(self, obs: Any) -> np.ndarray:
        """Flap commands (N, 4) in [-1, 1] for observations (N, 25); advances the estimates. The
        filter step runs in Rust with the GIL released, each row in fixed-order arithmetic (the
        same bits for any batch size or CPU)."""
        o = check_observations(obs)
        return self._filter.step(np.ascontiguousarray(o, dtype=np.float64))

    def predict_rows(self, obs: Any, rows: np.ndarray) -> np.ndarray:
        """:meth:`predict` advancing only the envs in the bool mask ``rows`` (the others keep
        their estimates; their commands in the result are zero). A row's command has the bits
        :meth:`predict` would give it."""
        o = np.ascontiguousarray(check_observations(obs), dtype=np.float64)
        if self._filter.num_envs != o.shape[0]:  # no estimates of this batch yet: every row starts
            return self._filter.step(o)
        return self._filter.step(o, np.ascontiguousarray(rows, dtype=bool))

    def peek(self, obs: Any) -> np.ndarray:
        """The commands :meth:`predict` would give for ``obs``, advancing no estimate."""
        o = check_observations(obs)
        return self._filter.step(np.ascontiguousarray(o, dtype=np.float64), None, False)

    def batch_stepper(self) -> Any:
        """The Rust stepper of this design (``_core.LqrFilter``; ``_core.Mpc`` for the MPC) for a
        batch to run per env in its own threads (``_core.BatchEnv.set_controller``): the
        vector envs' residual base and the evaluation of this policy run it there, each env's
        command computed right after its step, with the GIL released and the same bits as
        :meth:`predict`. Its env states are this policy's; the batch keeps its own."""
        return self._filter

    def add_batch_stats(self, counts: tuple[int, int, int, int]) -> None:
        """Counts of a batch that ran :meth:`batch_stepper` (the MPC's solves; the LQR keeps none)."""

    def sent(self, offset: np.ndarray) -> None:
        """Tells the filter that the command actually sent differs from the last :meth:`predict`'s
        by ``offset`` ((N, 4), flap-limit units; residual control adds a correction): its next
        prediction uses the command sent. A zero offset changes nothing, bit for bit."""
        if self._filter.num_envs:
            self._filter.sent(np.ascontiguousarray(offset, dtype=np.float64))

    def get_state(self) -> dict[str, np.ndarray]:
        """The filter's state per env (copies; empty before the first :meth:`predict`): ``z``
        (N, nz), ``u`` (N, 4), ``fresh`` (N,); with :meth:`set_state` on a policy of the same
        design it continues bit for bit."""
        if self._filter.num_envs == 0:
            return {}
        z, u, fresh = self._filter.get_state()
        return {"z": z, "u": u, "fresh": fresh}

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restores a state of :meth:`get_state` (an empty one: every estimate starts afresh)."""
        if not state:
            self._filter.clear()
            return
        z, u, fresh = (np.array(state[k]) for k in ("z", "u", "fresh"))
        nz = self.design.f.shape[0]
        if z.ndim != 2 or z.shape[1] != nz or u.shape != (z.shape[0], ACT_DIM) or fresh.shape != (z.shape[0],):
            raise ConfigError(f"invalid config: LQR filter state of shapes {z.shape}, {u.shape}, {fresh.shape} does "
                              f"not fit this design (N x {nz}, N x {ACT_DIM}, N)")
        self._filter.set_state(np.ascontiguousarray(z, dtype=np.float64), np.ascontiguousarray(u, dtype=np.float64),
                               np.ascontiguousarray(fresh, dtype=bool))


def blas_kernels() -> list[tuple[str, str]]:
    """The BLAS libraries loaded in this process (numpy's, and SciPy's or PyTorch's where they
    are loaded) and the kernels each chose for this CPU, ``[(internal_api, architecture), ...]``
    sorted (e.g. ``[("openblas", "SkylakeX")]``): for the record of a machine. The LQR does not
    run on them (its design and filter are fixed-order Rust)."""
    from threadpoolctl import threadpool_info

    return sorted({(i["internal_api"], i.get("architecture") or "") for i in threadpool_info()
                   if i.get("user_api") == "blas"})


def is_lqr_tuning(path: str) -> bool:
    """Whether the JSON file ``path`` is an LQR tuning result (``"policy": "lqr"``)."""
    from pathlib import Path

    if not Path(path).exists():
        return False
    try:
        doc = read_user_json(path, "tuning file")
    except ConfigError:
        return False
    return isinstance(doc, dict) and doc.get("policy") == "lqr"


def lqr_from_tuning(path: str, config: Any = None) -> LqrPolicy:
    """The LQR designed for ``config`` with the winning tuning of a ``scripts/tune_lqr.py``
    result file (ConfigError if it is not one)."""
    from pathlib import Path

    doc = read_user_json(path, "LQR tuning file")
    try:
        best = doc["best"]["tuning"]
    except (KeyError, TypeError) as e:
        raise ConfigError(f"invalid config: policy {path!r} is not an LQR tuning file ({e})") from None
    policy = LqrPolicy.for_config(config, tuning=best)
    policy.name = f"lqr ({Path(path).stem})"
    return policy


__all__ = ["LqrDesign", "LqrPolicy", "LqrTuning", "blas_kernels", "default_tuning", "design", "design_key",
           "is_lqr_tuning", "linearize", "lqr_from_tuning", "plant_key"]
