"""Gymnasium's own env and vector tests that apply to a third-party env, in our words, against our
ids: the checkers with warnings as errors, same-seed determinism, pickling, out-of-bound actions,
the spec (``max_episode_steps``, wrappers that need it), ``make_vec`` in every vectorisation mode,
autoreset metadata, partial resets and their errors, action counts, vector wrappers, and
``check_environments_match``. (Gymnasium's ``tests/envs/test_envs.py``,
``tests/envs/test_action_dim_check.py``, ``tests/envs/registration/test_make_vec.py`` and
``tests/vector/test_{vector_env,autoreset_mode,vector_wrapper}.py``.)
"""

import pickle
import re
import warnings

import numpy as np
import pytest
import gymnasium as gym
from gymnasium.utils.env_checker import check_env, data_equivalence
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import accd_gym
from accd_gym import ENV_ID

QUICK = dict(capture_window=2.0, initial={"settle_time": 20.0})


def test_env_checker_with_render_check_and_passive_checker_raise_no_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(ENV_ID, render_mode="rgb_array", **QUICK)
        check_env(env.unwrapped)
        env = gym.make(ENV_ID, **QUICK)  # with the passive checker of gym.make
        env.reset(seed=0)
        env.step(env.action_space.sample())
        env.close()


def test_same_seed_gives_the_same_rollout_across_resets():
    a, b = gym.make(ENV_ID, **QUICK), gym.make(ENV_ID, **QUICK)
    assert data_equivalence(a.reset(seed=0), b.reset(seed=0), exact=True)
    a.action_space.seed(0)
    for k in range(50):
        action = a.action_space.sample()
        out_a, out_b = a.step(action), b.step(action)
        assert data_equivalence(out_a, out_b, exact=True), k
        assert a.observation_space.contains(out_a[0])
        if out_a[2] or out_a[3]:
            a.reset(seed=0)
            b.reset(seed=0)


def test_a_pickled_env_resets_and_steps_as_the_original():
    env = gym.make(ENV_ID, **QUICK)
    action = env.action_space.sample()
    original = (env.reset(seed=123), env.step(action))
    copy = pickle.loads(pickle.dumps(env))
    assert data_equivalence(original, (copy.reset(seed=123), copy.step(action)), exact=True)
    vec = gym.make_vec(ENV_ID, num_envs=2, **QUICK)
    actions = vec.action_space.sample()
    original = (vec.reset(seed=5), vec.step(actions))
    copy = pickle.loads(pickle.dumps(vec))
    assert data_equivalence(original, (copy.reset(seed=5), copy.step(actions)), exact=True)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_out_of_bound_actions_act_as_the_bound(sign):
    env, oob = gym.make(ENV_ID, **QUICK), gym.make(ENV_ID, disable_env_checker=True, **QUICK)
    env.reset(seed=42)
    oob.reset(seed=42)
    bound = env.action_space.high if sign > 0 else env.action_space.low
    for i in range(4):
        action = bound.copy()
        action[i] += np.float32(sign * 2.0)
        a, b = env.step(bound), oob.step(action)
        assert np.all(a[0] == b[0]) and a[1] == b[1], i


def test_the_spec_has_max_episode_steps_and_time_aware_observation_accepts_the_env():
    spec = gym.spec(ENV_ID)
    assert spec.max_episode_steps == 700 == round(70.0 / 0.1)
    env = gym.wrappers.TimeAwareObservation(gym.make(ENV_ID, **QUICK))
    obs, _ = env.reset(seed=0)
    assert obs.shape == (26,)
    obs, *_ = env.step(np.zeros(4, np.float32))
    assert obs[-1] == 1
    # A time limit shorter than the capture window is refused, not silently different.
    with pytest.raises(accd_gym.ConfigError, match="max_episode_steps"):
        gym.make_vec(ENV_ID, num_envs=2, capture_window=100.0)
    vec = gym.make_vec(ENV_ID, num_envs=2, capture_window=100.0, max_episode_steps=1000)
    assert vec.num_envs == 2


@pytest.mark.parametrize("mode", ["vector_entry_point", "sync", "async"])
def test_make_vec_in_every_vectorization_mode(mode):
    env = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode=mode, **QUICK)
    assert env.num_envs == 2
    assert env.observation_space == gym.vector.utils.batch_space(env.single_observation_space, 2)
    assert env.action_space == gym.vector.utils.batch_space(env.single_action_space, 2)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert info["wake_seed"].dtype == np.int64
    obs, reward, term, trunc, info = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs) and reward.dtype == np.float64
    assert term.dtype == trunc.dtype == np.bool_
    env.close()


def test_make_vec_refuses_wrappers_for_the_native_vector_env_and_passes_the_render_mode():
    with pytest.raises(gym.error.Error):
        gym.make_vec(ENV_ID, num_envs=2, wrappers=[gym.wrappers.ClipAction], **QUICK)
    env = gym.make_vec(ENV_ID, num_envs=2, render_mode="rgb_array", **QUICK)
    assert env.render_mode == "rgb_array"


