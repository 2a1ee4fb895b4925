"""accd-gym: a fast, physically honest simulation of DLR's In-Air Capturing capture system.

The physics (Rust) follows Singh et al., "Multibody modelling of tether and capture system for
dynamic simulations of In-Air Capturing": a 3D chain of rigid tether segments with nonlinear bending
springs, joint damping, per-segment aerodynamics and one axial visco-elastic element, hung from the
towing aircraft, with the capturing device at its tip.

Frames and units: SI; the towing-aircraft (TA) frame has its origin at the tether attachment,
x forward, y to starboard, z down.

Public API:

* :class:`CaptureSim` -- one capture episode's physics (tether, 6-DoF capturing device, towing
  aircraft, RLV boom) for scripted runs; :func:`mix_flaps` turns pitch/yaw/roll into flaps.
* :class:`Tether` -- the tether model alone, for design studies and validation.
* :func:`tether_config` -- validated tether configurations from the paper's presets.
* :func:`towed_tether`, :func:`stand_in_body` -- the towed reference case (a stand-in capturing
  device at the tip, 185 m/s, 6000 m).
* :func:`isa` -- the International Standard Atmosphere.
* :class:`AccdError` and its subclasses :class:`ConfigError`, :class:`StateError`,
  :class:`SimulationError`.
"""

from accd_gym._core import (
    CaptureSim,
    Tether,
    __version__,
    default_aero_table_json,
    isa,
    mix_flaps,
    stand_in_body,
    tether_config,
    towed_tether,
)
from accd_gym.errors import AccdError, ConfigError, SimulationError, StateError

__all__ = [
    "AccdError",
    "CaptureSim",
    "ConfigError",
    "SimulationError",
    "StateError",
    "Tether",
    "__version__",
    "default_aero_table_json",
    "isa",
    "mix_flaps",
    "stand_in_body",
    "tether_config",
    "towed_tether",
]
