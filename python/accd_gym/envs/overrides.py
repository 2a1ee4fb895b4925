"""Named configuration overrides and how they merge: the exact air scheme, the sensors setting
and the benchmark tiers' declarations (:data:`TIERS`; their ids are registered and documented by
:mod:`accd_gym.envs.tiers`).

Plain data below :mod:`accd_gym.envs.config`, which resolves a ``tier`` key with :func:`tier` and
:func:`merge`.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any, Mapping

from accd_gym.errors import ConfigError


#: The exact air scheme, the default before the fast one (docs/decisions.md, "The fast air scheme is the default; the exact scheme stays"):
#: the segments sample the wake and its turbulence at every RK4 stage, Box-Muller normals, one
#: stream for every turbulence lane. Pass it to reproduce results of the first releases bit for
#: bit, e.g. ``InAirCaptureEnv(**EXACT_AIR_SCHEME)`` (merge your own ``wake``/``turbulence``
#: keys into its dicts). It is about 2x slower per physics step.
EXACT_AIR_SCHEME: dict[str, Any] = {
    "wake": {"sampling": "per_stage"},
    "turbulence": {"normal_sampler": "box_muller", "lane_streams": "shared"},
}


#: The recommended "sensors" benchmark setting: the sensor model on with the defaults
#: of its declarations (a 20 Hz vision sensor with 2 cm + 1e-3 r^2 range and 1 mrad bearing
#: noise; an uncalibrated MEMS IMU/AHRS; relative GNSS at 5 cm; a 100 N load cell), a vision
#: latency of 60 ms and 10 % of the vision measurements lost in bursts of 5 (0.25 s) on average,
#: no whole-vector delay. Pass it as the ``sensors`` key: ``InAirCaptureEnv(sensors=SENSORS_TIER)``
#: or ``--env '{"sensors": {...}}'``. On 100 held-out episodes the tuned guidance controller
#: captures 41 (100 without sensors) and zero flaps 17 (docs/environment.md, "Sensors"). It
#: registers no id.
SENSORS_TIER: dict[str, Any] = {
    "enabled": True,
    "vision": {"latency": 0.06, "dropout": 0.1, "dropout_burst": 5.0},
}


class EnvId(str):
    """A gymnasium id this package registers: a ``str``, equal to and hashing as the plain id,
    that pickles as a call of this class. Unpickling it therefore imports ``accd_gym``, which
    registers the ids: a subprocess started with ``spawn`` or ``forkserver`` (SB3's
    ``SubprocVecEnv`` and gymnasium's ``AsyncVectorEnv`` on macOS and Windows, SB3's default
    ``forkserver`` on Linux) that receives the id in a pickled env factory can make the env
    although it never imported ``accd_gym``. A plain string id there raises gymnasium's
    ``NamespaceNotFound`` in the child; the module-qualified id
    ``"accd_gym:accd_gym/InAirCapture-v0"`` works everywhere."""

    __slots__ = ()

    def __reduce__(self) -> tuple[type, tuple[str]]:
        return (EnvId, (str(self),))


@dataclass(frozen=True)
class Tier:
    """One benchmark tier: its gymnasium id, what it stands for, and its configuration overrides
    on the nominal task (sections as dicts, merged with the defaults like any keyword argument)."""

    name: str
    #: The registered id (an :class:`EnvId`: a ``str`` whose pickle imports ``accd_gym``).
    id: str
    summary: str
    overrides: Mapping[str, Any] = field(default_factory=dict)

    def config(self, **overrides: Any) -> dict[str, Any]:
        """The tier's overrides with ``overrides`` merged in section by section (a copy)."""
        return merge(self.overrides, overrides)


