"""The RL task's spaces, observation table, info fields and seeds, shared by every env class.

The numbers come from the Rust core (``crates/sim/src/task/``), so they cannot drift apart.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from accd_gym import _core
from accd_gym.errors import ConfigError, StateError
from accd_gym.envs.config import config_json

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
#: Names of the physical parameters randomized physics draws per episode (drawing order; see
#: ``randomization`` in docs/environment.md).
PARAMETER_NAMES: tuple[str, ...] = tuple(_core.PARAMETER_NAMES)
#: Wake seeds training draws from: ``range(*TRAINING_WAKE_SEEDS)``.
TRAINING_WAKE_SEEDS: range = range(*_core.TRAINING_WAKE_SEEDS)
#: Wake seeds held out for evaluation (training never draws them): ``range(10**9, 10**9 + 1000)``.
HELD_OUT_WAKE_SEEDS: range = range(*_core.HELD_OUT_WAKE_SEEDS)
#: Wake seeds for validation while tuning (the last 1000 training wake seeds): episodes of the
#: training distribution, wake and randomized parameters alike, so that hyperparameters chosen on
#: them have never seen the held-out set; training's draws skip them (a draw that lands there is
#: drawn again), so no training episode has a validation wake.
VALIDATION_WAKE_SEEDS: range = range(*_core.VALIDATION_WAKE_SEEDS)
#: Most envs of one vector env (``num_envs``).
MAX_ENVS: int = _core.MAX_ENVS
#: Most threads of one vector env (``num_threads``; 0: one per core).
MAX_THREADS: int = _core.MAX_THREADS
#: The end of the one range of every seed: config ``wake_seed``/``wake_seeds``, the reset
#: options of the same names, a reset's ``seed``, the vector envs' base seeds (``seed + i``
#: included) and the CLI's ``--seed`` all lie in [0, 2^63), the non-negative int64 values, so
#: that a seed reported in an info (an int64 column, as gymnasium batches Python ints) never wraps.
SEED_END: int = _core.SEED_END
#: :data:`SEED_END` in words, for the messages.
SEED_RANGE: str = "[0, 2^63)"
#: Observation scale by name (the observation is the quantity times its scale).
OBSERVATION_SCALE: dict[str, float] = {name: scale for name, _, scale, _ in OBSERVATION_TABLE}
#: Observation index by name.
OBSERVATION_INDEX: dict[str, int] = {name: i for i, (name, _, _, _) in enumerate(OBSERVATION_TABLE)}


def observation_indices(*names: str) -> np.ndarray:
    """The observation indices of the entries ``names`` (``OBSERVATION_TABLE``'s names), in the
    order given: ``obs[:, observation_indices("boom_rel_y", "boom_rel_z")]``. Code reads the
    observation by name, never by numeric slices. Raises ``KeyError`` naming an unknown entry."""
    try:
        return np.array([OBSERVATION_INDEX[n] for n in names], dtype=np.intp)
    except KeyError as e:
        raise KeyError(f"no observation entry {e.args[0]!r}; the entries are {list(OBSERVATION_INDEX)}") from None


#: Flags of the info dict that say why an episode ended, in their order of precedence (from the
#: Rust declaration of the info columns).
EVENT_NAMES: tuple[str, ...] = tuple(_core.EVENT_NAMES)
#: Column of the "diverged" flag in a step's info array.
DIVERGED_COLUMN: int = INFO_NAMES.index("diverged")


def observation_space() -> spaces.Box:
    """The observation space of one env: float32, shape (OBS_DIM,), bounds +-OBS_BOUND."""
    return spaces.Box(-OBS_BOUND, OBS_BOUND, shape=(OBS_DIM,), dtype=np.float32)


def action_space() -> spaces.Box:
    """The action space of one env: four flap commands, float32 in [-1, 1]."""
    return spaces.Box(-1.0, 1.0, shape=(ACT_DIM,), dtype=np.float32)


def info_dicts(info: np.ndarray, wake_seed: np.ndarray) -> list[dict[str, Any]]:
    """One info dict per row of a step's info array (plain Python values), built natively.

    ``info``: (n, len(INFO_NAMES)) float64; ``wake_seed``: (n,) uint64. Each dict has the
    ``INFO_NAMES`` in order (the ``EVENT_NAMES`` as bool, ``episode_steps`` as int, the rest as
    float), then ``wake_seed`` (int).
    """
    return _core.info_dicts(info, wake_seed)


_FLOAT32_MAX = float(np.finfo(np.float32).max)


def check_actions(actions: Any, num_envs: int, *, single: bool = False) -> np.ndarray:
    """Actions as a C-contiguous float32 array of shape (num_envs, ACT_DIM).

    ``single``: the action of a single env, shape (ACT_DIM,) exactly (a batch of one is
    refused). Raises :class:`~accd_gym.StateError` (a ValueError) for values that are not real
    numbers (bool, complex, str, objects), finite values outside float32's range and a wrong
    shape. Non-finite values are refused by the Rust core, with the env index named.
    """
    expected = (ACT_DIM,) if single else (num_envs, ACT_DIM)
    try:
        raw = np.asarray(actions)
    except (TypeError, ValueError) as e:
        raise StateError(f"actions must be real numbers of shape {expected}: {e}") from None
    if raw.dtype.kind not in "fiu":
        raise StateError(f"actions must be real numbers of shape {expected}, got dtype {raw.dtype}")
    if raw.shape != expected:
        raise StateError(f"actions have shape {raw.shape}, expected {expected}")
    if raw.dtype.kind == "f" and raw.dtype.itemsize > 4:
        too_big = np.isfinite(raw) & (np.abs(raw) > _FLOAT32_MAX)
        if too_big.any():
            k = int(np.flatnonzero(too_big.reshape(-1))[0])
            raise StateError(
                f"action {raw.reshape(-1)[k]!r} (env {k // ACT_DIM}, component {k % ACT_DIM}) is finite but "
                f"outside float32's range (|a| <= {_FLOAT32_MAX:.4g}): actions are float32 in [-1, 1] "
                f"(values outside it are clipped)"
            )
    return np.ascontiguousarray(raw, dtype=np.float32).reshape(num_envs, ACT_DIM)


def check_observations(obs: Any) -> np.ndarray:
    """Observations as a float64 array of shape (N, OBS_DIM) (one observation of shape (OBS_DIM,)
    becomes a batch of one); raises ValueError otherwise. What a policy's ``predict`` reads."""
    o = np.asarray(obs, dtype=np.float64)
    if o.ndim == 1:
        o = o.reshape(1, -1)
    if o.ndim != 2 or o.shape[1] != OBS_DIM:
        raise ValueError(f"observations have shape {np.shape(obs)}, expected (N, {OBS_DIM})")
    return o

def check_seed(seed: Any, what: str = "seed", bound: int = SEED_END) -> int:
    """``seed`` as a Python int in [0, bound) (by default the one seed range [0, 2^63),
    :data:`SEED_END`): a Python or numpy integer (not a bool).

    Raises :class:`~accd_gym.ConfigError` naming ``what`` and quoting the value as given for
    anything else (floats, strings, bools, negative or too large values).
    """
    allowed = SEED_RANGE if bound == SEED_END else f"[0, {bound})"
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise ConfigError(f"invalid config: `{what}` = {seed!r} is outside the allowed range: an int in {allowed}")
    value = int(seed)
    if not 0 <= value < bound:
        raise ConfigError(f"invalid config: `{what}` = {value} is outside the allowed range: an int in {allowed}")
    return value


def check_count(value: Any, what: str, low: int, high: int | None = None, noun: str = "") -> int:
    """``value`` as a Python int in [low, high] (``high=None``: no upper bound): a Python or numpy
    integer. Bools, floats, strings and integers out of range raise
    :class:`~accd_gym.ConfigError` naming ``what`` (after ``noun``, e.g. "env index"), the value
    and the range; nothing is truncated or parsed (``2.7`` is not 2, ``"3"`` is not 3, ``True``
    is not 1)."""
    allowed = f"an integer in [{low}, {high}]" if high is not None else f"an integer >= {low}"
    name = f"{noun} `{what}`" if noun else f"`{what}`"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"invalid config: {name} = {value!r} is outside the allowed range: {allowed}")
    count = int(value)
    if count < low or (high is not None and count > high):
        raise ConfigError(f"invalid config: {name} = {count} is outside the allowed range: {allowed}")
    return count


