"""The task's action, observation, reward and episode-end tables, declared once and rendered as
markdown for the env docstrings, ``docs/environment.md`` and ``README.md``.

The observation rows come from the Rust core's table (:data:`accd_gym.envs.task.OBSERVATION_TABLE`);
every number in the other tables (defaults, units) is read from the configuration's declarations,
never restated here, so a changed default changes the documentation with it. The info flags named
in :data:`EPISODE_END` are the keys the envs report (a test checks them against an env's info).
"""

import re
from typing import Any, Mapping, Optional

from accd_gym import _core
from accd_gym.envs.config import default_config
from accd_gym.envs.task import OBSERVATION_TABLE, observation_table_markdown

#: The action's entries: (flap, what a positive command does). The order is the action's and the
#: observation's (``flap_*`` entries).
ACTION_FLAPS: tuple[tuple[str, str], ...] = (
    ("right", "horizontal flap; with the left one: nose up (pitch)"),
    ("left", "horizontal flap; with the right one: nose up (pitch)"),
    ("top", "vertical flap; with the bottom one: nose right (yaw)"),
    ("bottom", "vertical flap; with the top one: nose right (yaw)"),
)

#: The reward's terms, summed per agent step: (term, formula, the configuration keys of its
#: symbols, when it applies). ``d`` is the capture-point-to-boom-tip distance at the end of the
#: step, ``a`` the action, ``a'`` the previous action (zero at the start), ``steps_left`` the
#: agent steps left in the capture window.
REWARD_TERMS: tuple[tuple[str, str, tuple[str, ...], str], ...] = (
    ("proximity", "w_p exp(-d / lambda)", ("reward.proximity", "reward.proximity_scale"), "every agent step"),
    ("effort", "-w_e sum(a^2) / 4", ("reward.effort",), "every agent step"),
    ("smoothness", "-w_s sum(((a - a') / 2)^2) / 4", ("reward.smoothness",), "every agent step"),
    (
        "capture",
        "w_c + w_p steps_left",
        ("reward.capture", "reward.proximity"),
        "once, on capture: always worth more than hovering beside the boom for the rest of the window",
    ),
    ("failure", "-w_f", ("reward.failure",), "once, on overload, envelope exit or divergence"),
)

#: Symbols of :data:`REWARD_TERMS`' formulas -> their configuration keys.
REWARD_SYMBOLS: dict[str, str] = {
    "w_p": "reward.proximity",
    "lambda": "reward.proximity_scale",
    "w_e": "reward.effort",
    "w_s": "reward.smoothness",
    "w_c": "reward.capture",
    "w_f": "reward.failure",
}

#: How an episode ends: (condition, kind, info flag). ``{key}`` stands for that configuration
#: key's value with its unit.
EPISODE_END: tuple[tuple[str, str, str], ...] = (
    (
        "capture point within {boom.capture_radius} of the boom tip at a closing speed below "
        "{boom.max_closing_speed}, checked every physics step",
        "terminated",
        "captured",
    ),
    (
        "attachment tension above {limits.overload_fraction} of the tether's breaking tension, "
        "checked every physics step",
        "terminated",
        "overload",
    ),
    (
        "distance to the boom over {limits.max_distance}, nose more than {limits.max_tilt_deg} off "
        "the flight direction, pitch or yaw rate over {limits.max_body_rate}, or roll rate over "
        "{limits.max_roll_rate} (the tether's swivel leaves roll free)",
        "terminated",
        "envelope_exit",
    ),
    (
        "the simulation diverged (an error, a non-finite or an implausible state); the observation is "
        "the last good one",
        "terminated",
        "diverged",
    ),
    ("{capture_window} elapsed", "truncated", "-"),
)


def _units() -> dict[str, str]:
    """Configuration key -> its declared unit (``_core.config_fields()``)."""
    return {row[0]: row[1] for row in _core.config_fields()}


def _value(config: Mapping[str, Any], key: str) -> Any:
    value: Any = config
    for part in key.split("."):
        value = value[part]
    return value


def _quantity(config: Mapping[str, Any], units: Mapping[str, str], key: str) -> str:
    """``key``'s value in ``config`` with its declared unit, e.g. ``0.5 m``."""
    unit = units.get(key, "-")
    value = _value(config, key)
    text = f"{value:g}" if isinstance(value, (int, float)) else str(value)
    return text if unit in ("-", "") else f"{text} {unit}"


def _fill(text: str, config: Mapping[str, Any], units: Mapping[str, str]) -> str:
    return re.sub(r"\{([\w.]+)\}", lambda m: f"`{m.group(1)}` ({_quantity(config, units, m.group(1))})", text)


