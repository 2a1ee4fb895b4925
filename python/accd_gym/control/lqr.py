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
* **Kalman filter**: steady-state gain from ``scipy.linalg.solve_discrete_are`` on the augmented
  model with process noise ``wind_white^2 E E^T`` (turbulence as white wind at the ACCD) plus
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
from dataclasses import asdict, dataclass, fields
from typing import Any, Mapping, Optional

import numpy as np

from accd_gym import _core
from accd_gym.errors import ConfigError
from accd_gym.envs.task import ACT_DIM, OBS_DIM, OBSERVATION_SCALE, check_observations, observation_indices, OBSERVATION_TABLE
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


#: Rows of the observation the filter reads (all but ``time_left``).
_MEASURED = np.array([i for i in range(OBS_DIM) if i != int(observation_indices("time_left")[0])])
_BOOM_POS = observation_indices("boom_rel_x", "boom_rel_y", "boom_rel_z")
_BOOM_VEL = observation_indices("boom_rel_vx", "boom_rel_vy", "boom_rel_vz")

#: Measurement noise of each observation entry in its physical unit (times ``meas_noise``).
_MEAS_SIGMA = {
    "boom_rel_x": 0.01, "boom_rel_y": 0.01, "boom_rel_z": 0.01,
    "boom_rel_vx": 0.01, "boom_rel_vy": 0.01, "boom_rel_vz": 0.01,
    "accd_dx": 0.01, "accd_dy": 0.01, "accd_dz": 0.01,
    "accd_vx": 0.01, "accd_vy": 0.01, "accd_vz": 0.01,
    "quat_w": 1e-4, "quat_x": 1e-4, "quat_y": 1e-4, "quat_z": 1e-4,
    "rate_p": 1e-3, "rate_q": 1e-3, "rate_r": 1e-3,
    "flap_right": 1e-4, "flap_left": 1e-4, "flap_top": 1e-4, "flap_bottom": 1e-4,
    "tension": 100.0,
}


@dataclass
class LqrDesign:
    """The matrices of one design (see the module docstring): the observer ``z+ = F z + G u``,
    ``z = z- + L (y_m - y*_m - H z-)`` over ``z = (dx, w, r, r')``, and the control law
    ``u = clip(-K dx + K_ff (w, r_y, r_z))``. ``closed_loop_radius``: the spectral radius of
    ``A - B K``; ``observer_radius``: of ``(I - L H) F``."""

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


