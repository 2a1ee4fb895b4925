"""The native vector envs are indistinguishable from the reference implementations.

``InAirCaptureVectorEnv`` against gymnasium's own ``SyncVectorEnv`` of single envs, and
``AccdVecEnv`` against stable-baselines3's ``DummyVecEnv``: step by step, with gymnasium's own
``data_equivalence`` (exact), observations, rewards, flags and infos (dtypes included), across
automatic resets (captures, envelope exits and truncations at different steps), in every
autoreset mode gymnasium defines, with partial resets (``reset_mask``).
"""

import numpy as np
import pytest
import gymnasium as gym
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import accd_gym
from accd_gym import ENV_ID

N = 4
# Short episodes, and a tight envelope so that random flaps end episodes at different steps
# (envelope exits) while others run to the end of the window (truncations).
CONFIG = dict(capture_window=2.5, initial={"settle_time": 20.0}, limits={"max_distance": 16.0})


def assert_same(native, reference, what):
    assert data_equivalence(native, reference, exact=True), f"{what}:\nnative    {native!r}\nreference {reference!r}"


def pair(mode):
    native = gym.make_vec(ENV_ID, num_envs=N, vectorization_mode="vector_entry_point", autoreset_mode=mode, **CONFIG)
    reference = gym.make_vec(
        ENV_ID, num_envs=N, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **CONFIG
    )
    assert isinstance(native, accd_gym.InAirCaptureVectorEnv) and isinstance(reference, SyncVectorEnv)
    assert native.metadata["autoreset_mode"] == reference.metadata["autoreset_mode"] == mode
    return native, reference


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED])
def test_native_vector_env_steps_exactly_as_sync_vector_env(mode):
    native, reference = pair(mode)
    rng = np.random.default_rng(3)
    ended = {"terminated": 0, "truncated": 0, "partial": 0}
    resets = [
        dict(seed=[11, 12, 13, 14]),
        dict(seed=21, options={"wake_seed": 77}),
        dict(seed=None, options={"wake_seed": None}),
    ]
    for reset in resets:
        out_n, out_r = native.reset(**reset), reference.reset(**reset)
        assert_same(out_n, out_r, f"reset {reset}")
        done = np.zeros(N, dtype=bool)
        for k in range(60):
            actions = rng.uniform(-1.0, 1.0, size=(N, 4)).astype(np.float32)
            if mode == AutoresetMode.DISABLED and done.any():
                mask = done.copy()
                out_n = native.reset(options={"reset_mask": mask.copy()})
                out_r = reference.reset(options={"reset_mask": mask.copy()})
                assert_same(out_n, out_r, f"step {k}: reset_mask {mask}")
            elif k % 29 == 28:
                # A partial reset in the middle of episodes (and of a pending autoreset), with
                # per-env seeds of which only the selected envs' count.
                mask = rng.random(N) < 0.5
                mask[k % N] = True
                seeds = [int(s) for s in rng.integers(0, 1000, N)]
                out_n = native.reset(seed=seeds, options={"reset_mask": mask.copy()})
                out_r = reference.reset(seed=seeds, options={"reset_mask": mask.copy()})
                assert_same(out_n, out_r, f"step {k}: partial reset {mask}")
                ended["partial"] += 1
            out_n, out_r = native.step(actions), reference.step(actions)
            for name, a, b in zip(("obs", "reward", "terminated", "truncated", "info"), out_n, out_r):
                assert_same(a, b, f"reset {reset}, step {k}: {name}")
            done = out_r[2] | out_r[3]
            ended["terminated"] += int(out_r[2].sum())
            ended["truncated"] += int(out_r[3].sum())
    assert ended["terminated"] >= 3 and ended["truncated"] >= 3, ended
    native.close()
    reference.close()


def test_disabled_autoreset_refuses_to_step_an_ended_env_like_sync_vector_env():
    native, reference = pair(AutoresetMode.DISABLED)
    native.reset(seed=5)
    reference.reset(seed=5)
    zeros = np.zeros((N, 4), np.float32)
    done = np.zeros(N, dtype=bool)
    while not done.any():
        _, _, term, trunc, _ = native.step(zeros)
        reference.step(zeros)
        done = term | trunc
    with pytest.raises(accd_gym.StateError, match="reset"):
        native.step(zeros)
    with pytest.raises(AssertionError):
        reference.step(zeros)


