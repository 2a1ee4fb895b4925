"""What the agent sees and sends beside the physics: residual control and observation history.

Two env options taken by every env class (``InAirCaptureEnv``, ``InAirCaptureVectorEnv``,
``AccdVecEnv``, ``gymnasium.make``/``make_vec`` of any registered id) beside the configuration
keys, and by the wrapper :class:`AgentInterface` around a single env:

* ``residual`` (:mod:`accd_gym.envs.residual`): the flap command sent is a base controller's command
  plus the agent's bounded correction, ``clip(u_base + scale * clip(a, -1, 1), -1, 1)``;
  e.g. ``residual={"base": "lqr", "scale": 0.3}``.
* ``history`` (:mod:`accd_gym.envs.history`): ``history=k`` appends the last ``k`` observations and
  flap commands sent.
* ``true_observation``: ``True`` adds the true observation to ``info["true_obs"]``: the 25 values
  perfect sensors would give (noise-free, delay-free; scaled like the observation), for teachers
  and critics that may see the true state. It equals the observation without ``sensors.enabled``.
  The agent's observation does not change; off, nothing of it is computed.

All are off by default, and then the envs are exactly the plain task. They are not part of
the physics configuration (``env.config``); the envs keep them in :attr:`agent_options`, pickles
and ``get_state()`` carry them and their state (the base controller's filter, the history).
In a training config they go into ``env`` beside the configuration keys
(``"env": {"tier": "hard", "residual": {"base": "lqr", "scale": 0.3}, "history": 4}``).

{AGENT_IO_TABLES}
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from typing import Any, Mapping, Optional

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from accd_gym.errors import ConfigError, StateError
from accd_gym.envs.history import HISTORY_MAX, HistoryBuffer, parse_history
from accd_gym.envs.residual import SCALE_MAX, ResidualOptions, base_controller
from accd_gym.envs.task import ACT_DIM, OBS_BOUND, OBS_DIM, OBSERVATION_TABLE, check_actions

#: The env arguments of this module (never configuration keys).
AGENT_KEYS = ("residual", "history", "true_observation")


@dataclass(frozen=True)
class AgentOptions:
    """The ``residual``, ``history`` and ``true_observation`` env options, validated."""

    residual: Optional[ResidualOptions] = None
    history: int = 0
    true_observation: bool = False

    @classmethod
    def parse(cls, residual: Any = None, history: Any = None, true_observation: Any = None) -> "AgentOptions":
        """From the env arguments (ConfigError naming the field, the value and the range)."""
        return cls(ResidualOptions.parse(residual), parse_history(history), parse_true_observation(true_observation))

    @property
    def enabled(self) -> bool:
        """Whether residual control or history is on (what :class:`AgentIO` keeps state for;
        ``true_observation`` only adds an info key)."""
        return self.residual is not None or self.history > 0

    def to_dict(self) -> dict[str, Any]:
        """The options as env arguments (JSON values; only those that are on)."""
        out: dict[str, Any] = {}
        if self.residual is not None:
            out["residual"] = self.residual.to_dict()
        if self.history:
            out["history"] = self.history
        if self.true_observation:
            out["true_observation"] = True
        return out

    def observation_names(self) -> list[str]:
        """The name of every observation entry the agent gets (see :func:`layout_markdown`)."""
        names = [name for name, *_ in OBSERVATION_TABLE]
        flaps = ("right", "left", "top", "bottom")
        out = list(names)
        if self.residual is not None and self.residual.observe_base:
            out += [f"base_{f}" for f in flaps]
        for j in range(1, self.history + 1):
            out += [f"{n}[t-{j}]" for n in names]
        for j in range(1, self.history + 1):
            out += [f"command_{f}[t-{j}]" for f in flaps]
        return out

    def observation_space(self) -> spaces.Box:
        """The observation space of one env: float32, bounds per entry (``OBS_BOUND`` for
        observations, 1 for commands)."""
        parts = [np.full(OBS_DIM, OBS_BOUND, dtype=np.float32)]
        if self.residual is not None and self.residual.observe_base:
            parts.append(np.ones(ACT_DIM, dtype=np.float32))
        if self.history:
            parts.append(np.full(self.history * OBS_DIM, OBS_BOUND, dtype=np.float32))
            parts.append(np.ones(self.history * ACT_DIM, dtype=np.float32))
        high = np.concatenate(parts)
        return spaces.Box(-high, high, dtype=np.float32)


def parse_true_observation(value: Any) -> bool:
    """The ``true_observation`` option: None or a bool (ConfigError naming the value otherwise)."""
    if value is None:
        return False
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"invalid config: `true_observation` = {value!r} is outside the allowed range true or false")
    return bool(value)


def split_agent_options(config: Mapping[str, Any]) -> tuple[AgentOptions, dict[str, Any]]:
    """``(AgentOptions, the rest)`` of env keyword arguments: the agent options validated, the
    rest (the configuration keys) left as they are."""
    rest = dict(config)
    values = {k: rest.pop(k) for k in AGENT_KEYS if k in rest}
    return AgentOptions.parse(**values), rest


class AgentIO:
    """Residual control and observation history of a batch of ``num_envs`` envs.

    The env calls :meth:`begin` when episodes start (reset), :meth:`command` with the agent's
    actions before a step (returns the flap commands to send) and :meth:`advance` with the
    step's observations (returns the agent's). Every method returns new arrays. ``core``: the
    env's Rust batch (``_core.BatchEnv``), which then steps an LQR or MPC base controller per
    env in its own threads (:class:`~accd_gym.envs.residual.BatchBaseController`); without it
    (a policy's side) the base controller steps on the calling thread.
    """

    def __init__(self, options: AgentOptions, config: Mapping[str, Any], num_envs: int, core: Any = None) -> None:
        self.options = options
        self.num_envs = int(num_envs)
        r = options.residual
        self._base = base_controller(r, config, core) if r is not None else None
        self._scale = np.float32(r.scale) if r is not None else None
        self._observe_base = r is not None and r.observe_base
        self._history = HistoryBuffer(self.num_envs, options.history, OBS_DIM, ACT_DIM) if options.history else None
        self._cur = np.zeros((self.num_envs, OBS_DIM), dtype=np.float32)
        self._base_u = np.zeros((self.num_envs, ACT_DIM), dtype=np.float32)
        self._sent = np.zeros((self.num_envs, ACT_DIM), dtype=np.float32)
        self._corrected = False
        self.observation_space = options.observation_space()

    @classmethod
    def create(cls, options: AgentOptions, config: Mapping[str, Any], num_envs: int,
               core: Any = None) -> "Optional[AgentIO]":
        """An AgentIO (``core`` as for the constructor), or None when neither option is on."""
        return cls(options, config, num_envs, core) if options.enabled else None

    def _observation(self, cur: np.ndarray, base_u: np.ndarray) -> np.ndarray:
        parts = [cur]
        if self._observe_base:
            parts.append(base_u)
        if self._history is not None:
            parts.extend(self._history.flat())
        return np.concatenate(parts, axis=1) if len(parts) > 1 else cur.copy()

    def begin(self, obs: np.ndarray, rows: Optional[np.ndarray] = None) -> np.ndarray:
        """Episodes start in the rows ``rows`` selects (all when None) with the observations
        ``obs`` (every row's); returns every row's agent observation."""
        if rows is None or rows.all():
            self._cur[:] = obs
            if self._history is not None:
                self._history.fill(self._cur)
            if self._base is not None:
                self._base.restart(None)
                self._base_u = self._base.command(self._cur)
        else:
            self._cur[rows] = obs[rows]
            if self._history is not None:
                self._history.fill(self._cur, rows)
            if self._base is not None:
                self._base.restart(rows)
                u = self._base.command_rows(self._cur, rows)
                self._base_u[rows] = u[rows]
        return self._observation(self._cur, self._base_u)

    def command(self, actions: np.ndarray) -> np.ndarray:
        """The flap commands to send for the agent's ``actions`` ((N, 4) float32, checked): with
        residual control ``clip(u_base + scale * clip(a, -1, 1), -1, 1)``, else the actions."""
        if self._base is None:
            self._sent = np.clip(actions, -1.0, 1.0)
            return actions
        correction = np.clip(actions, -1.0, 1.0) * self._scale
        self._corrected = bool(np.count_nonzero(correction))
        self._sent = np.clip(self._base_u + correction, -1.0, 1.0) if self._corrected else self._base_u
        return self._sent

    def sent(self, offset: np.ndarray) -> None:
        """The commands actually sent differ from :meth:`command`'s by ``offset`` ((N, 4),
        flap-limit units; e.g. a teacher whose student flew): the base controller's filter and the
        history take the commands sent at the next :meth:`advance`. A zero offset changes
        nothing, bit for bit."""
        offset = np.asarray(offset, dtype=np.float64)
        if offset.shape != self._sent.shape:
            raise ValueError(f"offset has shape {offset.shape}, expected {self._sent.shape}")
        if not np.count_nonzero(offset):
            return
        self._sent = np.clip(self._sent.astype(np.float64) + offset, -1.0, 1.0).astype(np.float32)
        if self._base is not None:
            self._corrected = True

    def advance(
        self,
        obs: np.ndarray,
        started: Optional[np.ndarray] = None,
        final_obs: Optional[np.ndarray] = None,
        ended: Optional[np.ndarray] = None,
    ) -> tuple[np.ndarray, Optional[np.ndarray]]:
        """After a step with :meth:`command`'s commands: ``obs`` every row's observation,
        ``started`` the rows whose ``obs`` starts a new episode (an automatic reset), ``ended``
        and ``final_obs`` (same-step autoreset) the rows whose episode ended in this step and
        their last observations. Returns the agent observations of every row and, with
        ``ended``, those of the ended episodes' last observations (rows ``ended`` selects)."""
        if self._base is not None and self._corrected and self._base.needs_sent:
            # (without a correction the base command was sent; a batch-run base is told by the batch)
            self._base.sent(self._sent.astype(np.float64) - self._base_u.astype(np.float64))
        if self._history is not None:
            self._history.push(self._cur, self._sent)
        finals = None
        if ended is not None and np.count_nonzero(ended):
            last = np.array(obs, dtype=np.float32, copy=True)
            last[ended] = final_obs[ended]
            u_last = self._base.peek(last) if self._observe_base else self._base_u
            finals = self._observation(last, u_last)
        self._cur[:] = obs
        if started is not None and np.count_nonzero(started):
            if self._history is not None:
                self._history.fill(self._cur, started)
            if self._base is not None:
                self._base.restart(started)
        if self._base is not None:
            self._base_u = self._base.command(self._cur)
        return self._observation(self._cur, self._base_u), finals

    # -- state ----------------------------------------------------------------------------

    def get_state(self) -> dict[str, np.ndarray]:
        """Every array of the batch's agent state (copies)."""
        out = {"cur": self._cur.copy(), "base_u": self._base_u.copy(), "sent": self._sent.copy()}
        if self._history is not None:
            out.update({f"history_{k}": v for k, v in self._history.get_state().items()})
        if self._base is not None:
            out.update({f"ctrl_{k}": v for k, v in self._base.get_state().items()})
        return out

    def check_state(self, state: Mapping[str, np.ndarray]) -> None:
        """StateError naming the first array of ``state`` (:meth:`get_state`'s) that does not fit
        this batch (another batch size, history length or base controller)."""
        n = self.num_envs
        expected = {"cur": (n, OBS_DIM), "base_u": (n, ACT_DIM), "sent": (n, ACT_DIM)}
        if self._history is not None:
            k = self._history.k
            expected.update(history_obs=(n, k, OBS_DIM), history_act=(n, k, ACT_DIM))
        if self._base is not None:
            current = self._base.get_state()
            for key, value in state.items():
                if key.startswith("ctrl_"):
                    name = key[5:]
                    expected[key] = current[name].shape if name in current else (n,) + np.shape(value)[1:]
        unexpected = set(state) - set(expected)
        if unexpected:
            raise StateError(f"agent state has arrays {sorted(unexpected)} this env does not keep")
        for key, shape in expected.items():
            if key not in state and key.startswith("ctrl_"):
                continue
            if key not in state or np.shape(state[key]) != shape:
                got = None if key not in state else np.shape(state[key])
                raise StateError(f"agent state `{key}` has shape {got}, expected {shape} (another batch size, "
                                 "history or base controller)")

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restores :meth:`get_state`'s arrays (checked first: StateError, nothing changed)."""
        self.check_state(state)
        base = {k[5:]: np.asarray(v) for k, v in state.items() if k.startswith("ctrl_")}
        self._base_u = np.array(state["base_u"], dtype=np.float32)
        if self._base is not None:
            self._base.set_state(base, self._base_u)
        self._cur[:] = state["cur"]
        self._sent = np.array(state["sent"], dtype=np.float32)
        if self._history is not None:
            self._history.set_state({"obs": state["history_obs"], "act": state["history_act"]})

    def pack_state(self, core_state: bytes) -> bytes:
        """An env state with this agent state: ``AGENT_STATE_MAGIC``, then an ``.npz`` archive
        (no pickles) of the core's state, the options and the arrays."""
        arrays = {f"agent_{k}": v for k, v in self.get_state().items()}
        buf = io.BytesIO()
        np.savez(buf, core=np.frombuffer(core_state, dtype=np.uint8),
                 options=np.frombuffer(json.dumps(self.options.to_dict(), sort_keys=True).encode(), dtype=np.uint8),
                 **arrays)
        return AGENT_STATE_MAGIC + buf.getvalue()

    def unpack_state(self, state: bytes) -> tuple[bytes, dict[str, np.ndarray]]:
        """``(core state, agent arrays)`` of :meth:`pack_state`'s bytes; StateError naming what is
        wrong (not such a state, other options)."""
        if not state.startswith(AGENT_STATE_MAGIC):
            raise StateError(f"not a state of an env with agent options {self.options.to_dict()} (it lacks their "
                             "state; it may be a plain env's)")
        try:
            with np.load(io.BytesIO(state[len(AGENT_STATE_MAGIC):]), allow_pickle=False) as z:
                doc = {k: z[k] for k in z.files}
            options = json.loads(doc.pop("options").tobytes().decode())
        except Exception as e:  # a truncated or corrupted archive
            raise StateError(f"corrupted agent state ({type(e).__name__}: {e})") from None
        if options != json.loads(json.dumps(self.options.to_dict(), sort_keys=True)):
            raise StateError(f"a state of an env with agent options {options}, this env has {self.options.to_dict()}")
        core = doc.pop("core").tobytes()
        arrays = {k[6:]: v for k, v in doc.items() if k.startswith("agent_")}
        self.check_state(arrays)
        return core, arrays


#: The first bytes of the state of an env with agent options (:meth:`AgentIO.pack_state`).
AGENT_STATE_MAGIC = b"ACCDAGIO"



class PolicyAgentIO:
    """The env options on a policy's side: a policy trained with ``residual``/``history`` runs on
    the plain env by keeping, per env, what the env kept in training (the base controller, the
    history). One :class:`AgentIO` per batch size; a new batch size starts every env afresh.
    Shared by the policies that run trained networks (stable-baselines3 models, exported
    networks)."""

    def __init__(self, options: AgentOptions, config: Mapping[str, Any]) -> None:
        self.options = options
        self._config = config
        self._io: Optional[AgentIO] = None
        self._started: Optional[np.ndarray] = None

    def observation(self, obs: np.ndarray) -> np.ndarray:
        """The observations the network was trained on for raw observations ``obs`` (N, 25),
        advancing the per-env state."""
        if obs.ndim != 2:
            raise ValueError(f"observations have shape {obs.shape}, expected (N, 25)")
        if self._io is None or self._io.num_envs != obs.shape[0]:
            self._io = AgentIO(self.options, self._config, obs.shape[0])
            self._started = None
            return self._io.begin(obs)
        started, self._started = self._started, None
        return self._io.advance(obs, started)[0]

    def command(self, actions: np.ndarray) -> np.ndarray:
        """The flap commands for the network's ``actions`` (unchanged without residual control)."""
        return actions if self._io is None else self._io.command(actions)

    def sent(self, offset: np.ndarray) -> None:
        """The commands actually sent differ from the last :meth:`command`'s by ``offset``
        ((N, 4)): the base controller and the history continue with the commands sent
        (:meth:`AgentIO.sent`; nothing before the first observation)."""
        if self._io is not None:
            self._io.sent(offset)

    def reset(self, mask: Optional[np.ndarray] = None) -> None:
        """The envs ``mask`` selects (all when None) start new episodes: their base controller and
        history restart at the next :meth:`observation`."""
        if self._io is None:
            return
        rows = np.ones(self._io.num_envs, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        if rows.shape != (self._io.num_envs,):
            self._io = None  # another batch: every env starts afresh
            return
        self._started = rows if self._started is None else (self._started | rows)

    def get_state(self) -> dict[str, np.ndarray]:
        """The per-env state (:meth:`AgentIO.get_state`), empty before the first observation."""
        return {} if self._io is None else self._io.get_state()

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restores a state of :meth:`get_state` (of a batch of the same size)."""
        if not state:
            self._io = None
            self._started = None
            return
        n = int(np.shape(state["cur"])[0])
        if self._io is None or self._io.num_envs != n:
            self._io = AgentIO(self.options, self._config, n)
        self._io.set_state(state)
        self._started = None


class AgentSideMethods:
    """The per-env methods of a policy that runs a trained network through a
    :class:`PolicyAgentIO` kept in ``self._agent`` (stable-baselines3 models, exported networks):
    episode restarts, the commands actually sent, and the state, all delegated to it."""

    _agent: PolicyAgentIO

    def reset(self, mask: Optional[np.ndarray] = None) -> None:
        """The envs ``mask`` selects (all when None) start new episodes: their base controller and
        history restart at the next ``predict`` (nothing to do without env options)."""
        self._agent.reset(mask)

    def sent(self, offset: np.ndarray) -> None:
        """The commands actually sent differ from the last ``predict``'s by ``offset`` ((N, 4)):
        a network trained with residual/history options continues with the commands sent (its
        base controller's filter, its history), as a teacher whose student flew must; nothing to
        do without env options."""
        self._agent.sent(offset)

    def get_state(self) -> dict[str, np.ndarray]:
        """The per-env agent state (the base controller, the history;
        :meth:`AgentIO.get_state`), empty without env options or before the first ``predict``."""
        return self._agent.get_state()

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restores a state of :meth:`get_state` (of a batch of the same size)."""
        self._agent.set_state(state)


class AgentInterface(gym.Wrapper):
    """Residual control and observation history around a single env (``InAirCaptureEnv``, or
    ``gymnasium.make`` of a registered id): the same as passing ``residual``/``history`` to the
    env itself, bit for bit. ``AgentInterface(env, residual={"base": "lqr", "scale": 0.3},
    history=4)``; the base controller is designed for ``env.unwrapped.config``."""

    def __init__(self, env: gym.Env, residual: Any = None, history: Any = None) -> None:
        super().__init__(env)
        self.agent_options = AgentOptions.parse(residual, history)
        self._io = AgentIO(self.agent_options, env.unwrapped.config, 1)
        self.observation_space = self._io.observation_space

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict[str, Any]] = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Resets the env and starts the agent state afresh."""
        obs, info = self.env.reset(seed=seed, options=options)
        return self._io.begin(np.asarray(obs, dtype=np.float32)[None])[0], info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One step with the command :meth:`AgentIO.command` makes of ``action``."""
        sent = self._io.command(check_actions(action, 1, single=True))
        obs, reward, terminated, truncated, info = self.env.step(sent[0])
        out, _ = self._io.advance(np.asarray(obs, dtype=np.float32)[None])
        return out[0], reward, terminated, truncated, info


def layout_markdown() -> str:
    """The agent observation's layout as a markdown table (what the env options append to the
    observation table's 25 entries, in order)."""
    rows = [
        "| entries | count | present | unit / scale | description |",
        "|---|---|---|---|---|",
        f"| observation table, indices 0-{OBS_DIM - 1} | {OBS_DIM} | always | as the table | the current observation |",
        f"| `base_right`, `base_left`, `base_top`, `base_bottom` | {ACT_DIM} | `residual` with `observe_base` "
        "(default) | flap-limit units, [-1, 1] | the base controller's command for the current observation, to "
        "which the action's correction is added |",
        f"| observation table at `t-1`, ..., `t-k` | {OBS_DIM} k | `history=k` | as the table | the past observations, "
        "newest first; at an episode's start all equal to its first observation |",
        f"| `command_*` at `t-1`, ..., `t-k` | {ACT_DIM} k | `history=k` | flap-limit units, [-1, 1] | the flap "
        "commands sent (right, left, top, bottom; with `residual` base plus correction), newest first; zero at "
        "an episode's start |",
    ]
    return "\n".join(rows)


def options_markdown() -> str:
    """The env options as a markdown table (argument, default, range, meaning)."""
    rows = [
        "| argument | default | range | description |",
        "|---|---|---|---|",
        "| `residual` | `None` | None, a base name, or a dict of the keys below | residual control: the flap command sent "
        "is `clip(u_base + scale * clip(a, -1, 1), -1, 1)`; a zero action reproduces the base controller's "
        "episodes bit for bit |",
        "| `residual.base` | `'lqr'` | `'lqr'`, `'guidance'`, `'mpc'` | the base controller: the LQR with its Kalman "
        "filter designed for the env's configuration, the tuned guidance controller, or the MPC on the LQR's filter; it reads the "
        "observations the agent gets, restarts with each episode and is told the command sent |",
        f"| `residual.scale` | `0.3` | (0, {SCALE_MAX:g}] | the bound of the correction, flap-limit units |",
        "| `residual.observe_base` | `True` | true, false | append the base command to the observation |",
        f"| `history` | `0` | [0, {HISTORY_MAX}] | append the last `k` observations and flap commands sent |",
        "| `true_observation` | `False` | true, false | add `info[\"true_obs\"]`: the 25 values perfect sensors "
        "would give (noise-free, delay-free), scaled like the observation; the observation itself without "
        "`sensors.enabled`; the agent's observation is unchanged |",
    ]
    return "\n".join(rows)


def agent_io_markdown() -> str:
    """The options table and the observation layout (:func:`options_markdown`,
    :func:`layout_markdown`): this module's docstring and docs/environment.md carry it."""
    return options_markdown() + "\n\nThe observation the agent gets, in order:\n\n" + layout_markdown()


__doc__ = (__doc__ or "").replace("{AGENT_IO_TABLES}", agent_io_markdown(), 1)


def physics_config(config: Optional[Any]) -> Any:
    """An env configuration without the env options of this module (``residual``, ``history``): what
    the physics takes. A trained policy carries its own options (see
    :class:`accd_gym.evals.policies.SB3Policy`); a validated ``EnvConfig`` holds none and is returned as it is."""
    from collections.abc import Mapping

    if config is not None and not isinstance(config, Mapping):
        return config  # a validated EnvConfig holds no env options
    return split_agent_options(dict(config or {}))[1]


__all__ = ["AGENT_KEYS", "AGENT_STATE_MAGIC", "AgentIO", "AgentInterface", "AgentOptions", "agent_io_markdown",
           "layout_markdown", "options_markdown", "parse_true_observation", "physics_config",
           "split_agent_options"]
