"""Counts (``num_envs``, ``num_threads``, ``steps``, env indices, episode counts) are Python or
numpy integers in their range, never truncated or parsed, with a ``ConfigError`` naming the
argument, the value and the range; seeds never leave the one seed range [0, 2^63): a vector
env's int seed ``s`` gives env ``i`` the seed ``s + i``, and an ``s`` for which that passes
2^63 - 1 is refused, as a
``SyncVectorEnv`` of single envs refuses it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

import accd_gym
from accd_gym import ENV_ID, ConfigError, _core
from accd_gym.envs.config import valid_config
from accd_gym.envs.task import MAX_ENVS, MAX_THREADS

QUICK = dict(capture_window=2.0, initial={"settle_time": 20.0})
#: Not integers (a float, a string, bools), or integers out of every count's range.
NOT_COUNTS = ["3", 2.7, 2.0, True, np.bool_(True), None, np.float64(2.0), -1, 2**64, 2**70]

VECTOR_ENVS = {
    "InAirCaptureVectorEnv": lambda n, **kw: accd_gym.InAirCaptureVectorEnv(n, **QUICK, **kw),
    "make_vec": lambda n, **kw: gym.make_vec(ENV_ID, num_envs=n, **QUICK, **kw),
    "AccdVecEnv": lambda n, **kw: accd_gym.AccdVecEnv(n, **QUICK, **kw),
}


@pytest.mark.parametrize("make", VECTOR_ENVS.values(), ids=VECTOR_ENVS.keys())
@pytest.mark.parametrize("bad", NOT_COUNTS + [0, MAX_ENVS + 1], ids=repr)
def test_num_envs_is_an_integer_in_range(make, bad):
    with pytest.raises(ConfigError, match=rf"`num_envs` = .* allowed range: an integer in \[1, {MAX_ENVS}\]"):
        make(bad)


@pytest.mark.parametrize("make", VECTOR_ENVS.values(), ids=VECTOR_ENVS.keys())
@pytest.mark.parametrize("bad", NOT_COUNTS + [MAX_THREADS + 1], ids=repr)
def test_num_threads_is_an_integer_in_range(make, bad):
    with pytest.raises(ConfigError, match=rf"`num_threads` = .* allowed range: an integer in \[0, {MAX_THREADS}\]"):
        make(2, num_threads=bad)


@pytest.mark.parametrize("make", VECTOR_ENVS.values(), ids=VECTOR_ENVS.keys())
def test_numpy_integer_counts_are_accepted(make):
    env = make(np.uint8(3), num_threads=np.int64(1))
    assert env.num_envs == 3 and type(env.num_envs) is int
    assert env.num_threads == 1


@pytest.mark.parametrize("bad", NOT_COUNTS, ids=repr)
def test_the_native_batch_checks_its_counts_and_seed_itself(bad):
    valid = valid_config(dict(QUICK))
    with pytest.raises(ConfigError, match="`num_envs`"):
        _core.BatchEnv(valid, bad, 0)
    if bad is not None:  # (None: the binding's default thread count)
        with pytest.raises(ConfigError, match="`num_threads`"):
            _core.BatchEnv(valid, 2, 0, "same_step", bad)
    with pytest.raises(ConfigError, match="`seed`"):
        _core.BatchEnv(valid, 2, bad)
    core = _core.BatchEnv(valid, 2, 0)
    core.reset(0)
    with pytest.raises(ConfigError, match="`steps`"):
        core.time_rust_steps(np.zeros((2, 4), np.float32), bad)


@pytest.mark.parametrize("bad", [b for b in NOT_COUNTS if b is not None], ids=repr)
def test_capture_sim_and_tether_steps_are_integers_in_range(bad):
    sim = accd_gym.CaptureSim(calm=True)
    with pytest.raises(ConfigError, match=r"`steps` = .* allowed range: an integer in \[0, 2\^64 - 1\]"):
        sim.step(steps=bad)
    assert sim.time == 0.0
    tether = accd_gym.Tether()
    with pytest.raises(ConfigError, match=r"`steps` = .* allowed range: an integer in \[0, 2\^64 - 1\]"):
        tether.step(bad)
    assert tether.time == 0.0


def test_capture_sim_and_tether_step_numpy_integer_counts_and_default_to_one():
    sim = accd_gym.CaptureSim(calm=True)
    dt = sim.time_step
    sim.step(steps=np.int64(2))
    sim.step()
    sim.step(steps=0)
    sim.step(steps=None)  # None: the default
    assert sim.time == pytest.approx(4 * dt)
    tether = accd_gym.Tether()
    tether.step(np.uint16(2))
    tether.step()
    tether.step(None)
    assert tether.time == pytest.approx(4 * tether.time_step)


@pytest.mark.parametrize("bad", ["0", 0.0, True, -1, 2, 2**64], ids=repr)
def test_env_indices_are_integers_in_range(bad):
    env = accd_gym.InAirCaptureVectorEnv(2, **QUICK)
    env.reset(seed=1)
    for call in (env.episode_parameters, env.episode_setup, lambda i: env.start_episode(i, 5)):
        with pytest.raises(ConfigError, match=r"`i` = .* allowed range: an integer in \[0, 1\]"):
            call(bad)
    assert env.episode_setup(np.int32(1))["equilibrium"].shape == (3,)


@pytest.mark.parametrize("bad", ["2", 2.5, True, 0], ids=repr)
def test_evaluation_counts_are_integers(bad):
    from accd_gym.control.baselines import GuidancePolicy
    from accd_gym.evals.episodes import run_episode_range, run_episodes

    with pytest.raises(ConfigError, match="`num_envs`"):
        run_episodes(GuidancePolicy(), 2, num_envs=bad, config=QUICK)
    with pytest.raises(ConfigError, match="`episodes`"):
        run_episodes(GuidancePolicy(), bad, config=QUICK)
    with pytest.raises(ConfigError, match="`batch`"):
        run_episode_range(GuidancePolicy(), 0, 2, batch=bad, config=QUICK)
    with pytest.raises(ConfigError, match="`num_envs`"):
        accd_gym.record_episodes(GuidancePolicy(), episodes=1, num_envs=bad, config=QUICK)


TOP = 2**63 - 1


def test_a_vector_int_seed_near_the_top_seeds_env_i_with_s_plus_i_as_sync_vector_env():
    native = gym.make_vec(ENV_ID, num_envs=2, **QUICK)
    reference = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync", **QUICK)
    actions = np.full((2, 4), 0.2, np.float32)
    out_native = [native.reset(seed=TOP - 1), native.step(actions)]
    out_reference = [reference.reset(seed=TOP - 1), reference.step(actions)]
    assert data_equivalence(out_native, out_reference, exact=True)
    assert native.np_random_seed == reference.np_random_seed == (TOP - 1, TOP)


@pytest.mark.parametrize("n, seed", [(2, TOP), (3, TOP - 1), (2, 2**63 + 5)])
def test_a_vector_int_seed_that_would_wrap_is_refused_and_changes_nothing(n, seed):
    native = accd_gym.InAirCaptureVectorEnv(n, **QUICK)
    reference = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="sync", **QUICK)
    native.reset(seed=7)
    before = native.get_state(), native.np_random_seed
    with pytest.raises(ConfigError, match=r"`seed` = \d+ is outside the allowed range"):
        native.reset(seed=seed)
    assert (native.get_state(), native.np_random_seed) == before
    # The reference raises the same error class from the single env whose seed passes 2^63 - 1.
    with pytest.raises(ConfigError, match="`seed`"):
        reference.reset(seed=seed)


def test_the_refusal_names_the_range_for_the_batch_size():
    env = accd_gym.InAirCaptureVectorEnv(4, **QUICK)
    with pytest.raises(ConfigError, match=rf"\[0, 2\^63 - num_envs\] = \[0, {2**63 - 4}\] for num_envs = 4"):
        env.reset(seed=2**63 - 3)
    env.reset(seed=2**63 - 4)
    assert env.np_random_seed[-1] == TOP
    # Per-env seeds are each in the seed range: the top one is fine.
    env.reset(seed=[TOP, 0, 1, TOP])
    with pytest.raises(ConfigError, match="`seed`"):
        env.reset(seed=[2**63, 0, 1, 2])


def test_accd_vec_env_seeds_never_wrap():
    env = accd_gym.AccdVecEnv(2, **QUICK)
    assert env.seed(TOP - 1) == [TOP - 1, TOP]
    env.reset()
    for bad in (TOP, 2**63):
        with pytest.raises(ConfigError, match="`seed`"):
            env.seed(bad)
        with pytest.raises(ConfigError, match="`seed`"):
            accd_gym.AccdVecEnv(2, seed=bad, **QUICK)
    accd_gym.AccdVecEnv(1, seed=TOP, **QUICK)


def test_the_native_batch_refuses_a_wrapping_base_seed():
    core = _core.BatchEnv(valid_config(dict(QUICK)), 2, TOP - 1)
    core.reset(TOP - 1)
    with pytest.raises(ConfigError, match="`seed` = 9223372036854775807"):
        core.reset(TOP)
    with pytest.raises(ConfigError, match="`seed`"):
        _core.BatchEnv(valid_config(dict(QUICK)), 2, TOP)
    with pytest.raises(ConfigError, match="`seed`"):
        core.reset([0, True])