def action_table_markdown(config: Optional[Mapping[str, Any]] = None) -> str:
    """The action table (index, name, range, unit, description) for ``config`` (the defaults)."""
    config = default_config() if config is None else config
    units = _units()
    flaps = [name for name, *_ in OBSERVATION_TABLE if name.startswith("flap_")]
    if [f"flap_{name}" for name, _ in ACTION_FLAPS] != flaps:
        raise RuntimeError(f"ACTION_FLAPS does not follow the observation's flaps {flaps}")
    limit = _quantity(config, units, "accd.flap_limit_deg")
    step = _quantity(config, units, "agent_step")
    rows = ["| index | name | range | unit | description |", "|---|---|---|---|---|"]
    for i, (name, what) in enumerate(ACTION_FLAPS):
        rows.append(f"| {i} | {name} | [-1, 1] | `accd.flap_limit_deg` ({limit}) | {what}; held for `agent_step` ({step}) |")
    return "\n".join(rows)


def reward_table_markdown(config: Optional[Mapping[str, Any]] = None) -> str:
    """The reward's terms (term, formula, when) and their symbols' values for ``config``."""
    config = default_config() if config is None else config
    units = _units()
    rows = ["| term | formula | when |", "|---|---|---|"]
    for term, formula, _, when in REWARD_TERMS:
        rows.append(f"| {term} | `{formula}` | {when} |")
    symbols = ", ".join(
        f"`{symbol}` = `{key}` ({_quantity(config, units, key)})" for symbol, key in REWARD_SYMBOLS.items()
    )
    return "\n".join(rows) + f"\n\nWith {symbols}; `d` is the capture-point-to-boom-tip distance at the end of the step."


def episode_end_table_markdown(config: Optional[Mapping[str, Any]] = None) -> str:
    """The episode-end table (condition, kind, info flag) for ``config`` (the defaults)."""
    config = default_config() if config is None else config
    units = _units()
    rows = ["| condition | kind | `info` flag |", "|---|---|---|"]
    for condition, kind, flag in EPISODE_END:
        shown = f"`{flag}`" if flag != "-" else "-"
        rows.append(f"| {_fill(condition, config, units)} | {kind} | {shown} |")
    return "\n".join(rows)


def task_tables_markdown() -> str:
    """The four tables under their headings, as README.md and ``docs/environment.md`` show them."""
    return "\n\n".join(
        [
            "**Action**: `Box(-1, 1, (4,), float32)`, flap commands.",
            action_table_markdown(),
            "**Observation**: `Box(-10, 10, (25,), float32)`, each quantity times its scale, clipped to "
            "[-10, 10]; TA frame (x forward, y starboard, z down).",
            observation_table_markdown(),
            "**Reward**, summed per agent step:",
            reward_table_markdown(),
            "**Episode end**:",
            episode_end_table_markdown(),
        ]
    )


#: Docstring lines replaced by :func:`with_task_tables`.
TABLE_MARKERS = {
    "{ACTION_TABLE}": action_table_markdown,
    "{OBSERVATION_TABLE}": observation_table_markdown,
    "{REWARD_TABLE}": reward_table_markdown,
    "{EPISODE_END_TABLE}": episode_end_table_markdown,
}


def with_task_tables(doc: Optional[str]) -> Optional[str]:
    """``doc`` (an env class docstring) with each marker line of :data:`TABLE_MARKERS` replaced by
    its table, indented like the marker (None stays None: ``python -OO``)."""
    if doc is None:
        return None
    lines = []
    for line in doc.splitlines():
        make = TABLE_MARKERS.get(line.strip())
        if make is None:
            lines.append(line)
            continue
        indent = line[: len(line) - len(line.lstrip())]
        lines.extend(indent + row if row else "" for row in make().splitlines())
    return "\n".join(lines)


#: A generated section of a markdown file: ``<!-- generated: NAME() -->``, its text, the end mark.
GENERATED_SECTION = re.compile(r"(<!-- generated: (accd_gym\.[\w.]+)\(\) -->\n)(.*?)(<!-- end generated -->)", re.S)


def regenerate(text: str, where: str = "the document") -> str:
    """``text`` (markdown) with every generated section rewritten by the function it names, an
    ``accd_gym`` module's function of no arguments returning markdown. Raises ``ValueError`` naming
    ``where`` and the section for a name that is not such a function."""
    import importlib

    def make(m: "re.Match[str]") -> str:
        module, _, function = m.group(2).rpartition(".")
        try:
            produce = getattr(importlib.import_module(module), function)
        except (ImportError, AttributeError) as e:
            raise ValueError(f"{where}: generated section {m.group(2)}() names no function ({e})") from None
        return f"{m.group(1)}{produce()}\n{m.group(4)}"

    return GENERATED_SECTION.sub(make, text)


__all__ = [
    "ACTION_FLAPS",
    "REWARD_TERMS",
    "REWARD_SYMBOLS",
    "EPISODE_END",
    "action_table_markdown",
    "reward_table_markdown",
    "episode_end_table_markdown",
    "task_tables_markdown",
    "with_task_tables",
    "regenerate",
]
