"""Property-based tests (hypothesis) over configurations, actions, seeds, states and files: no
input makes the package panic, hang, crash or return a non-finite value silently; every refusal
is an accd-gym error naming what is wrong.

CI runs a short profile (well under 90 s); ``ACCD_HYPOTHESIS_LONG=1`` runs about 20 times more
examples per property (the issue's 10,000-case sweep takes about that).
"""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import accd_gym
from accd_gym import AccdError, ConfigError, SimulationError, StateError

LONG = os.environ.get("ACCD_HYPOTHESIS_LONG") == "1"
settings.register_profile(
    "accd", deadline=None, derandomize=not LONG, suppress_health_check=[HealthCheck.too_slow],
    print_blob=True,
)
settings.load_profile("accd")


def examples(short: int) -> settings:
    """``short`` examples in CI, 20 times as many in the long mode."""
    return settings(max_examples=short * 20 if LONG else short)


# Values a user might type where a number belongs.
junk = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.booleans(),
    st.none(),
    st.text(max_size=5),
    st.lists(st.floats(-10, 10), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)

TETHER_FIELDS = sorted(accd_gym.tether_config())
QUICK_ENV = {"capture_window": 0.5, "initial": {"settle_time": 0.5}}


def plausible(field: str) -> st.SearchStrategy:
    """Values of a tether field around its default, in and a little out of range."""
    default = accd_gym.tether_config()[field]
    if field == "segments":
        return st.integers(-2, 1200)
    return st.floats(-0.5 * abs(default) - 1, 3.0 * abs(default) + 1, allow_nan=False)


@examples(60)
@given(st.data())
def test_tether_configs_are_refused_by_name_or_step(data):
    fields = data.draw(st.lists(st.sampled_from(TETHER_FIELDS), min_size=1, max_size=3, unique=True))
    overrides = {f: data.draw(st.one_of(plausible(f), junk)) for f in fields}
    try:
        tether = accd_gym.Tether(overrides)
    except ConfigError as e:
        message = str(e)
        # a field's own range names it; the stability rule between fields names the step and
        # the discretization it follows from
        assert any(f"`{f}`" in message or f"{f} =" in message for f in fields) or "RK4 substeps" in message, message
        return
    tether.tow()
    try:
        tether.step(20)
    except SimulationError:
        pass
    assert np.all(np.isfinite(tether.q)) and np.all(np.isfinite(tether.qd))
    assert np.all(np.isfinite(tether.tensions()))
    assert all(math.isfinite(v) for v in tether.energy().values())


#: Every key with its default, the sensors section (left out of the default configuration while
#: off) included, switched on.
_DEFAULTS = {**accd_gym.default_config(), "sensors": accd_gym.env_config(sensors={"enabled": True})["sensors"]}


def _env_leaf_paths() -> list[tuple[str, ...]]:
    """Dotted paths of every numeric leaf of the env config."""
    out: list[tuple[str, ...]] = []

    def walk(d, path):
        for k, v in d.items():
            if isinstance(v, dict):
                walk(v, path + (k,))
            elif isinstance(v, (int, float)) and not isinstance(v, bool):
                out.append(path + (k,))

    walk(_DEFAULTS, ())
    return out


ENV_PATHS = _env_leaf_paths()


def _nest(path: tuple[str, ...], value):
    for key in reversed(path):
        value = {key: value}
    return value


@examples(80)
@given(path=st.sampled_from(ENV_PATHS), value=junk)
def test_junk_env_config_values_are_refused_naming_the_field(path, value):
    try:
        accd_gym.env_config(**_nest(path, value))
    except ConfigError as e:
        message = str(e)
        named = ".".join(path) in message or f"`{path[-1]}`" in message or f"{path[-1]} =" in message
        assert named or "RK4 substeps" in message, message
        assert "line 1 column" not in message, message


@examples(12)
@given(path=st.sampled_from(ENV_PATHS), scale=st.floats(0.2, 3.0))
def test_env_configs_that_validate_build_and_step(path, scale):
    default = _DEFAULTS
    for key in path:
        default = default[key]
    value = type(default)(default * scale) if default else scale
    overrides = json.loads(json.dumps(QUICK_ENV))
    for k, v in _nest(path, value).items():
        if isinstance(v, dict) and isinstance(overrides.get(k), dict):
            overrides[k].update(v)
        else:
            overrides[k] = v
    if path[0] == "sensors":
        overrides["sensors"]["enabled"] = True
    try:
        env = accd_gym.InAirCaptureEnv(**overrides)
    except ConfigError:
        return
    except SimulationError as e:  # a valid config may only fail to settle with a named divergence
        assert "diverged" in str(e)
        return
    obs, _ = env.reset(seed=0)
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert np.all(np.isfinite(obs)) and math.isfinite(reward)
        if terminated or truncated:
            break


