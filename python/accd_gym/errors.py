"""The exception tree of accd-gym. Every error this package raises derives from :class:`AccdError`.

::

    AccdError
     +-- ConfigError (also ValueError)      invalid configuration: names the field, value, range
     +-- StateError (also ValueError)       invalid state or array argument (shape, non-finite),
                                            or a saved state that cannot be restored
     +-- SimulationError (also RuntimeError) the simulation diverged
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


__all__ = ["AccdError", "ConfigError", "StateError", "SimulationError"]
