"""Environment configuration: keyword arguments in, a validated, complete configuration out.

Every env of accd-gym takes its configuration as keyword arguments, e.g.
``gymnasium.make("accd_gym/InAirCapture-v0", capture_window=60.0, wake={"enabled": False})``.
Keys are all optional: missing keys keep their defaults, a section takes a dict of its keys
(merged with its defaults), ``tether`` also a preset name (``"table3"``, ``"uhmwpe-300m-24mm"``,
...), unknown keys raise :class:`~accd_gym.ConfigError`. Every key with its default, unit,
allowed range and description: :func:`config_table_markdown`, generated from the one
declaration per field in the Rust core (``accd_spec::config_struct!``), and printed in the env
docstrings' Arguments and in ``docs/environment.md``.

:func:`default_config` returns every key with its default value.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np

from accd_gym import _core
from accd_gym.envs.overrides import EXACT_AIR_SCHEME, SENSORS_TIER, merge, tier
from accd_gym.errors import ConfigError
from accd_gym.files import read_user_json


def _plain(value: Any) -> Any:
    """numpy scalars and arrays as plain Python values (for JSON)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not a configuration value")


#: The deepest nesting a configuration document may have (its deepest keys, such as
#: ``randomization.airspeed[0]``, are 3 levels down): a deeper one is refused before anything
#: walks it, since a walk thousands of levels deep ends in Python's RecursionError.
MAX_CONFIG_DEPTH = 16


def _check_depth(value: Any) -> None:
    """ConfigError naming the path down to the first value nested deeper than
    :data:`MAX_CONFIG_DEPTH` (walked without recursion)."""
    stack: list[tuple[Any, str, int]] = [(value, "", 0)]
    while stack:
        v, path, depth = stack.pop()
        if depth > MAX_CONFIG_DEPTH:
            shown = path if len(path) <= 60 else path[:57] + "..."
            raise ConfigError(f"invalid config: `{shown}` is nested {depth} levels deep; a configuration is at most "
                              f"{MAX_CONFIG_DEPTH} levels deep")
        if isinstance(v, Mapping):
            stack.extend((x, f"{path}.{k}" if path else str(k), depth + 1) for k, x in v.items())
        elif isinstance(v, (list, tuple)):
            stack.extend((x, f"{path}[{i}]", depth + 1) for i, x in enumerate(v))


def _check_finite(value: Any, path: str) -> None:
    """ConfigError naming the dotted field of the first NaN or infinite number in ``value``."""
    if isinstance(value, Mapping):
        for k, v in value.items():
            _check_finite(v, f"{path}.{k}" if path else str(k))
    elif isinstance(value, (list, tuple, np.ndarray)):
        for i, v in enumerate(value):
            _check_finite(v, f"{path}[{i}]")
    elif isinstance(value, (float, np.floating)) and not np.isfinite(value):
        raise ConfigError(f"invalid config: `{path}` = {value} is outside the allowed range: a finite number")


def default_config() -> dict[str, Any]:
    """The default environment configuration, every key filled in (SI units unless named)."""
    return json.loads(_core.default_env_config_json())


def env_config(config: Optional[Mapping[str, Any]] = None, **overrides: Any) -> dict[str, Any]:
    """A complete, validated environment configuration from ``config`` and keyword overrides.

    A string ``tether`` is taken as a tether preset; ``tier`` names a benchmark tier
    (:mod:`accd_gym.envs.tiers`) whose overrides the others are merged into. Raises :class:`~accd_gym.ConfigError`
    naming the field, the value and the allowed range (unknown keys included).
    """
    return json.loads(valid_config(config, self_contained_tables=False, **overrides).to_json())


def valid_config(
    config: Optional[Mapping[str, Any]] = None, *, self_contained_tables: bool = True, **overrides: Any
) -> _core.EnvConfig:
    """The validated configuration object the envs are built from (``accd_gym._core.EnvConfig``):
    ``config`` and keyword overrides merged (over the overrides of a benchmark tier named by the
    key ``tier``, :mod:`accd_gym.envs.tiers`, section by section), a string ``tether`` taken as a preset, a user
    aerodynamic table given by path replaced by its contents (with ``self_contained_tables``, so
    that pickles and saved states need no file), then sent to the core as one JSON document and
    validated there once. The envs take it as it is; ``.to_json()`` gives it back. Picklable.
    Raises :class:`~accd_gym.ConfigError` naming the field, the value and the allowed range.
    """
    merged: dict[str, Any] = dict(config or {})
    merged.update(overrides)
    _check_depth(merged)
    if "tier" in merged:
        name = merged.pop("tier")
        merged = merge(tier(name).overrides, merged)
    tether = merged.get("tether")
    if isinstance(tether, str):
        merged["tether"] = _core.tether_config(tether)
    _check_finite(merged, "")
    if self_contained_tables:
        merged = self_contained(merged)
    try:
        text = json.dumps(merged, default=_plain, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"invalid config: {e}") from None
    return _core.EnvConfig(text)