def check_base_seed(seed: Any, num_envs: int, count: str = "num_envs", what: str = "seed") -> int:
    """A base seed ``seed`` that gives ``num_envs`` envs (or episodes) the seeds ``seed + i``: a
    Python or numpy integer in [0, 2^63 - num_envs], so that every one of them lies in the seed
    range [0, 2^63) (none wraps). Raises :class:`~accd_gym.ConfigError` naming ``what`` (default
    ``seed``), quoting the value as given, the count (named ``count``) and the range otherwise (a
    ``SyncVectorEnv`` of single envs raises it from the env whose seed is out of range)."""
    value = check_seed(seed, what)
    if value + num_envs - 1 >= SEED_END:
        raise ConfigError(
            f"invalid config: `{what}` = {value} is outside the allowed range [0, 2^63 - {count}] = "
            f"[0, {SEED_END - num_envs}] for {count} = {num_envs} ({what} + i is the seed of the i-th, "
            f"every seed in {SEED_RANGE})"
        )
    return value


def check_flag(value: Any, what: str) -> bool:
    """``value`` as a bool: True or False (Python or numpy bools only; ``1``, ``"yes"`` and None
    raise :class:`~accd_gym.ConfigError` naming ``what``)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"invalid config: `{what}` = {value!r} is outside the allowed range: True or False")
    return bool(value)


#: Wake seeds lie in the one seed range (:data:`SEED_END`).
WAKE_SEED_BOUND: int = SEED_END


def wake_options(core: Any, options: dict[str, Any] | None) -> None:
    """Applies the wake-seed options of ``reset`` to the core (they persist over later resets).

    ``{"wake_seed": int}`` fixes the wake seed, ``{"wake_seeds": [int, ...]}`` cycles through a
    list, ``{"wake_seed": None}`` returns to training draws. Seeds are Python or numpy integers
    in the one seed range [0, 2^63) (floats, strings and bools are refused). Unknown keys raise
    ConfigError.
    """
    if not options:
        return

    unknown = set(options) - {"wake_seed", "wake_seeds"}
    if unknown:
        raise ConfigError(
            f"invalid config: reset option(s) {sorted(unknown)} outside the allowed set ['wake_seed', 'wake_seeds']"
        )
    if "wake_seeds" in options and options["wake_seeds"] is not None:
        seeds = options["wake_seeds"]
        if isinstance(seeds, (str, bytes)) or not hasattr(seeds, "__iter__"):
            raise ConfigError(f"invalid config: `wake_seeds` = {seeds!r} is outside the allowed range: a list of ints")
        core.set_wake_schedule("list", [check_seed(s, "wake_seeds", WAKE_SEED_BOUND) for s in seeds])
    elif "wake_seed" in options:
        seed = options["wake_seed"]
        if seed is None:
            core.set_wake_schedule("training", [])
        else:
            core.set_wake_schedule("fixed", [check_seed(seed, "wake_seed", WAKE_SEED_BOUND)])


def episode_steps(config: dict[str, Any]) -> int:
    """Agent steps of one episode under a full configuration (``capture_window / agent_step``)."""
    return int(_core.episode_steps(config_json(config)))


def check_max_episode_steps(max_episode_steps: Any, config: dict[str, Any]) -> None:
    """Refuses a ``max_episode_steps`` (gymnasium's TimeLimit length, which ``make_vec`` passes
    from the registered spec) shorter than the configuration's episode: the capture window ends
    episodes, and a time limit inside it would change nothing but the truncation step."""
    if max_episode_steps is None:
        return

    steps = episode_steps(config)
    limit = check_seed(max_episode_steps, "max_episode_steps")
    if limit < steps:
        raise ConfigError(
            f"invalid config: `max_episode_steps` = {limit} is outside the allowed range [{steps}, inf): the capture "
            f"window ({config['capture_window']} s = {steps} agent steps) sets the episode length; pass "
            f"max_episode_steps={steps} with this capture_window, or shorten capture_window"
        )


def random_seed(num_envs: int = 1) -> int:
    """A fresh 64-bit seed from the operating system's entropy, a valid int seed of ``num_envs``
    envs (:func:`check_base_seed`: in [0, 2^63 - num_envs])."""
    return int(np.random.SeedSequence().generate_state(1, dtype=np.uint64)[0]) % (SEED_END - num_envs + 1)


def observation_table_markdown() -> str:
    """The observation table as markdown (index, name, unit, scale, description)."""
    rows = ["| index | name | unit | scale | description |", "|---|---|---|---|---|"]
    for i, (name, unit, scale, desc) in enumerate(OBSERVATION_TABLE):
        rows.append(f"| {i} | {name} | {unit} | {scale:g} | {desc} |")
    return "\n".join(rows)