def _gymnasium_checks_with_asserts() -> bool:
    """gymnasium before 1.3 checks ``reset_mask`` with ``assert`` statements (AssertionError);
    1.3 and later raise TypeError / ValueError. Ray 2.60's RLlib pins gymnasium 1.2.2."""
    major, minor = (int(x) for x in gym.__version__.split(".")[:2])
    return (major, minor) < (1, 3)


def test_reset_mask_is_checked_as_sync_vector_env_checks_it():
    native, reference = pair(AutoresetMode.NEXT_STEP)
    for bad, error in [
        ([True] * N, TypeError),
        (np.ones(N + 1, dtype=bool), ValueError),
        (np.ones(N, dtype=np.int8), TypeError),
        (np.zeros(N, dtype=bool), ValueError),
    ]:
        # The native env raises gymnasium 1.3's TypeError / ValueError whatever gymnasium is installed.
        with pytest.raises(error):
            native.reset(options={"reset_mask": bad})
        with pytest.raises(AssertionError if _gymnasium_checks_with_asserts() else error):
            reference.reset(options={"reset_mask": bad})


def dummy_vec_env():
    from stable_baselines3.common.vec_env import DummyVecEnv

    return DummyVecEnv([lambda: gym.make(ENV_ID, **CONFIG) for _ in range(N)])


def test_accd_vec_env_steps_exactly_as_dummy_vec_env():
    native = accd_gym.AccdVecEnv(N, **CONFIG)
    reference = dummy_vec_env()
    rng = np.random.default_rng(8)
    dones_seen = 0
    for seed, options in [(31, None), (None, {"wake_seed": 123}), (40, {"wake_seeds": [5]})]:
        for env in (native, reference):
            if seed is not None:
                assert_same(native.seed(seed), reference.seed(seed), "seed()")
            env.set_options(options)
        assert_same(native.reset(), reference.reset(), f"reset {seed}")
        assert_same(native.reset_infos, reference.reset_infos, f"reset_infos {seed}")
        for k in range(60):
            actions = rng.uniform(-1.0, 1.0, size=(N, 4)).astype(np.float32)
            out_n = native.step(actions)
            out_r = reference.step(actions)
            for name, a, b in zip(("obs", "rewards", "dones", "infos"), out_n, out_r):
                assert_same(a, b, f"seed {seed}, step {k}: {name}")
            assert_same(native.reset_infos, reference.reset_infos, f"seed {seed}, step {k}: reset_infos")
            dones_seen += int(out_r[2].sum())
    assert dones_seen >= 10


def test_a_wake_seed_list_is_covered_by_the_batch_with_list_seeds_too():
    """With per-env seeds every env took the same entry, skipping most of it."""
    vec = accd_gym.InAirCaptureVectorEnv(3, **CONFIG)
    wakes = list(range(1_000_000_000, 1_000_000_009))
    _, info = vec.reset(seed=[10, 11, 12], options={"wake_seeds": wakes})
    seen = [info["wake_seed"].tolist()]
    _, info = vec.reset()
    seen.append(info["wake_seed"].tolist())
    assert seen == [wakes[0:3], wakes[3:6]]
    assert info["wake_seed"].dtype == np.int64


# RK4 at 0.1 s with a roll damping far beyond any body's: the ACCD's rate equation is stiff and the
# episodes diverge (the tether itself substeps through a 0.1 s step since the reliability work).
def _stiff_roll_table() -> str:
    import json

    table = json.loads(accd_gym.default_aero_table_json())
    table["damping"]["clp"] = -1e5
    return json.dumps(table)


DIVERGING = dict(
    tether={"time_step": 0.1},
    accd={"aero_table": _stiff_roll_table()},
    initial={"settle_time": 0.0},
    limits={"max_distance": 1e4},
)


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_diverging_episodes_report_as_sync_vector_env_reports_them(mode):
    native = gym.make_vec(ENV_ID, num_envs=2, autoreset_mode=mode, **DIVERGING)
    reference = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **DIVERGING)
    assert_same(native.reset(seed=[0, 1]), reference.reset(seed=[0, 1]), "reset")
    messages = 0
    for k in range(60):
        actions = np.zeros((2, 4), np.float32)
        out_n, out_r = native.step(actions), reference.step(actions)
        for name, a, b in zip(("obs", "reward", "terminated", "truncated", "info"), out_n, out_r):
            assert_same(a, b, f"step {k}: {name}")
        info = out_r[4].get("final_info", out_r[4])
        messages += sum(isinstance(m, str) and len(m) > 0 for m in info.get("divergence", []))
    assert messages >= 2