def self_contained(config: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of a complete configuration that needs no file: a user aerodynamic table given by
    path (``accd.aero_table``) is replaced by the table's contents (JSON text, which the core
    reads as the table itself). For pickles and saved envs that must load on another machine.
    Raises ConfigError when the file cannot be read, is not a regular file of at most 64 MiB
    (:func:`accd_gym.files.read_user_file`) or is not JSON."""
    out = json.loads(json.dumps(config, default=_plain))
    accd = out.get("accd")
    table = accd.get("aero_table") if isinstance(accd, dict) else None
    if isinstance(table, str) and not table.lstrip().startswith("{"):
        out["accd"]["aero_table"] = json.dumps(read_user_json(table, "`accd.aero_table`"))
    return out


def _default_text(defaults: Mapping[str, Any], key: str, declared: str) -> str:
    """The default of dotted ``key`` as Python shows it (from ``default_config()``), or, for a
    key the configuration omits at its default, the declaration's text with a Rust enum variant
    (``Elasticity::Attachment``) shown as the string the configuration takes (``'attachment'``)."""
    value: Any = defaults
    for part in key.split("."):
        if not isinstance(value, Mapping) or part not in value:
            variant = re.fullmatch(r"[A-Z]\w*::([A-Z]\w*)", declared)
            if variant:
                return repr(re.sub(r"(?<!^)(?=[A-Z])", "_", variant.group(1)).lower())
            try:  # a number or a switch (``1e-3``, ``false``) as Python shows it
                return repr(json.loads(declared))
            except ValueError:
                return declared
        value = value[part]
    return repr(value)


def config_table_markdown() -> str:
    """Every configuration key as a markdown table (key, default, unit, allowed range,
    description), generated from the Rust declarations (``_core.config_fields()``, one per
    field): the Arguments tables of the env docstrings and ``docs/environment.md`` carry it.
    Ranges: ``(`` and ``)`` exclude the end, ``[`` and ``]`` include it; a rule between fields
    is in the description."""
    defaults = default_config()
    rows = ["| key | default | unit | range | description |", "|---|---|---|---|---|"]
    for key, unit, allowed, description, section, declared in _core.config_fields():
        if section:
            rows.append(f"| **`{key}`** | | | | {description} |")
        else:
            default = _default_text(defaults, key, declared).replace("|", "\\|")
            text = description.replace("|", "\\|")
            rows.append(f"| `{key}` | `{default}` | {unit} | {allowed} | {text} |")
    return "\n".join(rows)


ARGUMENTS_MARKER = "{CONFIG_ARGUMENTS}"


def with_arguments(doc: Optional[str]) -> Optional[str]:
    """``doc`` (an env class docstring) with its :data:`ARGUMENTS_MARKER` line replaced by
    :func:`config_table_markdown`, indented like the marker (None stays None: ``python -OO``)."""
    if doc is None:
        return None
    for line in doc.splitlines():
        if line.strip() == ARGUMENTS_MARKER:
            indent = line[: len(line) - len(line.lstrip())]
            table = "\n".join(indent + row for row in config_table_markdown().splitlines())
            return doc.replace(line, table, 1)
    raise ValueError(f"docstring has no {ARGUMENTS_MARKER} line")


def read_json_object(path: "str | Path", what: str) -> dict[str, Any]:
    """The JSON object in file ``path`` (a training, sweep or other config named ``what`` in the
    messages); raises :class:`~accd_gym.ConfigError` if the file is missing, is not a regular
    file of at most 64 MiB (:func:`accd_gym.files.read_user_file`), is not JSON or holds
    something other than an object."""
    from pathlib import Path

    if not Path(path).exists():
        raise ConfigError(f"invalid config: {what} file {str(path)!r} does not exist")
    raw = read_user_json(path, what)
    if not isinstance(raw, dict):
        raise ConfigError(
            f"invalid config: {str(path)!r} holds a JSON {type(raw).__name__}; a {what} must be a JSON object"
        )
    return raw


def config_json(config: Mapping[str, Any]) -> str:
    """A configuration as the JSON text the Rust core reads."""
    return json.dumps(config, default=_plain)


__all__ = [
    "default_config",
    "env_config",
    "valid_config",
    "config_json",
    "self_contained",
    "config_table_markdown",
    "read_json_object",
    "EXACT_AIR_SCHEME",
    "SENSORS_TIER",
]
