"""The ``true_observation`` env option: ``info["true_obs"]`` is, bit for bit, the observation of
the same episode (same seeds, same actions) with the sensors disabled, in the single env, the
gymnasium vector env (its ``_true_obs`` mask, ``final_info`` with same-step autoreset) and the
SB3 VecEnv (every info, the ended episode's last beside ``terminal_observation``); off by
default, when no info holds it."""

from __future__ import annotations

import numpy as np
import pytest

from accd_gym import InAirCaptureEnv, InAirCaptureVectorEnv
from accd_gym.envs.sb3 import AccdVecEnv
from accd_gym.errors import ConfigError, StateError

#: Short episodes, so that some end (truncation) within a test.
SHORT = {"capture_window": 3.0}


def _actions(k: int, n: int = 1) -> np.ndarray:
    t = 0.1 * k + np.arange(n)[:, None]
    return np.clip(np.hstack([np.sin(t), np.cos(t), -np.sin(0.7 * t), np.cos(0.3 * t)]), -1, 1).astype(np.float32)


def _bits(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, dtype=np.float32).view(np.uint32)


@pytest.mark.parametrize("tier", ["sensors", "hard"])
def test_the_true_observation_is_the_observation_without_sensors_bit_for_bit(tier):
    kept = InAirCaptureEnv(tier=tier, true_observation=True)
    truth = InAirCaptureEnv(tier=tier, sensors={"enabled": False})
    obs, info = kept.reset(seed=11)
    expected, _ = truth.reset(seed=11)
    assert np.array_equal(_bits(info["true_obs"]), _bits(expected))
    assert not np.array_equal(obs, expected)  # the sensors change the observation
    for k in range(30):
        obs, reward, term, trunc, info = kept.step(_actions(k)[0])
        expected, reward_t, term_t, trunc_t, info_t = truth.step(_actions(k)[0])
        assert np.array_equal(_bits(info["true_obs"]), _bits(expected)), f"step {k}"
        # nothing else of the episode depends on the sensors' randomness
        assert (reward, term, trunc, info["distance"]) == (reward_t, term_t, trunc_t, info_t["distance"])
        if term or trunc:
            break


def test_on_the_nominal_tier_the_true_observation_is_the_observation_and_off_by_default_there_is_none():
    env = InAirCaptureEnv(tier="nominal", true_observation=True)
    obs, info = env.reset(seed=3)
    assert np.array_equal(info["true_obs"], obs)
    for k in range(5):
        obs, *_, info = env.step(_actions(k)[0])
        assert np.array_equal(info["true_obs"], obs)
    plain = InAirCaptureEnv(tier="sensors")
    _, info = plain.reset(seed=3)
    assert "true_obs" not in info and "true_obs" not in plain.step(_actions(0)[0])[4]
    assert plain.agent_options.to_dict() == {} and env.agent_options.to_dict() == {"true_observation": True}
    with pytest.raises(StateError, match="true observations are off"):
        plain.true_observations()
    with pytest.raises(ConfigError, match="`true_observation` = 'yes' is outside the allowed range true or false"):
        InAirCaptureEnv(true_observation="yes")


def _truth_rollouts(n: int, seed: int, steps: int) -> list[list[np.ndarray]]:
    """Per env i, the observations of a single sensorless env seeded ``seed + i`` stepped with
    the batch's actions, restarting (``reset()``) when an episode ends."""
    out = []
    for i in range(n):
        env = InAirCaptureEnv(tier="sensors", sensors={"enabled": False}, **SHORT)
        obs, _ = env.reset(seed=seed + i)
        seq = [obs]
        for k in range(steps):
            obs, _, term, trunc, _ = env.step(_actions(k, n)[i])
            seq.append(obs)
            if term or trunc:
                seq.append(env.reset()[0])
        out.append(seq)
    return out


def test_the_vector_envs_report_the_true_observation_and_the_ended_episodes_last():
    n, seed, steps = 2, 5, 32  # a 3 s window is 30 agent steps: every env's first episode ends
    truth = _truth_rollouts(n, seed, steps)
    vec = InAirCaptureVectorEnv(n, autoreset_mode="same_step", tier="sensors", true_observation=True, **SHORT)
    _, infos = vec.reset(seed=seed)
    assert infos["_true_obs"].all()
    pos = [0] * n
    for i in range(n):
        assert np.array_equal(_bits(infos["true_obs"][i]), _bits(truth[i][0]))
    ended = 0
    for k in range(steps):
        _, _, term, trunc, infos = vec.step(_actions(k, n))
        for i in range(n):
            pos[i] += 1
            if term[i] or trunc[i]:
                ended += 1
                assert infos["final_info"]["_true_obs"][i]
                assert np.array_equal(_bits(infos["final_info"]["true_obs"][i]), _bits(truth[i][pos[i]]))
                pos[i] += 1  # the new episode's first observation
            assert np.array_equal(_bits(infos["true_obs"][i]), _bits(truth[i][pos[i]])), (k, i)
    assert ended >= n

    sb3 = AccdVecEnv(n, seed=seed, tier="sensors", true_observation=True, **SHORT)
    sb3.reset()
    pos = [0] * n
    for i in range(n):
        assert np.array_equal(_bits(sb3.reset_infos[i]["true_obs"]), _bits(truth[i][0]))
    for k in range(steps):
        sb3.step_async(_actions(k, n))
        _, _, dones, infos = sb3.step_wait()
        for i in range(n):
            pos[i] += 1
            # the ended episode's last true observation, beside terminal_observation
            assert np.array_equal(_bits(infos[i]["true_obs"]), _bits(truth[i][pos[i]])), (k, i)
            if dones[i]:
                assert "terminal_observation" in infos[i]
                pos[i] += 1
                assert np.array_equal(_bits(sb3.reset_infos[i]["true_obs"]), _bits(truth[i][pos[i]]))
