"""The benchmark tiers (accd_gym.envs.tiers) and randomized physics as users meet them: registered ids,
overrides merged section by section, generated docs, per-episode parameters that are a function of
the wake seed alone (so training and held-out parameter sets are disjoint like the wake seeds), the
same in every env class and batch size."""

import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import accd_gym
from accd_gym.envs.tiers import TIERS, merge, tiers_markdown


def test_every_tier_is_registered_with_its_config_and_episode_length():
    for t in TIERS.values():
        spec = gym.spec(t.id)
        assert spec.max_episode_steps == 700
        env = gym.make(t.id)
        cfg = env.unwrapped.config
        assert cfg == accd_gym.env_config(t.overrides), t.name
        env.close()
    # The nominal tier is the default configuration, unchanged.
    assert gym.make(accd_gym.ENV_ID).unwrapped.config == accd_gym.default_config()


def test_user_overrides_merge_into_the_tiers_sections():
    env = gym.make("accd_gym/InAirCapturePrecision-v0", boom={"capture_radius": 0.4}, capture_window=30.0)
    boom = env.unwrapped.config["boom"]
    assert boom["capture_radius"] == 0.4 and boom["max_closing_speed"] == 1.0
    assert env.unwrapped.config["turbulence"]["ambient"] == "severe"
    vec = gym.make_vec("accd_gym/InAirCaptureRandomized-v0", num_envs=2, vectorization_mode="vector_entry_point")
    assert vec.unwrapped.config["randomization"]["enabled"] is True
    vec.close()
    assert merge({"a": {"b": 1, "c": 2}}, {"a": {"c": 3}, "d": 4}) == {"a": {"b": 1, "c": 3}, "d": 4}


def test_an_unknown_tier_is_refused_naming_the_tiers():
    with pytest.raises(accd_gym.ConfigError, match=r"`tier` = 'nope'.*nominal, precision"):
        accd_gym.InAirCaptureEnv(tier="nope")


def test_tier_tables_are_generated_from_the_declaration():
    doc = (Path(__file__).resolve().parents[1] / "docs" / "environment.md").read_text()
    section = re.search(r"<!-- generated: accd_gym\.envs\.tiers\.tiers_markdown\(\) -->\n(.*?)\n<!-- end generated -->", doc, re.S)
    assert section and section.group(1) == tiers_markdown()
    assert tiers_markdown() in accd_gym.envs.tiers.__doc__
    for t in TIERS.values():
        assert f"`{t.id}`" in tiers_markdown()
    # A tier's rows name what it changes, with the nominal value beside it.
    assert "| `boom.capture_radius` | `0.3` | `0.5` | m |" in tiers_markdown()




def test_randomized_parameters_are_a_function_of_the_wake_seed_and_reported():
    env = accd_gym.InAirCaptureEnv(tier="randomized")
    _, info = env.reset(seed=3)
    p = info["parameters"]
    assert set(p) == set(accd_gym.PARAMETER_NAMES)
    assert 150.0 <= p["tether_length"] <= 300.0 and 0.016 <= p["tether_diameter"] <= 0.032
    assert env.unwrapped.episode_parameters() == p
    # The same wake seed in another episode (other initial conditions): the same parameters.
    _, info2 = env.reset(seed=4, options={"wake_seed": info["wake_seed"]})
    assert info2["parameters"] == p
    # Another wake seed: other parameters; and the episode's equilibrium is its own.
    setup = env.episode_setup()
    _, info3 = env.reset(seed=5, options={"wake_seed": info["wake_seed"] + 1})
    assert info3["parameters"] != p
    assert np.linalg.norm(env.episode_setup()["equilibrium"] - setup["equilibrium"]) > 0.01
    # The boom keeps its offset from each equilibrium.
    here = env.episode_setup()
    nominal = accd_gym.InAirCaptureEnv()
    nominal.reset(seed=0)
    d = nominal.episode_setup()
    assert np.allclose(here["boom_nominal"] - here["capture_point"], d["boom_nominal"] - d["capture_point"], atol=1e-9)
    # Without randomization there is nothing to report.
    assert accd_gym.InAirCaptureEnv().reset(seed=0)[1].get("parameters") is None


