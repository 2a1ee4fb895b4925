"""The benchmark's task tiers: registered gymnasium ids, each a named set of configuration
overrides on the nominal task, declared once in :data:`TIERS`.

{TIER_TABLES}

Use a tier by id (``gymnasium.make("accd_gym/InAirCaptureHard-v0")``,
``gymnasium.make_vec("accd_gym/InAirCaptureHard-v0", num_envs=16)``), by name on any env class
(``InAirCaptureVectorEnv(16, tier="hard")``, ``AccdVecEnv(16, tier="hard")``) or on the command
line (``accd-gym train|evaluate|rollout|replay --tier hard``). Keyword overrides are merged into
the tier's, section by section (``tier="hard", boom={"capture_radius": 0.5}`` keeps the tier's
closing-speed limit). Versions follow Gymnasium's rule: any change to a tier's definition that
changes its episodes gets a new version (``-v1``); the old one stays registered as it was.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any, Mapping, Optional

from accd_gym.config import SENSORS_TIER
from accd_gym.errors import ConfigError


@dataclass(frozen=True)
class Tier:
    """One benchmark tier: its gymnasium id, what it stands for, and its configuration overrides
    on the nominal task (sections as dicts, merged with the defaults like any keyword argument)."""

    name: str
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
#: recommended suite :data:`accd_gym.config.SENSORS_TIER` (60 ms vision latency, 10 % dropouts).
SENSORS: dict[str, Any] = copy.deepcopy(SENSORS_TIER)

#: Formation uncertainty of the sensors, randomized and hard tiers: the boom's initial formation
#: offset spread over +-8 m laterally and vertically (nominal +-3 m), so that a passive ACCD is met
#: by the drifting boom less often (zero flaps on 200 training episodes of the randomized tier:
#: 15 % at +-3 m, 10.5 % at +-6 m, 8 % at +-8 m; the tuned guidance controller 100 % at each).
_FORMATION: dict[str, Any] = {"boom": {"initial_spread": [2.0, 8.0, 8.0]}}

#: The precision scenario's soft capture: a 0.3 m radius, at most 1 m/s closing speed.
_SOFT_CAPTURE: dict[str, Any] = {"boom": {"capture_radius": 0.3, "max_closing_speed": 1.0}}
#: The precision scenario (design notes, item 14): the soft capture in severe ambient turbulence.
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
            "accd_gym/InAirCapture-v0",
            "the mission's nominal case: 8 deg wake with its turbulence, perfect full-state "
            "observations, the paper's tether and ACCD",
        ),
        Tier(
            "precision",
            "accd_gym/InAirCapturePrecision-v0",
            "a soft capture in severe turbulence: MIL-F-8785C severe ambient turbulence (7 m/s), "
            "a 0.3 m capture radius and a 1 m/s closing-speed limit",
            _PRECISION,
        ),
        Tier(
            "sensors",
            "accd_gym/InAirCaptureSensors-v0",
            "the nominal physics seen through sensors: a vision sensor for the boom (range-"
            "dependent noise, 20 Hz, 60 ms latency, 10 % dropouts in bursts), IMU/AHRS noise and "
            "bias, GNSS and load-cell noise; the formation uncertain by +-8 m",
            merge({"sensors": SENSORS}, _FORMATION),
        ),
        Tier(
            "randomized",
            "accd_gym/InAirCaptureRandomized-v0",
            "randomized physics per episode from its wake seed: tether length and diameter, ACCD "
            "mass and aerodynamics, wake angle and strength, towing speed, ambient turbulence; the "
            "formation uncertain by +-8 m",
            _RANDOMIZED,
        ),
        Tier(
            "hard",
            "accd_gym/InAirCaptureHard-v0",
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


def _flatten(d: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    rows: list[tuple[str, Any]] = []
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            rows.extend(_flatten(v, key + "."))
        else:
            rows.append((key, v))
    return rows


def differences(name: str) -> list[tuple[str, Any, Any, str, str]]:
    """What tier ``name`` sets differently from the nominal task: ``(dotted key, value, nominal
    default, unit, description)`` per key, from the tier's declaration and the Rust field
    declarations."""
    from accd_gym import _core
    from accd_gym.config import default_config

    fields = {key: (unit, description) for key, unit, _, description, _, _ in _core.config_fields()}
    defaults = default_config()
    rows = []
    for key, value in _flatten(tier(name).overrides):
        default: Any = defaults
        for part in key.split("."):
            default = default.get(part) if isinstance(default, Mapping) else None
        unit, description = fields.get(key, ("", ""))
        rows.append((key, value, default, unit, description))
    return rows


def tier_table_markdown(name: str) -> str:
    """Tier ``name`` as a markdown table of what differs from the nominal task (generated from
    :data:`TIERS` and the field declarations)."""
    t = tier(name)
    lines = [f"**{t.name}** (`{t.id}`, {_episode_steps(t)} agent steps): {t.summary}.", ""]
    rows = differences(name)
    if not rows:
        lines.append("Nothing differs: this is the nominal task (the defaults of every key).")
        return "\n".join(lines)
    lines += ["| key | tier | nominal | unit | description |", "|---|---|---|---|---|"]
    for key, value, default, unit, description in rows:
        text = description.replace("|", "\\|")
        lines.append(f"| `{key}` | `{value!r}` | `{default!r}` | {unit} | {text} |")
    return "\n".join(lines)


def tiers_markdown() -> str:
    """Every tier's table (:func:`tier_table_markdown`), one after the other: the module docstring
    and docs/environment.md carry it (tested)."""
    return "\n\n".join(tier_table_markdown(name) for name in TIERS)


def _episode_steps(t: Tier) -> int:
    from accd_gym.config import env_config
    from accd_gym.task import episode_steps

    return episode_steps(env_config(t.overrides))


def register_tiers() -> None:
    """Registers every tier's id with gymnasium (single and native vector entry points, the
    tier's ``max_episode_steps``); ids already registered are left alone."""
    import gymnasium as gym

    for t in TIERS.values():
        if t.id in gym.registry:
            continue
        gym.register(
            id=t.id,
            entry_point="accd_gym.env:InAirCaptureEnv",
            vector_entry_point="accd_gym.vector:InAirCaptureVectorEnv",
            max_episode_steps=_episode_steps(t),
            kwargs={} if t.name == "nominal" else {"tier": t.name},
        )


def with_tier_tables(doc: Optional[str]) -> Optional[str]:
    """``doc`` with its ``{TIER_TABLES}`` line replaced by :func:`tiers_markdown`."""
    if doc is None:
        return None
    return doc.replace("{TIER_TABLES}", tiers_markdown(), 1)


__doc__ = with_tier_tables(__doc__)

__all__ = ["Tier", "TIERS", "SENSORS", "tier", "merge", "differences", "tier_table_markdown", "tiers_markdown",
           "register_tiers"]