def _dare(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The stabilizing solution of the discrete algebraic Riccati equation (ConfigError if none)."""
    import scipy.linalg

    try:
        p = scipy.linalg.solve_discrete_are(a, b, q, r)
    except (np.linalg.LinAlgError, ValueError) as e:
        raise ConfigError(f"invalid config: no stabilizing LQR/Kalman design for this configuration ({e})") from None
    return 0.5 * (p + p.T)


def design(lin: Any, tuning: LqrTuning) -> LqrDesign:
    """The LQR and Kalman gains for a linearization ``lin`` (:func:`linearize`) and ``tuning``,
    computed with every BLAS library (numpy's and SciPy's) on one thread. The Riccati solvers'
    last bits depend on the BLAS thread count, and the gains' last bits decide episodes near the
    capture boundary: one thread gives every process the same design (a training process, a Ray
    worker and a command-line evaluation on a machine of any size)."""
    import scipy.linalg  # noqa: F401  (loaded first: threadpoolctl limits the libraries loaded when it is entered)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _design(lin, tuning)


def _design(lin: Any, tuning: LqrTuning) -> LqrDesign:
    t = tuning
    a, b, e, c = lin.a, lin.b, lin.e, lin.c
    n = a.shape[0]
    names = lin.state_names
    steps = np.asarray(lin.steps)
    dt = lin.dt
    sp = OBSERVATION_SCALE["boom_rel_x"]
    sv = OBSERVATION_SCALE["boom_rel_vx"]
    cp = -c[_BOOM_POS] / sp  # capture point (m) per state
    cpv = -c[_BOOM_VEL] / sv  # its velocity (m/s) per state

    # LQR on the plant.
    att = np.array([names.index(k) for k in ("att_x", "att_y", "att_z")])
    rates = np.array([names.index(k) for k in ("p", "q", "r")])
    q = t.q_position * cp[1:].T @ cp[1:] + t.q_velocity * cpv.T @ cpv + 1e-9 * np.eye(n)
    q[att, att] += t.q_attitude
    q[rates, rates] += t.q_rate
    r = t.r_flap * np.eye(ACT_DIM)
    p = _dare(a, b, q, r)
    k = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)

    # Offset-free target: (A - I) dx + B u = -E w, cp_yz dx = r_yz, minimum norm in scaled units.
    m = np.block([[a - np.eye(n), b], [cp[1:], np.zeros((2, ACT_DIM))]])
    d = np.concatenate([steps * 1e3, np.ones(ACT_DIM)])
    rhs = np.block([[-e, np.zeros((n, 2))], [np.zeros((2, 2)), np.eye(2)]])  # per (w_y, w_z, r_y, r_z)
    sol = d[:, None] * (np.linalg.pinv(m * d[None, :], rcond=1e-10) @ rhs)
    x_ss, u_ss = sol[:n], sol[n:]
    k_ff = u_ss + k @ x_ss  # u = u_ss - K (dx - x_ss) = -K dx + k_ff (w, r_yz)

    # Observer on z = (dx, w, r, r').
    nz = n + 2 + 3 + 3
    f = np.zeros((nz, nz))
    f[:n, :n] = a
    f[:n, n:n + 2] = e
    f[n:n + 2, n:n + 2] = np.eye(2)
    f[n + 2:n + 5, n + 2:n + 5] = np.eye(3)
    f[n + 2:n + 5, n + 5:] = dt * np.eye(3)
    f[n + 5:, n + 5:] = np.eye(3)
    g = np.zeros((nz, ACT_DIM))
    g[:n] = b
    h = np.zeros((len(_MEASURED), nz))
    h[:, :n] = c[_MEASURED]
    rows = list(_MEASURED)
    for j in range(3):
        h[rows.index(_BOOM_POS[j]), n + 2 + j] = sp
        h[rows.index(_BOOM_VEL[j]), n + 5 + j] = sv
    qn = np.zeros((nz, nz))
    qn[:n, :n] = t.wind_white**2 * e @ e.T + np.diag((t.model_noise * 1e3 * steps) ** 2)
    qn[n:n + 2, n:n + 2] = t.wind_walk**2 * np.eye(2)
    qn[n + 2:n + 5, n + 2:n + 5] = 1e-6 * np.eye(3)
    qn[n + 5:, n + 5:] = t.boom_accel**2 * np.eye(3)

    sigma = np.array([_MEAS_SIGMA[OBSERVATION_TABLE[i][0]] * OBSERVATION_TABLE[i][2] for i in _MEASURED])
    rn = np.diag((t.meas_noise * sigma) ** 2)
    pz = _dare(f.T, h.T, qn, rn)
    l_gain = pz @ h.T @ np.linalg.inv(h @ pz @ h.T + rn)

    closed = float(np.max(np.abs(np.linalg.eigvals(a - b @ k))))
    observer = float(np.max(np.abs(np.linalg.eigvals((np.eye(nz) - l_gain @ h) @ f))))
    return LqrDesign(tuning=t, f=f, g=g, h=h, l=l_gain, k=k, k_ff=k_ff,
                     y_trim=np.asarray(lin.trim_observation)[_MEASURED], n=n,
                     closed_loop_radius=closed, observer_radius=observer)


#: Designs by (configuration JSON without its seeds, tuning): the look-up that skips the
#: linearization.
_DESIGNS: dict[tuple[str, LqrTuning], LqrDesign] = {}
#: Designs by (plant digest, tuning): configurations that differ only where the plant does not
#: (the capture limits, the turbulence, the sensors: every registered tier) share one design.
_PLANT_DESIGNS: dict[tuple[str, LqrTuning], LqrDesign] = {}

#: What :func:`design` reads of a linearization, the arrays of the plant key.
_PLANT_ARRAYS = ("a", "b", "c", "e", "steps", "trim_observation")


def _plant_key(lin: Any) -> str:
    """SHA-256 of everything :func:`design` reads of ``lin``: equal keys, equal designs."""
    h = hashlib.sha256()
    for name in _PLANT_ARRAYS:
        arr = np.ascontiguousarray(np.asarray(getattr(lin, name), dtype=np.float64))
        h.update(f"{name}{arr.shape}".encode())
        h.update(arr.tobytes())
    h.update(float(lin.dt).hex().encode())
    h.update("\0".join(lin.state_names).encode())
    return h.hexdigest()


def _design_key(cfg: "_core.EnvConfig") -> str:
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
        self._z: Optional[np.ndarray] = None
        self._u: Optional[np.ndarray] = None
        self._fresh: Optional[np.ndarray] = None

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
        key = (_design_key(cfg), t)
        if key not in _DESIGNS:
            lin = _core.linearize(cfg)
            plant = (_plant_key(lin), t)
            if plant not in _PLANT_DESIGNS:
                _PLANT_DESIGNS[plant] = design(lin, t)
            _DESIGNS[key] = _PLANT_DESIGNS[plant]
        return cls(_DESIGNS[key])

    def reset(self, mask: Optional[np.ndarray] = None) -> None:
        """Restarts the estimates of the envs in ``mask`` (all when None)."""
        if self._fresh is None:
            return
        if mask is None:
            self._fresh[:] = True
            return
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != self._fresh.shape:
            self._z = None  # another batch: every estimate starts afresh at the next predict
        else:
            self._fresh[mask] = True

    def predict(self, obs: Any) -> np.ndarray:
        """Flap commands (N, 4) in [-1, 1] for observations (N, 25); advances the estimates."""
        o = check_observations(obs)
        d = self.design
        n_env = o.shape[0]
        if self._z is None or self._z.shape[0] != n_env:
            self._z = np.zeros((n_env, d.f.shape[0]))
            self._u = np.zeros((n_env, ACT_DIM))
            self._fresh = np.ones(n_env, dtype=bool)
        y = o[:, _MEASURED] - d.y_trim
        prior = self._z @ d.f.T + self._u @ d.g.T
        prior[self._fresh] = 0.0
        z = prior + (y - prior @ d.h.T) @ d.l.T
        self._fresh[:] = False
        n = d.n
        reference = np.concatenate([z[:, n:n + 2], z[:, n + 3:n + 5]], axis=1)  # w_y, w_z, r_y, r_z
        u = np.clip(-z[:, :n] @ d.k.T + reference @ d.k_ff.T, -1.0, 1.0)
        self._z = z
        self._u = u
        return u.astype(np.float32)

    def sent(self, offset: np.ndarray) -> None:
        """Tells the filter that the command actually sent differs from the last :meth:`predict`'s
        by ``offset`` ((N, 4), flap-limit units; residual control adds a correction): its next
        prediction uses the command sent. A zero offset changes nothing, bit for bit."""
        if self._u is not None:
            self._u = self._u + np.asarray(offset, dtype=np.float64)

    def get_state(self) -> dict[str, np.ndarray]:
        """The filter's state per env (copies; empty before the first :meth:`predict`): with
        :meth:`set_state` on a policy of the same design it continues bit for bit."""
        if self._z is None:
            return {}
        return {"z": self._z.copy(), "u": self._u.copy(), "fresh": self._fresh.copy()}

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restores a state of :meth:`get_state` (an empty one: every estimate starts afresh)."""
        if not state:
            self._z = self._u = self._fresh = None
            return
        z, u, fresh = (np.array(state[k]) for k in ("z", "u", "fresh"))
        nz = self.design.f.shape[0]
        if z.ndim != 2 or z.shape[1] != nz or u.shape != (z.shape[0], ACT_DIM) or fresh.shape != (z.shape[0],):
            raise ConfigError(f"invalid config: LQR filter state of shapes {z.shape}, {u.shape}, {fresh.shape} does "
                              f"not fit this design (N x {nz}, N x {ACT_DIM}, N)")
        self._z, self._u, self._fresh = z.astype(np.float64), u.astype(np.float64), fresh.astype(bool)


def blas_kernels() -> list[tuple[str, str]]:
    """The BLAS libraries that numpy and SciPy loaded and the kernels each chose for this CPU,
    ``[(internal_api, architecture), ...]`` sorted (e.g. ``[("openblas", "SkylakeX")]``). The
    LQR's design and Kalman filter run on them and their last bits follow the kernels
    (docs/decisions.md, "Known limitations")."""
    import scipy.linalg  # noqa: F401  (loaded first: threadpoolctl reports the libraries loaded)
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


__all__ = ["LqrDesign", "LqrPolicy", "LqrTuning", "blas_kernels", "default_tuning", "design", "is_lqr_tuning",
           "linearize", "lqr_from_tuning"]
