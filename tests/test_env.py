"""The single gymnasium env and the native gymnasium VectorEnv: checkers, tables, seeds,
autoreset, buffers, state, pickling, rendering and bad input."""

from __future__ import annotations

import json
import pickle
import threading
import time
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import accd_gym
from accd_gym.envs.task import EVENT_NAMES, OBS_DIM, OBSERVATION_TABLE

ENV_ID = "accd_gym/InAirCapture-v0"
#: Short episodes (2 s = 20 agent steps) and a quick equilibrium, for tests.
QUICK = {"capture_window": 2.0, "initial": {"settle_time": 20.0}}


def rollout(env, actions, seed):
    """Observations, rewards and flags of a single env under a fixed action list."""
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out += [obs, r, term, trunc, info["distance"]]
        if term or trunc:
            break
    return out


def same(a, b):
    """Bitwise equality of nested lists of arrays and scalars."""
    return len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b))


def test_gymnasium_check_env_passes_without_warnings():
    from gymnasium.utils.env_checker import check_env

    env = gym.make(ENV_ID, **QUICK)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)


def test_stable_baselines3_check_env_passes_without_warnings():
    from stable_baselines3.common.env_checker import check_env

    env = gym.make(ENV_ID, **QUICK)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, warn=True)


def test_step_types_and_bounds():
    env = gym.make(ENV_ID, **QUICK)
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and obs.shape == (OBS_DIM,)
    assert isinstance(info["wake_seed"], int)
    obs, r, term, trunc, info = env.step(env.action_space.sample())
    assert type(r) is float and type(term) is bool and type(trunc) is bool
    assert env.observation_space.contains(obs)
    assert set(EVENT_NAMES) <= set(info) and all(type(info[k]) is bool for k in EVENT_NAMES)


def test_docstring_tables_match_the_core():
    doc = accd_gym.InAirCaptureEnv.__doc__
    for heading in ("## Action Space", "## Observation Space", "## Rewards", "## Starting State", "## Episode End"):
        assert heading in doc
    assert len(OBSERVATION_TABLE) == OBS_DIM == 25
    for name, unit, scale, _ in OBSERVATION_TABLE:
        stem = name.rstrip("xyzwpqr").rstrip("_v") if name[-1] in "xyzwpqr" else name
        assert stem.split("_")[0] in doc, name
    lo, hi = accd_gym.reward_bounds()
    assert (lo, hi) == (-(0.05 + 0.05 + 50.0), 700.0 + 100.0)


def test_truncates_at_the_capture_window_and_needs_reset():
    env = gym.make(ENV_ID, **QUICK, boom={"capture_radius": 1e-6}).unwrapped
    env.reset(seed=1)
    for k in range(20):
        _, _, term, trunc, info = env.step(np.zeros(4, np.float32))
        assert not term
        assert trunc == (k == 19)
    assert info["episode_steps"] == 20 and abs(info["time"] - 2.0) < 1e-9
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(4, np.float32))


def test_same_seed_same_episode_different_seed_different():
    env = gym.make(ENV_ID, **QUICK).unwrapped
    actions = [np.array([np.sin(k / 3), 0.3, -0.2, 0.5], np.float32) for k in range(15)]
    a = rollout(env, actions, seed=5)
    b = rollout(env, actions, seed=5)
    c = rollout(env, actions, seed=6)
    assert same(a, b)
    assert not same(a, c)


def test_wake_seed_can_be_fixed_alone_and_persists():
    env = gym.make(ENV_ID, **QUICK).unwrapped
    _, info = env.reset(seed=1, options={"wake_seed": 1_000_000_007})
    assert info["wake_seed"] == 1_000_000_007
    seeds = env.episode_seeds()
    _, info = env.reset()
    assert info["wake_seed"] == 1_000_000_007 and env.episode_seeds()["initial"] != seeds["initial"]
    _, info = env.reset(options={"wake_seed": None})
    assert info["wake_seed"] in accd_gym.TRAINING_WAKE_SEEDS
    with pytest.raises(accd_gym.ConfigError, match="wake_sed"):
        env.reset(options={"wake_sed": 3})


def test_training_draws_never_hit_the_held_out_set():
    vec = gym.make_vec(ENV_ID, num_envs=8, **QUICK)
    seen = set()
    for s in range(40):
        # An int seed s gives env i the seed s + i (gymnasium's convention): 8 s keeps them apart.
        _, info = vec.reset(seed=8 * s)
        seen.update(int(w) for w in info["wake_seed"])
    assert len(seen) == 320
    assert all(w in accd_gym.TRAINING_WAKE_SEEDS and w not in accd_gym.HELD_OUT_WAKE_SEEDS for w in seen)


