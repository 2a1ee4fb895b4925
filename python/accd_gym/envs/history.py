"""Observation history: the last ``k`` observations and flap commands, appended to the observation.

An env option of every env class (``history=k``; see :mod:`accd_gym.envs.agent_io` for the layout).
Held per env in numpy ring buffers (:class:`HistoryBuffer`) that share one write position, so a
step writes one slot of the batch and never shifts. **Fill rule**: when an env's episode
starts, its ``k`` past observations are all that episode's first observation and its ``k`` past
commands are zero (the neutral flaps the episode starts from; the reward's smoothness term also
takes the previous command as zero at the start). The commands are the flap commands sent to
the env, clipped to [-1, 1] (with residual control: base command plus correction).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from accd_gym.errors import ConfigError

#: The largest ``history`` accepted.
HISTORY_MAX = 64


def parse_history(value: Any) -> int:
    """The ``history`` env option as an int in [0, HISTORY_MAX] (0: off; None: off); ConfigError
    naming the value and the allowed range otherwise."""
    if value is None:
        return 0
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not 0 <= int(value) <= HISTORY_MAX:
        raise ConfigError(f"invalid config: `history` = {value!r} is outside the allowed range: an integer in "
                          f"[0, {HISTORY_MAX}] (past observations and commands appended to the observation)")
    return int(value)


class HistoryBuffer:
    """The last ``k`` observations (N, k, obs_dim) and commands (N, k, act_dim) of ``N`` envs
    (float32), in ring buffers with one shared write position."""

    def __init__(self, num_envs: int, k: int, obs_dim: int, act_dim: int) -> None:
        self.k = int(k)
        self.obs = np.zeros((num_envs, self.k, obs_dim), dtype=np.float32)
        self.act = np.zeros((num_envs, self.k, act_dim), dtype=np.float32)
        self.head = 0  # the slot the next push writes
        self._order = self._newest_first()

    def _newest_first(self) -> np.ndarray:
        return (self.head - 1 - np.arange(self.k)) % self.k

    def fill(self, obs: np.ndarray, rows: "np.ndarray | None" = None) -> None:
        """Starts the history of the rows ``rows`` selects (all when None) by the fill rule: every
        past observation is the row's ``obs``, every past command zero."""
        if rows is None:
            self.obs[:] = obs[:, None, :]
            self.act[:] = 0.0
        else:
            self.obs[rows] = obs[rows][:, None, :]
            self.act[rows] = 0.0

    def push(self, obs: np.ndarray, act: np.ndarray) -> None:
        """Appends one step of every row: the observation it acted on and the command sent."""
        self.obs[:, self.head] = obs
        self.act[:, self.head] = act
        self.head = (self.head + 1) % self.k
        self._order = self._newest_first()

    def flat(self) -> tuple[np.ndarray, np.ndarray]:
        """The past observations and commands, newest first, each row flattened: (N, k obs_dim)
        and (N, k act_dim) (new arrays)."""
        n = self.obs.shape[0]
        return self.obs[:, self._order].reshape(n, -1), self.act[:, self._order].reshape(n, -1)

    def get_state(self) -> dict[str, np.ndarray]:
        """The buffers in age order (newest first), as arrays (copies)."""
        return {"obs": self.obs[:, self._order].copy(), "act": self.act[:, self._order].copy()}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restores :meth:`get_state`'s arrays (shapes checked by the caller)."""
        self.head = 0
        order = self._newest_first()  # head 0: slot k-1 newest, ..., slot 0 oldest
        self.obs[:, order] = state["obs"]
        self.act[:, order] = state["act"]
        self._order = order


__all__ = ["HISTORY_MAX", "HistoryBuffer", "parse_history"]
