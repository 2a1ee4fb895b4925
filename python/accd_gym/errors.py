"""The exception tree of accd-gym. Every error this package raises derives from :class:`AccdError`.

::

    AccdError
     +-- ConfigError (also ValueError)      invalid configuration: names the field, value, range
     +-- StateError (also ValueError)       invalid state or array argument (shape, non-finite),
                                            or a saved state that cannot be restored
     +-- SimulationError (also RuntimeError) the simulation diverged
     +-- OutputError (also OSError)         a file could not be written (full disk, read-only
                                            folder); the previous file is left as it was
"""


class AccdError(Exception):
    """Base class of every error raised by accd-gym."""


class ConfigError(AccdError, ValueError):
    """An invalid configuration: the message names the field, the value and the allowed range."""


class StateError(AccdError, ValueError):
    """An invalid state or array argument: wrong shape, non-finite values, a singular direction;
    or a saved state (``get_state`` bytes) that cannot be restored: corrupted, truncated, of
    another env class, configuration or number of envs, or of an older state format."""


class SimulationError(AccdError, RuntimeError):
    """The simulation diverged (non-finite state, a folded joint, a coordinate singularity)."""


class OutputError(AccdError, OSError):
    """A file could not be written (a full disk, a read-only folder, ...). The message names the
    file and the reason; the write was atomic (:mod:`accd_gym.files`), so the previous version of
    the file, if any, is left as it was. ``errno`` and ``filename`` are those of the failure."""

    def __init__(self, message: str, errno: int | None = None, filename: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.errno = errno
        self.filename = filename
        self.strerror = message

    def __str__(self) -> str:
        return self.message


__all__ = ["AccdError", "ConfigError", "StateError", "SimulationError", "OutputError"]