def merge(base: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``overrides`` merged in: a dict value merges into the base's dict at that
    key (recursively), anything else replaces it. Copies; neither argument is changed."""
    out = copy.deepcopy(dict(base))
    for key, value in overrides.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


#: The sensor suite of the sensors and hard tiers (``sensors`` section, docs/environment.md): the
#: recommended suite :data:`SENSORS_TIER` (60 ms vision latency, 10 % dropouts).
SENSORS: dict[str, Any] = copy.deepcopy(SENSORS_TIER)

#: Formation uncertainty of the sensors, randomized and hard tiers: the boom's initial formation
#: offset spread over +-8 m laterally and vertically (nominal +-3 m), so that a passive ACCD is met
#: by the drifting boom less often (zero flaps on 200 training episodes of the randomized tier:
#: 15 % at +-3 m, 10.5 % at +-6 m, 8 % at +-8 m; the tuned guidance controller 100 % at each).
_FORMATION: dict[str, Any] = {"boom": {"initial_spread": [2.0, 8.0, 8.0]}}

#: The precision scenario's soft capture: a 0.3 m radius, at most 1 m/s closing speed.
_SOFT_CAPTURE: dict[str, Any] = {"boom": {"capture_radius": 0.3, "max_closing_speed": 1.0}}
#: The precision scenario (docs/decisions.md, "The precision scenario is where policies separate"): the soft capture in severe ambient turbulence.
_PRECISION: dict[str, Any] = merge({"turbulence": {"ambient": "severe"}}, _SOFT_CAPTURE)

#: Randomized physics at the documented default ranges (crates/sim/src/task/randomization.rs), written
#: out so that a change of the code's defaults cannot change the tier.
_RANDOMIZATION: dict[str, Any] = {
    "enabled": True,
    "tether_length": [150.0, 300.0],
    "tether_diameter": [0.016, 0.032],
    "accd_mass": [40.0, 60.0],
    "force_coefficient_scale": [0.85, 1.15],
    "moment_coefficient_scale": [0.8, 1.2],
    "wake_alpha_deg": [0.0, 8.0],
    "wake_strength": [0.7, 1.3],
    "airspeed": [170.0, 200.0],
    "ambient_sigma_mps": [0.0, 2.8],
}
_RANDOMIZED: dict[str, Any] = merge({"randomization": _RANDOMIZATION}, _FORMATION)

TIERS: dict[str, Tier] = {
    t.name: t
    for t in (
        Tier(
            "nominal",
            EnvId("accd_gym/InAirCapture-v0"),
            "the mission's nominal case: 8 deg wake with its turbulence, perfect full-state "
            "observations, the paper's tether and ACCD",
        ),
        Tier(
            "precision",
            EnvId("accd_gym/InAirCapturePrecision-v0"),
            "a soft capture in severe turbulence: MIL-F-8785C severe ambient turbulence (7 m/s), "
            "a 0.3 m capture radius and a 1 m/s closing-speed limit",
            _PRECISION,
        ),
        Tier(
            "sensors",
            EnvId("accd_gym/InAirCaptureSensors-v0"),
            "the nominal physics seen through sensors: a vision sensor for the boom (range-"
            "dependent noise, 20 Hz, 60 ms latency, 10 % dropouts in bursts), IMU/AHRS noise and "
            "bias, GNSS and load-cell noise; the formation uncertain by +-8 m",
            merge({"sensors": SENSORS}, _FORMATION),
        ),
        Tier(
            "randomized",
            EnvId("accd_gym/InAirCaptureRandomized-v0"),
            "randomized physics per episode from its wake seed: tether length and diameter, ACCD "
            "mass and aerodynamics, wake angle and strength, towing speed, ambient turbulence; the "
            "formation uncertain by +-8 m",
            _RANDOMIZED,
        ),
        Tier(
            "hard",
            EnvId("accd_gym/InAirCaptureHard-v0"),
            "everything at once: the precision scenario's soft capture, sensors, randomized "
            "physics with light to severe ambient turbulence",
            merge(
                merge(_SOFT_CAPTURE, _RANDOMIZED),
                {"sensors": SENSORS, "randomization": {"ambient_sigma_mps": [1.7, 7.0]}},
            ),
        ),
    )
}


def tier(name: str) -> Tier:
    """The tier ``name`` (one of :data:`TIERS`); ConfigError naming the tiers otherwise."""
    if not isinstance(name, str) or name not in TIERS:
        raise ConfigError(f"invalid config: `tier` = {name!r} is outside the allowed values: one of {', '.join(TIERS)}")
    return TIERS[name]


__all__ = ["EnvId", "EXACT_AIR_SCHEME", "SENSORS_TIER", "SENSORS", "Tier", "TIERS", "merge", "tier"]