def test_held_out_evaluation_meets_held_out_parameters_whatever_the_batch():
    from accd_gym.control.baselines import ZeroPolicy
    from accd_gym.evals.evaluation import run_episodes

    wake = list(accd_gym.HELD_OUT_WAKE_SEEDS[:6])
    a = run_episodes(ZeroPolicy(), 6, wake_seeds=wake, num_envs=2, config={"tier": "randomized", "capture_window": 2.0})
    b = run_episodes(ZeroPolicy(), 6, wake_seeds=wake, num_envs=3, config={"tier": "randomized", "capture_window": 2.0})
    assert [e.metrics() for e in a] == [e.metrics() for e in b]
    single = accd_gym.InAirCaptureEnv(tier="randomized")
    for k, ep in enumerate(a):
        assert ep.wake_seed == wake[k]
        _, info = single.reset(seed=0, options={"wake_seed": wake[k]})
        assert ep.parameters == info["parameters"]
    # Training draws never produce a held-out wake seed, hence never held-out parameters.
    train = accd_gym.InAirCaptureVectorEnv(4, tier="randomized", capture_window=0.2)
    _, info = train.reset(seed=11)
    assert all(int(w) in accd_gym.TRAINING_WAKE_SEEDS for w in info["wake_seed"])


def test_randomized_episodes_equal_in_every_env_class_and_thread_count():
    from accd_gym import AccdVecEnv

    actions = np.random.default_rng(0).uniform(-1, 1, (8, 2, 4)).astype(np.float32)
    runs = []
    for make in (lambda: accd_gym.InAirCaptureVectorEnv(2, tier="randomized", num_threads=1),
                 lambda: accd_gym.InAirCaptureVectorEnv(2, tier="randomized", num_threads=2),
                 lambda: AccdVecEnv(2, tier="randomized")):
        env = make()
        if isinstance(env, AccdVecEnv):
            env.seed(7)
            obs = env.reset()
            params = [env.episode_parameters(i) for i in range(2)]
            out = [obs.copy()]
            for a in actions:
                obs, *_ = env.step(a)
                out.append(obs.copy())
        else:
            obs, _ = env.reset(seed=7)
            params = [env.episode_parameters(i) for i in range(2)]
            out = [obs.copy()]
            for a in actions:
                obs, *_ = env.step(a)
                out.append(obs.copy())
        runs.append((params, np.array(out)))
        env.close()
    for params, out in runs[1:]:
        assert params == runs[0][0]
        assert np.array_equal(out, runs[0][1])
    single = accd_gym.InAirCaptureEnv(tier="randomized")
    _, info = single.reset(seed=8)  # env 1 of a batch seeded 7 is the single env seeded 8
    assert info["parameters"] == runs[0][0][1]


def test_evaluation_metrics_are_the_true_geometry_under_sensors():
    # Zero flaps ignore the observation, and sensors never change the physics: with sensors on and
    # off the evaluated episodes (trajectories, miss distances) must be identical, because the
    # metrics come from the true state, not from the sensed observation.
    from accd_gym.control.baselines import ZeroPolicy
    from accd_gym.evals.evaluation import run_episodes

    wake = list(accd_gym.HELD_OUT_WAKE_SEEDS[:3])
    runs = [run_episodes(ZeroPolicy(), 3, wake_seeds=wake, num_envs=3,
                         config={"tier": "sensors", "capture_window": 3.0, **extra})
            for extra in ({}, {"sensors": {"enabled": False}})]
    for sensed, true in zip(*runs):
        assert sensed.metrics() == true.metrics()
        assert np.array_equal(sensed.trajectory, true.trajectory)