def test_make_vec_is_native_with_next_step_autoreset():
    vec = gym.make_vec(ENV_ID, num_envs=3, **QUICK, boom={"capture_radius": 1e-6})
    assert isinstance(vec, accd_gym.InAirCaptureVectorEnv)
    assert vec.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    vec.reset(seed=2)
    a = np.zeros((3, 4), np.float32)
    for k in range(20):
        obs, r, term, trunc, info = vec.step(a)
    assert trunc.all() and not term.any()
    obs, r, term, trunc, info = vec.step(np.full((3, 4), 5.0, np.float32))
    assert (r == 0).all() and not (term | trunc).any()
    assert np.allclose(obs[:, -1], 1.0), "new episodes start with the whole window left"
    # The reset step reports the new episodes' reset info only (as SyncVectorEnv), no fake zeros.
    assert set(info) == {"wake_seed", "_wake_seed"} and info["_wake_seed"].all()


def test_same_step_autoreset_reports_final_observations():
    vec = gym.make_vec(ENV_ID, num_envs=2, autoreset_mode=AutoresetMode.SAME_STEP, **QUICK, boom={"capture_radius": 1e-6})
    assert vec.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    vec.reset(seed=4)
    for _ in range(20):
        obs, r, term, trunc, info = vec.step(np.zeros((2, 4), np.float32))
    assert trunc.all()
    assert info["_final_obs"].all() and info["final_obs"][0].shape == (OBS_DIM,)
    assert np.allclose(obs[:, -1], 1.0) and np.allclose([f[-1] for f in info["final_obs"]], 0.0, atol=1e-6)
    assert info["final_info"]["_distance"].all()


def test_vector_env_matches_single_envs_seed_for_seed():
    actions = [np.array([0.4, -0.1, np.cos(k), 0.2], np.float32) for k in range(10)]
    vec = gym.make_vec(ENV_ID, num_envs=3, num_threads=2, **QUICK)
    obs = vec.reset(seed=[7, 8, 9])[0].copy()  # the returned buffer is reused two calls later
    steps = [vec.step(np.tile(a, (3, 1)))[0].copy() for a in actions]
    single = gym.make(ENV_ID, **QUICK).unwrapped
    for i, s in enumerate([7, 8, 9]):
        o, _ = single.reset(seed=s)
        assert np.array_equal(o, obs[i])
        for k, a in enumerate(actions):
            o = single.step(a)[0]
            assert np.array_equal(o, steps[k][i]), (i, k)


def test_with_copy_false_buffers_are_written_in_place_and_double_buffered():
    vec = gym.make_vec(ENV_ID, num_envs=2, copy=False, **QUICK)
    vec.reset(seed=0)
    a = np.zeros((2, 4), np.float32)
    o1 = vec.step(a)[0]
    kept = o1.copy()
    o2 = vec.step(a)[0]
    assert o1 is not o2 and np.array_equal(o1, kept), "valid through the next step"
    o3 = vec.step(a)[0]
    assert o3 is o1, "the same numpy array is rewritten: no allocation per step"


def test_the_gil_is_released_while_the_batch_steps():
    vec = gym.make_vec(ENV_ID, num_envs=96, num_threads=1, **QUICK)
    vec.reset(seed=0)
    a = np.zeros((96, 4), np.float32)
    vec.step(a)
    done = threading.Event()

    def work():
        for _ in range(8):
            vec.step(a)
        done.set()

    counts = 0
    t0 = time.perf_counter()
    worker = threading.Thread(target=work)
    worker.start()
    while not done.is_set():
        counts += 1
    busy = time.perf_counter() - t0
    worker.join()
    t0 = time.perf_counter()
    solo = 0
    while time.perf_counter() - t0 < busy:
        solo += 1
    # With the GIL held during the step this thread would run only between steps (a small share).
    assert counts > 0.4 * solo, (counts, solo)