def test_diverging_episodes_report_as_dummy_vec_env_reports_them():
    from stable_baselines3.common.vec_env import DummyVecEnv

    native = accd_gym.AccdVecEnv(2, **DIVERGING)
    reference = DummyVecEnv([lambda: gym.make(ENV_ID, **DIVERGING) for _ in range(2)])
    native.seed(4)
    reference.seed(4)
    assert_same(native.reset(), reference.reset(), "reset")
    messages = 0
    for k in range(60):
        actions = np.zeros((2, 4), np.float32)
        out_n, out_r = native.step(actions), reference.step(actions)
        for name, a, b in zip(("obs", "rewards", "dones", "infos"), out_n, out_r):
            assert_same(a, b, f"step {k}: {name}")
        messages += sum(isinstance(i.get("divergence"), str) for i in out_r[3])
    assert messages >= 2


def test_np_random_seed_reports_each_envs_seed_as_sync_vector_env_does():
    native, reference = pair(AutoresetMode.NEXT_STEP)
    assert len(native.np_random_seed) == N
    for kwargs in (
        {"seed": 11},
        {},
        {"seed": [3, 9, 27, 81]},
        {"seed": 40, "options": {"reset_mask": np.array([True, False, True, False])}},
    ):
        native.reset(**kwargs)
        reference.reset(**kwargs)
        assert native.np_random_seed == reference.np_random_seed, kwargs
    native.close()
    reference.close()


def _make_copying(kind, **kw):
    if kind == "gymnasium":
        return gym.make_vec(ENV_ID, num_envs=2, **CONFIG, **kw)
    return accd_gym.AccdVecEnv(2, **CONFIG, **kw)


def _arrays(obj) -> list:
    """Every numpy array in ``obj`` (nested tuples, lists and dicts)."""
    if isinstance(obj, np.ndarray):
        return [obj]
    items = obj.values() if isinstance(obj, dict) else obj if isinstance(obj, (tuple, list)) else ()
    return [a for item in items for a in _arrays(item)]


@pytest.mark.parametrize("kind", ["gymnasium", "sb3"])
def test_returned_arrays_are_new_and_never_change_later_by_default(kind):
    import copy

    env = _make_copying(kind)
    assert env.copy is True
    kept, snapshots = [], []
    kept.append(env.reset(seed=3) if kind == "gymnasium" else env.reset())
    snapshots.append(copy.deepcopy(kept[-1]))
    for _ in range(5):
        kept.append(env.step(np.full((2, 4), 0.3, np.float32)))
        snapshots.append(copy.deepcopy(kept[-1]))
    for k, (a, b) in enumerate(zip(kept, snapshots)):
        assert_same(a, b, f"returned object {k}")
    arrays = _arrays(kept)
    assert len(arrays) >= 1 + 5 * 3
    assert not any(np.shares_memory(a, b) for i, a in enumerate(arrays) for b in arrays[i + 1:])


@pytest.mark.parametrize("kind", ["gymnasium", "sb3"])
def test_copy_false_returns_the_in_place_buffers_valid_through_the_next_call(kind):
    env = _make_copying(kind, copy=False)
    assert env.copy is False
    first = env.reset(seed=3) if kind == "gymnasium" else env.reset()
    obs = [first[0] if kind == "gymnasium" else first]
    saved = [obs[0].copy()]
    for k in range(4):
        obs.append(env.step(np.full((2, 4), 0.3, np.float32))[0])
        assert np.array_equal(obs[-2], saved[-1]), f"step {k}: the previous call's array is intact"
        saved.append(obs[-1].copy())
    # Two buffers, used alternately by reset and step.
    assert all(np.shares_memory(obs[k], obs[k + 2]) for k in range(3))
    assert not any(np.shares_memory(obs[k], obs[k + 1]) for k in range(4))
    assert not np.array_equal(obs[1], saved[1]), "overwritten two calls later"


def test_copy_must_be_a_bool_and_survives_pickling():
    import pickle

    for bad in (0, 1, "yes", None):
        with pytest.raises(accd_gym.ConfigError, match="`copy`"):
            accd_gym.InAirCaptureVectorEnv(2, copy=bad, **CONFIG)
        with pytest.raises(accd_gym.ConfigError, match="`copy`"):
            accd_gym.AccdVecEnv(2, copy=bad, **CONFIG)
    assert pickle.loads(pickle.dumps(accd_gym.InAirCaptureVectorEnv(2, copy=False, **CONFIG))).copy is False
    assert pickle.loads(pickle.dumps(accd_gym.AccdVecEnv(2, copy=False, **CONFIG))).copy is False
