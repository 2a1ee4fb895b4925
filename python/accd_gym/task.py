"""The RL task's spaces, observation table, info fields and seeds, shared by every env class.

The numbers come from the Rust core (``crates/sim/src/task.rs``), so they cannot drift apart.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from accd_gym import _core

#: Number of observation values.
OBS_DIM: int = _core.OBS_DIM
#: Number of action values (flap commands: right, left, top, bottom).
ACT_DIM: int = _core.ACT_DIM
#: Every observation value lies in [-OBS_BOUND, OBS_BOUND].
OBS_BOUND: float = float(_core.OBS_BOUND)
#: The observation table: (name, unit, scale, description) per index.
OBSERVATION_TABLE: list[tuple[str, str, float, str]] = list(_core.observation_table())
#: Names of the per-step info values.
INFO_NAMES: tuple[str, ...] = tuple(_core.INFO_NAMES)
#: Wake seeds training draws from: ``range(*TRAINING_WAKE_SEEDS)``.
TRAINING_WAKE_SEEDS: range = range(*_core.TRAINING_WAKE_SEEDS)
#: Wake seeds held out for evaluation (training never draws them): ``range(10**9, 10**9 + 1000)``.
HELD_OUT_WAKE_SEEDS: range = range(*_core.HELD_OUT_WAKE_SEEDS)
#: Observation scale by name (the observation is the quantity times its scale).
OBSERVATION_SCALE: dict[str, float] = {name: scale for name, _, scale, _ in OBSERVATION_TABLE}
#: Observation index by name.
OBSERVATION_INDEX: dict[str, int] = {name: i for i, (name, _, _, _) in enumerate(OBSERVATION_TABLE)}
#: Flags of the info dict that say why an episode ended.
EVENT_NAMES: tuple[str, ...] = ("captured", "overload", "envelope_exit", "diverged")


def observation_space() -> spaces.Box:
    """The observation space of one env: float32, shape (OBS_DIM,), bounds +-OBS_BOUND."""
    return spaces.Box(-OBS_BOUND, OBS_BOUND, shape=(OBS_DIM,), dtype=np.float32)


def action_space() -> spaces.Box:
    """The action space of one env: four flap commands, float32 in [-1, 1]."""
    return spaces.Box(-1.0, 1.0, shape=(ACT_DIM,), dtype=np.float32)


def info_dict(info_row: np.ndarray, wake_seed: int) -> dict[str, Any]:
    """The info dict of one env from its row of the info array (plain Python values)."""
    out: dict[str, Any] = {}
    for name, value in zip(INFO_NAMES, info_row.tolist()):
        out[name] = bool(value) if name in EVENT_NAMES else value
    out["episode_steps"] = int(out["episode_steps"])
    out["wake_seed"] = int(wake_seed)
    return out


def check_actions(actions: Any, num_envs: int) -> np.ndarray:
    """Actions as a C-contiguous float32 array of shape (num_envs, ACT_DIM).

    Raises :class:`~accd_gym.StateError` (a ValueError) for values that are not numbers or a
    wrong shape. Non-finite values are refused by the Rust core, with the env index named.
    """
    from accd_gym.errors import StateError

    try:
        a = np.ascontiguousarray(actions, dtype=np.float32)
    except (TypeError, ValueError) as e:
        raise StateError(f"actions must be numbers, shape ({num_envs}, {ACT_DIM}): {e}") from None
    if a.shape == (ACT_DIM,) and num_envs == 1:
        a = a.reshape(1, ACT_DIM)
    if a.shape != (num_envs, ACT_DIM):
        raise StateError(f"actions have shape {np.shape(actions)}, expected ({num_envs}, {ACT_DIM})")
    return a


def wake_options(core: Any, options: dict[str, Any] | None) -> None:
    """Applies the wake-seed options of ``reset`` to the core (they persist over later resets).

    ``{"wake_seed": int}`` fixes the wake seed, ``{"wake_seeds": [int, ...]}`` cycles through a
    list, ``{"wake_seed": None}`` returns to training draws. Unknown keys raise ConfigError.
    """
    if not options:
        return
    from accd_gym.errors import ConfigError

    unknown = set(options) - {"wake_seed", "wake_seeds"}
    if unknown:
        raise ConfigError(
            f"invalid config: reset option(s) {sorted(unknown)} outside the allowed set ['wake_seed', 'wake_seeds']"
        )
    if "wake_seeds" in options and options["wake_seeds"] is not None:
        core.set_wake_schedule("list", [int(s) for s in options["wake_seeds"]])
    elif "wake_seed" in options:
        seed = options["wake_seed"]
        if seed is None:
            core.set_wake_schedule("training", [])
        else:
            core.set_wake_schedule("fixed", [int(seed)])


def random_seed() -> int:
    """A fresh 64-bit seed from the operating system's entropy."""
    return int(np.random.SeedSequence().generate_state(1, dtype=np.uint64)[0])


def observation_table_markdown() -> str:
    """The observation table as markdown (index, name, unit, scale, description)."""
    rows = ["| index | name | unit | scale | description |", "|---|---|---|---|---|"]
    for i, (name, unit, scale, desc) in enumerate(OBSERVATION_TABLE):
        rows.append(f"| {i} | {name} | {unit} | {scale:g} | {desc} |")
    return "\n".join(rows)
