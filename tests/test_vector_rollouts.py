"""Whole rollouts of the native vector envs equal those of the reference vector envs, on every
registered tier: ``InAirCaptureVectorEnv`` against gymnasium's ``SyncVectorEnv`` of single envs
(every autoreset mode), ``AccdVecEnv`` against stable-baselines3's ``DummyVecEnv``.

Every object a rollout returns (observations, rewards, flags, infos, SB3's ``reset_infos``) is
kept as returned and the two rollouts are compared only at the end, so an array that an env hands
out and later overwrites (an in-place buffer) shows up as a difference, as does an info key one
of them leaves out (e.g. the drawn ``parameters`` of the randomized tiers at an automatic reset).
``tests/test_vector_equivalence.py`` compares step by step.
"""

from __future__ import annotations

import numpy as np
import pytest
import gymnasium as gym
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode

import accd_gym
from accd_gym.envs.tiers import TIERS

N = 3
STEPS = 48
#: Short episodes (2 s = 20 agent steps), a quick equilibrium and a tight envelope: random flaps
#: end some episodes early (envelope exits) while others run to the end of the window
#: (truncations), so every rollout autoresets several times, at different steps per env.
SHORT = dict(capture_window=2.0, initial={"settle_time": 20.0}, limits={"max_distance": 14.0})
#: Every id this package registers (each is a tier of ``accd_gym.envs.tiers.TIERS``).
REGISTERED = sorted(spec.id for spec in gym.registry.values() if spec.namespace == "accd_gym")
MODES = [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED]


def test_every_registered_id_is_a_tier():
    assert REGISTERED == sorted(t.id for t in TIERS.values())


def _actions(seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1.0, 1.0, size=(N, 4)).astype(np.float32) for _ in range(STEPS)]


def _gymnasium_rollout(env, mode) -> list:
    """Every object ``env`` returns over a rollout: seeded resets (a list, then an int in the
    middle), steps, and with autoreset disabled a masked reset of the ended envs."""
    kept = [env.reset(seed=[5, 6, 7])]
    for k, actions in enumerate(_actions(1)):
        if k == STEPS // 2:
            kept.append(env.reset(seed=2**40))
        out = env.step(actions)
        kept.append(out)
        done = out[2] | out[3]
        if mode == AutoresetMode.DISABLED and done.any():
            kept.append(env.reset(options={"reset_mask": done.copy()}))
    return kept


def _assert_same_rollouts(native: list, reference: list) -> None:
    assert len(native) == len(reference)
    for k, (a, b) in enumerate(zip(native, reference)):
        assert data_equivalence(a, b, exact=True), f"returned object {k}:\nnative    {a!r}\nreference {b!r}"


def _ends(rollout: list) -> int:
    """Episodes that ended in a gymnasium rollout (terminated or truncated)."""
    return sum(int((out[2] | out[3]).sum()) for out in rollout if len(out) == 5)


def _has_key(obj, key: str) -> bool:
    if isinstance(obj, dict):
        return key in obj or any(_has_key(v, key) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return any(_has_key(v, key) for v in obj)
    return False


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.value)
@pytest.mark.parametrize("env_id", REGISTERED)
def test_native_vector_rollout_equals_sync_vector_env_rollout_kept_whole(env_id, mode):
    native = gym.make_vec(env_id, num_envs=N, autoreset_mode=mode, **SHORT)
    reference = gym.make_vec(env_id, num_envs=N, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **SHORT)
    assert isinstance(native, accd_gym.InAirCaptureVectorEnv)
    kept_native = _gymnasium_rollout(native, mode)
    kept_reference = _gymnasium_rollout(reference, mode)
    assert _ends(kept_reference) >= 2 * N, "the rollout must autoreset several times"
    if native.config["randomization"]["enabled"]:
        assert _has_key(kept_reference[2:], "parameters"), "the drawn parameters of reset episodes"
    _assert_same_rollouts(kept_native, kept_reference)
    native.close()
    reference.close()


def _sb3_rollout(env) -> list:
    """Every object ``env`` returns over a rollout, with a copy of the ``reset_infos`` list after
    each call (its dicts as they are: a dict changed later would show): two seeded resets (the
    second with wake options) and steps."""
    env.seed(5)
    kept = [(env.reset(), list(env.reset_infos))]
    for k, actions in enumerate(_actions(2)):
        if k == STEPS // 2:
            env.seed(2**40)
            env.set_options({"wake_seed": 12345})
            kept.append((env.reset(), list(env.reset_infos)))
        kept.append((env.step(actions), list(env.reset_infos)))
    return kept


@pytest.mark.parametrize("env_id", REGISTERED)
def test_accd_vec_env_rollout_equals_dummy_vec_env_rollout_kept_whole(env_id):
    from stable_baselines3.common.vec_env import DummyVecEnv

    name = next(t.name for t in TIERS.values() if t.id == env_id)
    native = accd_gym.AccdVecEnv(N, tier=name, **SHORT)
    reference = DummyVecEnv([lambda: gym.make(env_id, **SHORT) for _ in range(N)])
    kept_native = _sb3_rollout(native)
    kept_reference = _sb3_rollout(reference)
    dones = sum(int(out[2].sum()) for out, _ in kept_reference if len(out) == 4)
    assert dones >= 2 * N, "the rollout must autoreset several times"
    if native.config["randomization"]["enabled"]:
        assert all("parameters" in info for _, infos in kept_reference for info in infos)
    _assert_same_rollouts(kept_native, kept_reference)