_ENV = None


def _vec_env():
    global _ENV
    if _ENV is None:
        _ENV = accd_gym.AccdVecEnv(num_envs=3, seed=0, num_threads=1, **QUICK_ENV)
        _ENV.reset()
    return _ENV


@examples(60)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=12, max_size=12))
def test_actions_are_clipped_or_refused_never_propagated(values):
    env = _vec_env()
    actions = np.asarray(values, np.float32).reshape(3, 4)
    env.step_async(actions)
    if not np.all(np.isfinite(actions)):
        with pytest.raises(StateError):
            env.step_wait()
        return
    obs, reward, dones, infos = env.step_wait()
    assert np.all(np.isfinite(obs)) and np.all(np.abs(obs) <= accd_gym._core.OBS_BOUND)
    assert np.all(np.isfinite(reward))


@examples(60)
@given(st.one_of(junk, st.integers(-5, 2**66)))
def test_capture_sim_seeds_are_integers_in_range(seed):
    valid = isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < 2**63
    if seed is None:  # the default: the wake seed follows `seed`
        assert accd_gym.CaptureSim(calm=True, seed=3, wake_seed=None).seeds["wake"] == 3
    elif valid:
        assert accd_gym.CaptureSim(calm=True, seed=seed, wake_seed=seed).seeds["wake"] == seed
    else:
        with pytest.raises(ConfigError, match="seed"):
            accd_gym.CaptureSim(calm=True, wake_seed=seed)


@examples(40)
@given(
    phi=st.lists(st.floats(-4, 4), min_size=8, max_size=8),
    psi=st.lists(st.floats(-1.6, 1.6), min_size=8, max_size=8),
    rate=st.floats(-200, 200),
)
def test_any_tether_state_steps_or_diverges_with_finite_outputs(phi, psi, rate):
    tether = accd_gym.Tether({"segments": 8, "length": 40.0, "tip_mass": 5.0})
    tether.tow()
    try:
        tether.set_angles(np.array(phi), np.array(psi), phi_rate=np.full(8, rate), psi_rate=np.zeros(8))
    except StateError:
        return
    try:
        tether.advance(0.5)
    except SimulationError:
        pass
    assert np.all(np.abs(tether.q) <= 1e6) and np.all(np.abs(tether.qd) <= 1e6)
    assert np.all(np.isfinite(tether.tensions()))
    assert all(math.isfinite(v) for v in tether.energy().values())


_TABLE = json.loads(accd_gym.default_aero_table_json())


@examples(25)
@given(data=st.data())
def test_aero_table_files_are_loaded_or_refused(tmp_path_factory, data):
    table = json.loads(json.dumps(_TABLE))
    key = data.draw(st.sampled_from(sorted(table)))
    mutation = data.draw(st.sampled_from(["drop", "junk", "truncate", "scale"]))
    if mutation == "drop":
        del table[key]
    elif mutation == "junk":
        table[key] = data.draw(junk)
    elif mutation == "truncate" and isinstance(table[key], list):
        table[key] = table[key][: len(table[key]) // 2]
    elif isinstance(table[key], (int, float)) and not isinstance(table[key], bool):
        table[key] = table[key] * data.draw(st.floats(-2, 2))
    path = tmp_path_factory.mktemp("aero") / "table.json"
    text = json.dumps(table)
    if data.draw(st.booleans()):
        text = text[: data.draw(st.integers(0, len(text)))]
    path.write_text(text)
    try:
        sim = accd_gym.CaptureSim({"accd": {"aero_table": str(path)}}, calm=True)
    except ConfigError as e:
        assert str(path) in str(e) or "table" in str(e) or "accd" in str(e), str(e)
        return
    try:
        state = sim.step([1.0, -1.0, 0.5, 0.0], steps=20)
    except SimulationError:
        return
    assert all(np.all(np.isfinite(v)) for v in state.values() if isinstance(v, (float, np.ndarray)))


@examples(40)
@given(st.binary(max_size=200), st.integers(0, 4000), st.integers(0, 255))
def test_corrupted_env_states_are_refused(junk_bytes, where, byte):
    env = _vec_env()
    good = env.get_state()
    corrupted = bytearray(good)
    corrupted[where % len(corrupted)] = byte
    for state in (bytes(junk_bytes), bytes(corrupted), good[: where % len(good)]):
        try:
            env.set_state(state)
        except AccdError:
            continue
        env.step_async(np.zeros((3, 4), np.float32))
        try:
            obs, *_ = env.step_wait()
        except AccdError:
            continue
        assert np.all(np.isfinite(obs))
    env.set_state(good)
