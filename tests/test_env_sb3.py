"""The native stable-baselines3 VecEnv: same-step autoreset conventions, VecMonitor and
VecNormalize, seeding and options on automatic resets, PPO and SAC learning, pickling."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import accd_gym

#: Short episodes (2 s = 20 agent steps) and a quick equilibrium, for tests.
QUICK = {"capture_window": 2.0, "initial": {"settle_time": 20.0}}


def make(n=2, **kw):
    return accd_gym.AccdVecEnv(num_envs=n, num_threads=1, **{**QUICK, **kw})


def test_is_an_sb3_vecenv_with_same_step_autoreset():
    from stable_baselines3.common.vec_env import VecEnv

    env = make(2, boom={"capture_radius": 1e-6})
    assert isinstance(env, VecEnv)
    env.seed(3)
    obs = env.reset()
    assert obs.shape == (2, 25) and obs.dtype == np.float32
    for k in range(20):
        obs, rew, done, infos = env.step(np.zeros((2, 4), np.float32))
        assert rew.dtype == np.float32 and done.dtype == bool and len(infos) == 2
        assert done.all() == (k == 19)
    for i in range(2):
        assert infos[i]["TimeLimit.truncated"] is True
        term = infos[i]["terminal_observation"]
        assert term.shape == (25,) and abs(term[-1]) < 1e-6 and not np.shares_memory(term, obs)
    assert np.allclose(obs[:, -1], 1.0), "the returned observation starts the next episode"


def test_seed_and_options_apply_on_automatic_resets():
    env = make(2, boom={"capture_radius": 1e-6})
    env.seed(5)
    env.set_options({"wake_seeds": [1_000_000_000, 1_000_000_001, 1_000_000_002]})
    env.reset()
    assert [i["wake_seed"] for i in env.reset_infos] == [1_000_000_000, 1_000_000_001]
    seen = []
    for _ in range(21):
        _, _, done, infos = env.step(np.zeros((2, 4), np.float32))
        seen.append([i["wake_seed"] for i in infos])
    assert seen[20] == [1_000_000_002, 1_000_000_000], "autoreset episodes follow the list"

    a, b = make(2), make(2)
    a.seed(11)
    b.seed(11)
    oa, ob = a.reset(), b.reset()
    assert np.array_equal(oa, ob)
    for k in range(25):
        act = np.full((2, 4), np.sin(k), np.float32)
        ra, rb = a.step(act), b.step(act)
        assert np.array_equal(ra[0], rb[0]) and np.array_equal(ra[1], rb[1])


def test_bad_actions_name_the_env_and_nothing_panics():
    env = make(3)
    env.reset()
    bad = np.zeros((3, 4), np.float32)
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match="env 1"):
        env.step(bad)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros((2, 4), np.float32))
    with pytest.raises(accd_gym.ConfigError, match="bogus"):
        make(2, bogus=1)


def test_works_under_vecmonitor_and_vecnormalize():
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    env = VecNormalize(VecMonitor(make(2, boom={"capture_radius": 1e-6})), norm_obs=True, norm_reward=True)
    env.seed(0)
    env.reset()
    episodes = []
    for _ in range(45):
        obs, rew, done, infos = env.step(np.random.default_rng(0).uniform(-1, 1, (2, 4)).astype(np.float32))
        assert np.isfinite(obs).all() and np.isfinite(rew).all()
        episodes += [i["episode"] for i in infos if "episode" in i]
    assert len(episodes) == 4 and all(e["l"] == 20 for e in episodes)


@pytest.mark.parametrize("algo", ["PPO", "SAC"])
def test_ppo_and_sac_learn_a_few_hundred_steps(algo, tmp_path):
    import stable_baselines3 as sb3
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    env = VecNormalize(VecMonitor(make(4)))
    if algo == "PPO":
        model = sb3.PPO("MlpPolicy", env, n_steps=32, batch_size=64, n_epochs=2, seed=0, device="cpu")
    else:
        model = sb3.SAC("MlpPolicy", env, learning_starts=64, batch_size=64, train_freq=8, seed=0, device="cpu")
    model.learn(total_timesteps=320)
    assert model.num_timesteps >= 320
    obs = env.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (4, 4) and np.isfinite(action).all()
    model.save(tmp_path / "m")
    env.save(tmp_path / "vecnormalize.pkl")


def test_state_restores_and_env_pickles():
    env = make(2)
    env.seed(2)
    env.reset()
    for _ in range(5):
        env.step(np.full((2, 4), 0.2, np.float32))
    state = env.get_state()
    copy = pickle.loads(pickle.dumps(env))
    acts = [np.full((2, 4), np.cos(k), np.float32) for k in range(12)]
    first = [env.step(a)[0].copy() for a in acts]
    env.set_state(state)
    second = [env.step(a)[0].copy() for a in acts]
    third = [copy.step(a)[0].copy() for a in acts]
    assert all(np.array_equal(x, y) and np.array_equal(x, z) for x, y, z in zip(first, second, third))


def _reference_info_dict(row: np.ndarray, wake_seed: int) -> dict:
    """The info dict as the Python layer built it before the native builder (the reference)."""
    from accd_gym.envs.task import EVENT_NAMES, INFO_NAMES

    out = {name: (bool(v) if name in EVENT_NAMES else v) for name, v in zip(INFO_NAMES, row.tolist())}
    out["episode_steps"] = int(out["episode_steps"])
    out["wake_seed"] = int(wake_seed)
    return out


def test_native_info_dicts_equal_the_python_construction_in_keys_order_types_and_values():
    from accd_gym.envs.task import INFO_NAMES, info_dicts

    rng = np.random.default_rng(5)
    info = rng.normal(0, 1e3, (7, len(INFO_NAMES)))
    info[:, 4:8] = rng.integers(0, 2, (7, 4))
    info[:, 8] = rng.integers(0, 701, 7)
    info[0, 1], info[1, 2], info[2, 3] = np.nan, np.inf, -0.0
    wake = rng.integers(0, 2**64 - 1, 7, dtype=np.uint64)
    got = info_dicts(info, wake)
    assert len(got) == 7
    for i, d in enumerate(got):
        want = _reference_info_dict(info[i], int(wake[i]))
        assert list(d) == list(want)
        for k in want:
            assert type(d[k]) is type(want[k]), k
            assert d[k] == want[k] or (d[k] != d[k] and want[k] != want[k]), k
        assert str(d["peak_tension"]) == str(want["peak_tension"])  # -0.0 stays -0.0
    with pytest.raises(ValueError, match="info has shape"):
        info_dicts(info[:, :5], wake)
    with pytest.raises(ValueError, match="wake_seed"):
        info_dicts(info, wake[:3])


def test_step_infos_carry_the_time_limit_and_divergence_keys_in_order():
    env = make(2, boom={"capture_radius": 1e-6})
    env.seed(1)
    env.reset()
    for k in range(20):
        _, _, done, infos = env.step(np.zeros((2, 4), np.float32))
        for d in infos:
            assert list(d)[-2:] == ["wake_seed", "TimeLimit.truncated"] or "terminal_observation" in d
            assert d["TimeLimit.truncated"] is (k == 19)
            assert type(d["episode_steps"]) is int and type(d["captured"]) is bool


def test_the_rust_step_loop_of_the_benchmarks_advances_the_envs_as_step_does():
    """``BatchEnv.time_rust_steps`` (bench_envs.py's side-by-side rounds) steps the batch the way
    ``step`` does: after it, a twin stepped through the Python env holds the same state."""
    a, b = accd_gym.AccdVecEnv(num_envs=3, seed=5, num_threads=1), accd_gym.AccdVecEnv(num_envs=3, seed=5, num_threads=2)
    a.reset()
    b.reset()
    actions = np.array([[0.5, -0.25, 0.0, 1.0], [-1.0, 0.0, 0.75, -0.5], [0.0, 0.1, -0.1, 0.2]], np.float32)
    seconds = a._core.time_rust_steps(actions, 25)
    assert seconds > 0
    for _ in range(25):
        b.step(actions)
    assert a.get_state() == b.get_state()
    with pytest.raises(accd_gym.StateError, match=r"shape \[2, 4\]"):
        a._core.time_rust_steps(actions[:2], 1)