def test_state_snapshot_restores_exactly_and_envs_pickle():
    env = gym.make(ENV_ID, **QUICK).unwrapped
    env.reset(seed=3)
    for _ in range(5):
        env.step(np.array([0.5, 0.5, -0.3, 0.1], np.float32))
    state = env.get_state()
    copy = pickle.loads(pickle.dumps(env))
    actions = [np.array([np.sin(k), 0.2, 0.1, -0.4], np.float32) for k in range(10)]
    tail = [env.step(a) for a in actions]
    env.set_state(state)
    again = [env.step(a) for a in actions]
    from_pickle = [copy.step(a) for a in actions]
    for x, y, z in zip(tail, again, from_pickle):
        assert np.array_equal(x[0], y[0]) and np.array_equal(x[0], z[0])
        assert x[1:4] == y[1:4] == z[1:4]
    other = gym.make(ENV_ID, capture_window=3.0, initial={"settle_time": 20.0}).unwrapped
    # Every foreign state is a StateError naming what differs.
    with pytest.raises(accd_gym.StateError, match="another configuration"):
        other.set_state(state)

    vec = gym.make_vec(ENV_ID, num_envs=2, **QUICK)
    vec.reset(seed=1)
    vec.step(np.zeros((2, 4), np.float32))
    vcopy = pickle.loads(pickle.dumps(vec))
    a = np.full((2, 4), 0.3, np.float32)
    assert np.array_equal(vec.step(a)[0], vcopy.step(a)[0])


def test_rgb_array_renders_without_a_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    env = gym.make(ENV_ID, render_mode="rgb_array", **QUICK)
    env.reset(seed=0)
    env.step(np.zeros(4, np.float32))
    frame = env.render()
    assert frame.shape == (480, 640, 3) and frame.dtype == np.uint8
    assert frame.std() > 10, "a picture, not a blank canvas"
    vec = gym.make_vec(ENV_ID, num_envs=2, render_mode="rgb_array", **QUICK)
    vec.reset(seed=0)
    frames = vec.render()
    assert isinstance(frames, tuple) and len(frames) == 2
    assert all(f.shape == (480, 640, 3) and f.dtype == np.uint8 for f in frames)


def test_bad_input_gets_clear_errors():
    env = gym.make(ENV_ID, **QUICK).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="env 0") as e:
        env.step(np.array([0, np.nan, 0, 0], np.float32))
    assert isinstance(e.value, accd_gym.AccdError)
    with pytest.raises(accd_gym.StateError, match="numbers"):
        env.step(["a", "b", "c", "d"])
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3, np.float32))
    vec = gym.make_vec(ENV_ID, num_envs=3, **QUICK)
    vec.reset(seed=0)
    bad = np.zeros((3, 4), np.float32)
    bad[2, 1] = np.inf
    with pytest.raises(ValueError, match="env 2"):
        vec.step(bad)
    with pytest.raises(accd_gym.ConfigError, match="capture_windw"):
        gym.make(ENV_ID, capture_windw=3.0)
    with pytest.raises(accd_gym.ConfigError, match="agent_step"):
        gym.make(ENV_ID, agent_step=0.105)
    with pytest.raises(accd_gym.ConfigError, match="limits.max_tilt_deg"):
        gym.make(ENV_ID, limits={"max_tilt_deg": -1.0})
    with pytest.raises(accd_gym.ConfigError, match="num_envs"):
        gym.make_vec(ENV_ID, num_envs=0)
    assert issubclass(accd_gym.ConfigError, accd_gym.AccdError)


def test_out_of_range_actions_are_clipped():
    env = gym.make(ENV_ID, **QUICK).unwrapped
    big = [np.array([3.0, -9.0, 1.5, -1.0], np.float32)] * 5
    clipped = [np.clip(a, -1, 1) for a in big]
    assert same(rollout(env, big, 2), rollout(env, clipped, 2))


def test_a_diverging_episode_ends_with_a_flag_not_nan():
    # RK4 at 0.1 s is far beyond the stability limit of the tether's axial element;
    # the tether substeps through it, so the divergence comes from a stiff ACCD roll (a roll
    # damping far beyond any body's).
    table = json.loads(accd_gym.default_aero_table_json())
    table["damping"]["clp"] = -1e5
    env = gym.make(
        ENV_ID,
        tether={"time_step": 0.1},
        accd={"aero_table": json.dumps(table)},
        initial={"settle_time": 0.0},
        limits={"max_distance": 1e4},
    ).unwrapped
    env.reset(seed=0)
    for _ in range(50):
        obs, r, term, trunc, info = env.step(np.zeros(4, np.float32))
        assert np.isfinite(obs).all() and np.isfinite(r)
        if term:
            break
    assert info["diverged"] and "diverged" in info["divergence"] or "beyond" in info["divergence"]


def test_environment_doc_carries_the_cores_observation_table():
    from pathlib import Path

    from accd_gym.envs.task import observation_table_markdown

    doc = (Path(__file__).resolve().parents[1] / "docs" / "environment.md").read_text()
    assert observation_table_markdown() in doc


