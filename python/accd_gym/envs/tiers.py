"""The benchmark's task tiers: registered gymnasium ids, each a named set of configuration
overrides on the nominal task, declared once in :data:`TIERS` (:mod:`accd_gym.envs.overrides`).

{TIER_TABLES}

Use a tier by id (``gymnasium.make("accd_gym/InAirCaptureHard-v0")``,
``gymnasium.make_vec("accd_gym/InAirCaptureHard-v0", num_envs=16)``), by name on any env class
(``InAirCaptureVectorEnv(16, tier="hard")``, ``AccdVecEnv(16, tier="hard")``) or on the command
line (``accd-gym train|evaluate|rollout|replay --tier hard``). Keyword overrides are merged into
the tier's, section by section (``tier="hard", boom={"capture_radius": 0.5}`` keeps the tier's
closing-speed limit). Versions follow Gymnasium's rule from the first release on: any change to a
tier's definition that changes its episodes gets a new version (``-v1``); the old one stays
registered as it was. Until that release the ``-v0`` ids follow the code (the changes of their
episodes are recorded in docs/decisions.md).
"""

from __future__ import annotations

from typing import Any, Mapping, Optional

from accd_gym import _core
from accd_gym.envs.config import default_config, env_config
from accd_gym.envs.overrides import SENSORS, TIERS, EnvId, Tier, merge, tier
from accd_gym.envs.task import episode_steps


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
            entry_point="accd_gym.envs.env:InAirCaptureEnv",
            vector_entry_point="accd_gym.envs.vector:InAirCaptureVectorEnv",
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
