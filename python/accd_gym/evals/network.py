"""A shipped policy's network as plain arrays (``network.npz``) and its forward pass in
fixed-order arithmetic, so that evaluating a shipped policy needs neither PyTorch nor
stable-baselines3 and gives the same actions on every CPU.

The file (written by ``scripts/export_networks.py`` from the stable-baselines3 model and its
VecNormalize statistics; the format is documented in docs/trained-policies.md) holds the actor's
layers (float32 weights and biases, as trained), the observation normalisation (float64 mean and
variance, epsilon, clip), how the network's output becomes an action (SAC: tanh of the mean, then
stable-baselines3's unscaling to the action bounds; PPO: the mean clipped to the bounds) and the
env options the policy was trained with (residual base, history), as a JSON ``spec`` entry.

Why the forward pass is written out instead of calling ``x @ W``: a matrix product goes to BLAS
(numpy's OpenBLAS, PyTorch's MKL or oneDNN), whose kernels pick the summation order, blocking and
fused multiply-adds per CPU, so the last bits of an action differ between CPUs and library
versions, and a closed loop of several hundred steps can turn last bits into another episode.
Here every operation is a separate IEEE-754 elementwise numpy operation (``+``, ``*``, ``/``,
``sqrt``, comparisons), each correctly rounded on every CPU and never contracted into a fused
multiply-add, in an order the code fixes:

* a layer is ``y_j = (((b_j + x_0 W_0j) + x_1 W_1j) + ...) + x_{n-1} W_{n-1,j}`` in float64
  (inputs in index order; no reduction whose order a library chooses);
* tanh is computed from an exponential written out as Cody-Waite range reduction and a degree-13
  Taylor polynomial (about 1e-16 absolute error), because numpy's own ``tanh``/``exp`` dispatch
  to CPU-specific SIMD implementations (SVML on AVX-512) that round differently;
* the action is rounded to float32 once, at the end, and turned into a command as
  stable-baselines3 does (in float32).

The float64 pass is closer to the exact result than PyTorch's float32 pass; the two agree within
1e-6 (``tests/test_trained_network.py``), not bit for bit.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Optional

import numpy as np

from accd_gym.envs.agent_io import AgentSideMethods, PolicyAgentIO, physics_config, split_agent_options
from accd_gym.errors import ConfigError

#: The file name of an exported network in a shipped policy's folder.
NETWORK_FILE = "network.npz"
#: The ``format`` of the spec this module reads.
FORMAT = "accd-gym network"
#: The spec version this module reads.
VERSION = 1
#: The activations a layer may have.
ACTIVATIONS = ("relu", "tanh", "identity")

# Cody-Waite split of ln 2 (fdlibm's: the high part has its low 21 bits zero, so k * _LN2_HI is
# exact for |k| < 2^21) and the Taylor coefficients 1/k! (Python's integer division rounds
# correctly), Horner order from the highest.
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e00
_EXP_COEFFS = tuple(1 / math.factorial(k) for k in range(13, -1, -1))
#: Beyond this |x| tanh(x) rounds to +-1 in float64 (tanh(20) = 1 - 8.5e-18).
_TANH_SATURATION = 20.0


def exp_nonpositive(y: np.ndarray) -> np.ndarray:
    """exp(y) for float64 ``y`` in [-2 * 20, 0] from basic IEEE operations alone (the same bits on
    every CPU): y = k ln 2 + r with |r| <= ln 2 / 2, exp(r) by its Taylor polynomial of degree 13
    (truncation below 5e-18 relative), times 2^k exactly."""
    k = np.rint(y * _INV_LN2)
    r = (y - k * _LN2_HI) - k * _LN2_LO
    p = np.full_like(r, _EXP_COEFFS[0])
    for c in _EXP_COEFFS[1:]:
        p = p * r + c
    return np.ldexp(p, k.astype(np.int64))


def tanh(x: np.ndarray) -> np.ndarray:
    """tanh of float64 ``x`` from basic IEEE operations alone: sign(x) (1 - t) / (1 + t) with
    t = exp(-2|x|) (:func:`exp_nonpositive`); about 1e-16 absolute error."""
    a = np.minimum(np.abs(x), _TANH_SATURATION)
    t = exp_nonpositive(-2.0 * a)
    return np.copysign((1.0 - t) / (1.0 + t), x)


def linear(x: np.ndarray, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """``x W + b`` for float64 ``x`` (N, n), ``weight`` (n, m) and ``bias`` (m,), summed in a
    fixed order: the bias, then input 0, 1, ..., n-1, each product and each sum one rounding (no
    BLAS, no fused multiply-add). Each row of the result depends on that row of ``x`` alone."""
    out = np.empty((x.shape[0], weight.shape[1]), dtype=np.float64)
    out[...] = bias
    term = np.empty_like(out)
    for i in range(weight.shape[0]):
        np.multiply(x[:, i : i + 1], weight[i], out=term)
        np.add(out, term, out=out)
    return out


def _activate(x: np.ndarray, name: str) -> np.ndarray:
    if name == "relu":
        return np.maximum(x, 0.0)
    if name == "tanh":
        return tanh(x)
    return x


class Network:
    """An exported actor network (``network.npz``): :meth:`actions` maps the agent's raw
    observations to the actions in [-1, 1] that stable-baselines3's deterministic ``predict``
    would give, in fixed-order arithmetic (module docs).

    ``path``: the ``network.npz`` file, or a folder holding one. ConfigError naming the file when
    it is missing, damaged, or of another format or version.
    """

    def __init__(self, path: str | Path) -> None:
        p = Path(path)
        if p.is_dir():
            p = p / NETWORK_FILE
        #: The file read.
        self.path = p
        if not p.is_file():
            raise ConfigError(f"invalid config: network file {str(p)!r} does not exist "
                              "(scripts/export_networks.py writes it from a stable-baselines3 model)")
        try:
            with np.load(p, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
            spec = json.loads(str(arrays.pop("spec")))
        except (OSError, ValueError, KeyError) as e:
            raise ConfigError(f"invalid config: network file {str(p)!r} cannot be read (truncated or corrupted: "
                              f"{type(e).__name__}: {e})") from None
        if not isinstance(spec, dict) or spec.get("format") != FORMAT or spec.get("version") != VERSION:
            got = (spec.get("format"), spec.get("version")) if isinstance(spec, dict) else spec
            raise ConfigError(f"invalid config: network file {str(p)!r} has format {got!r}; this version reads "
                              f"({FORMAT!r}, {VERSION})")
        #: The file's spec (format, algorithm, layers, normalisation, action, env options).
        self.spec: dict[str, Any] = spec
        self.algo: str = spec["algo"]
        self.obs_dim = int(spec["observation_dim"])
        self.action_dim = int(spec["action_dim"])
        self._layers: list[tuple[np.ndarray, np.ndarray, str]] = []
        width = self.obs_dim
        for k, layer in enumerate(spec["layers"]):
            w = self._array(arrays, layer["weight"], np.float32)
            b = self._array(arrays, layer["bias"], np.float32)
            act = layer["activation"]
            if act not in ACTIVATIONS or w.ndim != 2 or w.shape[0] != width or b.shape != (w.shape[1],):
                raise ConfigError(f"invalid config: network file {str(p)!r}: layer {k} has weight {w.shape}, bias "
                                  f"{b.shape}, activation {act!r}; expected ({width}, m), (m,), one of {ACTIVATIONS}")
            # float32 -> float64 is exact: the weights are the trained ones.
            self._layers.append((w.astype(np.float64), b.astype(np.float64), act))
            width = w.shape[1]
        if width != self.action_dim:
            raise ConfigError(f"invalid config: network file {str(p)!r}: the last layer has {width} outputs, "
                              f"the action {self.action_dim}")
        norm = spec.get("normalization")
        self._norm: Optional[tuple[np.ndarray, np.ndarray, float]] = None
        if norm is not None:
            mean = self._array(arrays, norm["mean"], np.float64)
            var = self._array(arrays, norm["var"], np.float64)
            if mean.shape != (self.obs_dim,) or var.shape != (self.obs_dim,):
                raise ConfigError(f"invalid config: network file {str(p)!r}: normalisation of shape {mean.shape}, "
                                  f"observations ({self.obs_dim},)")
            # As VecNormalize.normalize_obs: (obs - mean) / sqrt(var + epsilon), clipped.
            self._norm = (mean, np.sqrt(var + float(norm["epsilon"])), float(norm["clip"]))
        action = spec["action"]
        self._squash = action["squash"]
        if self._squash not in ("tanh", "none"):
            raise ConfigError(f"invalid config: network file {str(p)!r}: action squash {self._squash!r} is outside "
                              "the allowed range ['tanh', 'none']")
        self._low = np.asarray(action["low"], dtype=np.float32)
        self._high = np.asarray(action["high"], dtype=np.float32)

    def _array(self, arrays: dict[str, np.ndarray], key: str, dtype: Any) -> np.ndarray:
        if key not in arrays or arrays[key].dtype != dtype:
            raise ConfigError(f"invalid config: network file {str(self.path)!r} has no {np.dtype(dtype).name} "
                              f"array {key!r}")
        return arrays[key]

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """The float32 observations the network sees: as VecNormalize's ``normalize_obs`` (the
        same float64 operations, then float32)."""
        if self._norm is None:
            return np.asarray(obs, dtype=np.float32)
        mean, std, clip = self._norm
        return np.clip((obs - mean) / std, -clip, clip).astype(np.float32)

    def outputs(self, obs: Any) -> np.ndarray:
        """The network's squashed output in float64 (N, action_dim) for the agent's raw
        observations ``obs`` (N, observation_dim): normalised, through the layers and (SAC)
        tanh, before the rounding to float32 of :meth:`actions`."""
        o = np.asarray(obs, dtype=np.float32)
        if o.ndim != 2 or o.shape[1] != self.obs_dim:
            raise ValueError(f"observations have shape {o.shape}, expected (N, {self.obs_dim})")
        x = self.normalize(o).astype(np.float64)
        for w, b, act in self._layers:
            x = _activate(linear(x, w, b), act)
        return tanh(x) if self._squash == "tanh" else x

    def actions(self, obs: Any) -> np.ndarray:
        """Deterministic actions (N, action_dim), float32 within the action bounds, for the
        agent's raw observations ``obs`` (N, observation_dim): :meth:`outputs` rounded to float32,
        then (SAC) stable-baselines3's unscaling ``low + 0.5 (a + 1) (high - low)`` in float32
        or (PPO) clipped to the bounds, as ``model.predict(normalize_obs(obs),
        deterministic=True)`` does. Each row depends on that row alone, whatever the batch."""
        a = self.outputs(obs).astype(np.float32)
        if self._squash == "tanh":
            return self._low + (np.float32(0.5) * (a + np.float32(1.0)) * (self._high - self._low))
        return np.clip(a, self._low, self._high)


class NetworkPolicy(AgentSideMethods):
    """A shipped policy evaluated from its exported network (:class:`Network`), without PyTorch or
    stable-baselines3: ``predict(obs) -> flap commands`` on the plain env, as
    :class:`accd_gym.evals.policies.SB3Policy` does with the stable-baselines3 model.

    ``path``: the policy's folder (``network.npz`` in it) or the file. ``config``: the env
    configuration (overrides) the policy runs on; with the env option ``residual`` its base
    controller is designed for it. The env options the network was trained with (residual,
    history; :attr:`agent_options`) are the file's: the policy keeps the base controller and the
    history per env, restarted by :meth:`reset`.
    """

    def __init__(self, path: str | Path, config: Optional[Any] = None) -> None:
        #: The exported network.
        self.network = Network(path)
        #: The policy's name (its path).
        self.name = str(path)
        #: The algorithm the network was trained with ("ppo" or "sac").
        self.algo = self.network.algo
        #: Nothing unusual about how the policy was found (the interface of SB3Policy's note).
        self.note: Optional[str] = None
        #: The env options the network was trained with (residual control, history).
        self.agent_options = split_agent_options(self.network.spec.get("env", {}))[0]
        expected = self.agent_options.observation_space().shape
        if expected != (self.network.obs_dim,):
            raise ConfigError(f"invalid config: network file {str(self.network.path)!r} observes "
                              f"({self.network.obs_dim},), its env options {self.agent_options.to_dict() or 'none'} "
                              f"give {expected}")
        self._config = physics_config(config)
        self._agent = PolicyAgentIO(self.agent_options, self._config)

    def predict(self, obs: Any) -> np.ndarray:
        """Deterministic flap commands (N, 4) for raw observations (N, 25) (with residual/history
        options: augmented, and the actions made commands, as the env did in training)."""
        o = np.asarray(obs, dtype=np.float32)
        if self.agent_options.enabled:
            o = self._agent.observation(o)
        actions = np.clip(self.network.actions(o), -1.0, 1.0)
        return self._agent.command(actions)