def test_config_docs_are_generated_from_the_declarations():
    """docs/environment.md and the three env docstrings carry the configuration table generated
    from the Rust declarations (one per field); regenerate the docs section with
    ``accd_gym.envs.config.config_table_markdown()`` when a declaration changes."""
    import re
    from pathlib import Path

    from accd_gym import _core
    from accd_gym.envs.config import config_table_markdown, default_config

    table = config_table_markdown()
    doc = (Path(__file__).resolve().parents[1] / "docs" / "environment.md").read_text()
    generated = re.search(r"<!-- generated: accd_gym\.envs\.config\.config_table_markdown\(\) -->\n(.*?)\n<!-- end generated -->", doc, re.S)
    assert generated and generated.group(1) == table
    for cls in (accd_gym.InAirCaptureEnv, accd_gym.InAirCaptureVectorEnv, accd_gym.AccdVecEnv):
        lines = [line.strip() for line in cls.__doc__.splitlines()]
        assert all(row in lines for row in table.splitlines()), cls.__name__
    # Every key of the configuration is declared, and every declared leaf key is in it.
    rows = _core.config_fields()
    keys = {key for key, *_ in rows}
    defaults = default_config()

    def leaves(d, prefix=""):
        for k, v in d.items():
            key = f"{prefix}{k}"
            yield key
            if isinstance(v, dict):
                yield from leaves(v, key + ".")

    assert set(leaves(defaults)) <= keys
    # The tether's model options and the sensors section are left out of the JSON at their
    # defaults (saved states keep their config hash); every other declared key is in the default
    # configuration.
    omitted = {"tether.elasticity", "tether.drag_velocity", "tether.scheme"} | {k for k in keys if k.split(".")[0] == "sensors"}
    assert set(leaves(defaults)) | omitted == keys
    assert len(omitted) > 2


def test_the_id_loads_through_gymnasiums_module_syntax():
    env = gym.make("accd_gym:accd_gym/InAirCapture-v0", **QUICK)
    assert isinstance(env.unwrapped, accd_gym.InAirCaptureEnv)


def test_observation_is_read_by_name():
    """The Python index constants come from the one Rust table; unknown names are refused."""
    from accd_gym.envs.task import OBSERVATION_INDEX, OBSERVATION_TABLE, observation_indices

    names = [row[0] for row in OBSERVATION_TABLE]
    assert list(observation_indices(*names)) == list(range(len(names)))
    assert list(OBSERVATION_INDEX) == names
    with pytest.raises(KeyError, match="boom_rel_w"):
        observation_indices("boom_rel_x", "boom_rel_w")


def test_python_code_reads_the_observation_by_name():
    """No numeric slices of the observation in the package (names, never indices)."""
    import re
    from pathlib import Path

    import accd_gym

    pattern = re.compile(r"\b(obs|o|observation|observations)\[[^\]]*\b\d+\s*:\s*\d+")
    offenders = []
    for path in Path(accd_gym.__file__).parent.rglob("*.py"):
        for no, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line):
                offenders.append(f"{path.name}:{no}: {line.strip()}")
    assert not offenders, offenders


@pytest.mark.parametrize("make", ["single", "vector", "sb3"])
def test_an_env_construction_validates_its_config_once(make):
    """The configuration is validated once per env construction (it used to be eight
    times), from one crossing of the keyword arguments into Rust."""
    from accd_gym import _core
    from accd_gym.envs.sb3 import AccdVecEnv
    from accd_gym.envs.vector import InAirCaptureVectorEnv

    kwargs = {"capture_window": 1.0, "initial": {"settle_time": 1.0}}
    before = _core.validation_passes()
    if make == "single":
        env = accd_gym.InAirCaptureEnv(**kwargs)
    elif make == "vector":
        env = InAirCaptureVectorEnv(num_envs=3, **kwargs)
    else:
        env = AccdVecEnv(num_envs=3, **kwargs)
    assert _core.validation_passes() - before == 1
    env.close()


def test_the_validated_config_object_pickles_and_compares():
    import pickle

    from accd_gym.envs.config import valid_config

    a = valid_config(capture_window=5.0)
    b = pickle.loads(pickle.dumps(a))
    assert a == b and b.episode_steps == 50
    assert json.loads(b.to_json())["capture_window"] == 5.0
    assert a != valid_config(capture_window=6.0)
    with pytest.raises(accd_gym.ConfigError, match="capture_window"):
        valid_config(capture_window=-1.0)