@pytest.mark.parametrize("mode", list(AutoresetMode))
@pytest.mark.parametrize("how", ["enum", "value", "snake_case"])
def test_autoreset_mode_is_declared_in_metadata(mode, how):
    given = {"enum": mode, "value": mode.value, "snake_case": {"NextStep": "next_step", "SameStep": "same_step", "Disabled": "disabled"}[mode.value]}[how]
    env = gym.make_vec(ENV_ID, num_envs=2, autoreset_mode=given, **QUICK)
    assert env.metadata["autoreset_mode"] is mode
    sync = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **QUICK)
    assert sync.metadata["autoreset_mode"] is mode


def test_same_step_final_obs_is_the_ended_episodes_last_observation():
    env = gym.make_vec(ENV_ID, num_envs=2, autoreset_mode=AutoresetMode.SAME_STEP, **QUICK)
    env.reset(seed=1)
    last = None
    for _ in range(20):
        obs, _, term, trunc, info = env.step(np.zeros((2, 4), np.float32))
        if not (term | trunc).any():
            last = obs.copy()
    assert (term | trunc).all() and info["_final_obs"].all()
    for i in range(2):
        assert info["final_obs"][i][-1] == pytest.approx(0.0, abs=1e-6)  # no time left
        assert not np.array_equal(info["final_obs"][i], last[i])
        assert obs[i][-1] == 1.0  # the new episode's first observation


def test_partial_reset_restarts_the_selected_envs_only():
    env = gym.make_vec(ENV_ID, num_envs=3, autoreset_mode=AutoresetMode.DISABLED, **QUICK)
    reset_obs, _ = env.reset(seed=[0, 1, 2])
    reset_obs = reset_obs.copy()
    env.action_space.seed(123)
    for _ in range(3):
        step_obs, *_ = env.step(env.action_space.sample())
    step_obs = step_obs.copy()
    obs, info = env.reset(seed=[0, 1, 0], options={"reset_mask": np.array([True, True, False])})
    assert np.all(obs[:2] == reset_obs[:2]) and np.all(obs[2] == step_obs[2])
    assert info["_wake_seed"].tolist() == [True, True, False]


def test_partial_reset_errors_match_gymnasium():
    env = gym.make_vec(ENV_ID, num_envs=3, autoreset_mode=AutoresetMode.DISABLED, **QUICK)
    env.reset(options={"reset_mask": np.array([True, True, True])})
    for mask, error, message in [
        (np.array([True]), ValueError, "`options['reset_mask']` must have shape `(3,)`, got (1,)"),
        (np.array([True, True, False, False]), ValueError, "`options['reset_mask']` must have shape `(3,)`, got (4,)"),
        (np.array([[True, True, True]]), ValueError, "`options['reset_mask']` must have shape `(3,)`, got (1, 3)"),
        (np.array([False, False, False]), ValueError, "must contain a boolean array with at least one True value, got reset_mask=[False False False]"),
        (np.array([1, 1, 0]), TypeError, "`options['reset_mask']` must have `dtype=np.bool_`, got int64"),
        (np.array([1.0, 1.0, 0.0]), TypeError, "`options['reset_mask']` must have `dtype=np.bool_`, got float64"),
    ]:
        with pytest.raises(error, match=re.escape(message)):
            env.reset(options={"reset_mask": mask})


def test_a_wrong_number_of_actions_is_refused():
    env = gym.make_vec(ENV_ID, num_envs=4, autoreset_mode=AutoresetMode.DISABLED, **QUICK)
    env.reset()
    for n in (1, 3, 5):
        with pytest.raises(ValueError):
            env.step(np.zeros((n, 4), np.float32))
    env.step(np.zeros((4, 4), np.float32))


def test_gymnasium_vector_wrappers_work_on_the_native_vector_env():
    from gymnasium.wrappers import vector as vw

    env = gym.make_vec(ENV_ID, num_envs=2, **QUICK)
    env = vw.ClipAction(vw.NormalizeObservation(vw.RecordEpisodeStatistics(env)))
    env = vw.DictInfoToList(env)
    env.reset(seed=0)
    episodes = 0
    for _ in range(25):
        _, _, term, trunc, infos = env.step(np.full((2, 4), 3.0, np.float32))
        assert isinstance(infos, list) and len(infos) == 2
        episodes += sum("episode" in i for i in infos)
    assert episodes == 2
    assert env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP


def test_check_environments_match_between_make_and_the_class():
    from gymnasium.utils.env_match import check_environments_match

    check_environments_match(
        gym.make(ENV_ID, **QUICK), accd_gym.InAirCaptureEnv(**QUICK), num_steps=40, seed=3, skip_render=True
    )


def test_sync_vector_env_of_the_native_vector_envs_sub_envs_is_equal_at_reset():
    """``SyncVectorEnv`` of ``gym.make`` thunks and the native env agree on int seeds (s + i)."""
    native = gym.make_vec(ENV_ID, num_envs=3, **QUICK)
    sync = SyncVectorEnv([lambda: gym.make(ENV_ID, **QUICK) for _ in range(3)])
    assert data_equivalence(native.reset(seed=42), sync.reset(seed=42), exact=True)
    assert data_equivalence(native.reset(seed=np.int64(42)), sync.reset(seed=42), exact=True)
