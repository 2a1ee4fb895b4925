"""One range for every seed: [0, 2^63) (``accd_gym.envs.task.SEED_END``, declared once in the
core as ``accd_sim::SEED_END``). The config keys ``wake_seed`` and ``wake_seeds``, the reset
options of those names, a reset's seed, the vector envs' base seeds (``s + i`` included), the
command line's ``--seed`` and a training config's ``seed`` share it; an info's int64 wake seed
never wraps; every refusal quotes the value as the user gave it."""

from __future__ import annotations

import json

import numpy as np
import pytest

import accd_gym
from accd_gym import ConfigError, _core
from accd_gym.cli import main
from accd_gym.envs.task import SEED_END, check_base_seed, check_seed

QUICK = dict(capture_window=2.0, initial={"settle_time": 20.0})
TOP = SEED_END - 1


def test_the_range_is_declared_once_in_the_core():
    assert SEED_END == _core.SEED_END == 2**63


@pytest.mark.parametrize("key", ["wake_seed", "wake_seeds"])
@pytest.mark.parametrize("seed", [2**63, 2**63 + 1, 2**64 - 1])
def test_config_wake_seeds_beyond_the_range_are_refused_quoting_the_value(key, seed):
    value = seed if key == "wake_seed" else [1, seed]
    for make in (lambda: accd_gym.InAirCaptureEnv(**QUICK, **{key: value}),
                 lambda: accd_gym.InAirCaptureVectorEnv(2, **QUICK, **{key: value})):
        with pytest.raises(ConfigError, match=rf"`{key}` = {seed} is outside the allowed range \[0, 2\^63\)"):
            make()


@pytest.mark.parametrize("key", ["wake_seed", "wake_seeds"])
def test_the_top_wake_seed_is_reported_without_wrapping(key):
    value = TOP if key == "wake_seed" else [TOP, TOP - 1]
    env = accd_gym.InAirCaptureVectorEnv(2, **QUICK, **{key: value})
    _, infos = env.reset(seed=1)
    assert infos["wake_seed"].dtype == np.int64
    assert [int(w) for w in infos["wake_seed"]] == ([TOP, TOP] if key == "wake_seed" else [TOP, TOP - 1])
    single = accd_gym.InAirCaptureEnv(**QUICK, **{key: value})
    assert single.reset(seed=1)[1]["wake_seed"] == TOP


@pytest.mark.parametrize("seed", [2**63, 2**64 - 1])
def test_reset_options_and_reset_seeds_share_the_range(seed):
    env = accd_gym.InAirCaptureEnv(**QUICK)
    vec = accd_gym.InAirCaptureVectorEnv(2, **QUICK)
    for reset in (env.reset, vec.reset):
        with pytest.raises(ConfigError, match=rf"`seed` = {seed} .*\[0, 2\^63"):
            reset(seed=seed)
        with pytest.raises(ConfigError, match=rf"`wake_seed` = {seed} .*\[0, 2\^63\)"):
            reset(seed=1, options={"wake_seed": seed})
        with pytest.raises(ConfigError, match=rf"`wake_seeds` = {seed} .*\[0, 2\^63\)"):
            reset(seed=1, options={"wake_seeds": [3, seed]})
    with pytest.raises(ConfigError, match=rf"`seed` = {seed}"):
        vec.reset(seed=[0, seed])
    with pytest.raises(ConfigError, match=rf"`seed` = {seed} .*\[0, 2\^63\)"):
        accd_gym.CaptureSim(calm=True, seed=seed)
    assert env.reset(seed=TOP, options={"wake_seed": TOP})[1]["wake_seed"] == TOP


def test_a_base_seed_is_refused_quoting_the_value_given_not_plus_one():
    with pytest.raises(ConfigError) as e:
        check_base_seed(TOP, 2)
    assert f"`seed` = {TOP} " in str(e.value) and str(TOP + 1) not in str(e.value)
    assert check_base_seed(TOP - 1, 2) == TOP - 1
    assert check_seed(np.uint64(TOP)) == TOP


@pytest.mark.parametrize("seed", [2**64 - 1, 2**63])
def test_rollout_refuses_a_seed_quoting_it_as_given(seed, capsys):
    with pytest.raises(SystemExit) as e:
        main(["rollout", "--policy", "zero", "--episodes", "1", "--num-envs", "2", "--quiet", "--seed", str(seed)])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"--seed = {seed} " in err and str(seed + 1) not in err and "[0, 9223372036854775807]" in err, err


def test_rollout_refuses_a_seed_whose_episodes_would_leave_the_range(capsys):
    assert main(["rollout", "--policy", "zero", "--episodes", "2", "--num-envs", "1", "--quiet",
                 "--env", json.dumps(QUICK), "--seed", str(TOP)]) == 2
    err = capsys.readouterr().err
    assert f"`seed` = {TOP} " in err and "episodes = 2" in err and str(TOP + 1) not in err, err


def test_a_training_config_seed_shares_the_range():
    from accd_gym.learning.training import validate_config

    assert validate_config({"seed": TOP})["seed"] == TOP
    with pytest.raises(ConfigError, match=rf"`seed` = {2**63} .*\[0, {TOP}\]"):
        validate_config({"seed": 2**63})
