"""The registered ids work in subprocess vector envs started with ``spawn`` (SubprocVecEnv's
default on macOS and Windows) or ``forkserver``, whose children never import ``accd_gym`` unless
something they unpickle does: ``accd_gym.ENV_ID`` and the tiers' ids pickle as an import of
``accd_gym`` (:class:`accd_gym.envs.tiers.EnvId`), and the module-qualified string id
``"accd_gym:accd_gym/InAirCapture-v0"`` has gymnasium import it."""

from __future__ import annotations

import pickle
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import accd_gym
from accd_gym.envs.tiers import TIERS, EnvId

QUICK = dict(capture_window=2.0, initial={"settle_time": 20.0})


def test_every_tier_id_is_a_str_that_pickles_as_an_import_of_accd_gym():
    for t in TIERS.values():
        assert isinstance(t.id, str) and type(t.id) is EnvId
        assert t.id == str(t.id) and hash(t.id) == hash(str(t.id)) and t.id in gym.registry
        assert b"accd_gym.envs.overrides" in pickle.dumps(t.id)
        assert type(pickle.loads(pickle.dumps(t.id))) is EnvId
    assert accd_gym.ENV_ID is TIERS["nominal"].id


def test_a_fresh_interpreter_makes_every_tier_from_its_unpickled_id():
    """What a spawned child does: unpickle what it was sent, then ``gymnasium.make``; it never
    imported accd_gym, so the registry has the ids only because unpickling imported it."""
    script = (
        "import pickle, sys, gymnasium as gym\n"
        "ids = pickle.loads(sys.stdin.buffer.read())\n"
        "print('accd_gym' in sys.modules)\n"
        "print(' '.join(gym.make(i, capture_window=2.0, initial={'settle_time': 20.0}).spec.id for i in ids))\n"
    )
    ids = [t.id for t in TIERS.values()]
    done = subprocess.run([sys.executable, "-c", script], input=pickle.dumps(ids), capture_output=True, timeout=300)
    assert done.returncode == 0, done.stderr.decode()
    assert done.stdout.decode().split() == ["True"] + [str(i) for i in ids]
    # A plain string id in the same fresh interpreter is not found (gymnasium's NamespaceNotFound):
    # the failure that the id class and the module-qualified id avoid.
    plain = subprocess.run([sys.executable, "-c", script], input=pickle.dumps([str(i) for i in ids]),
                           capture_output=True, timeout=300)
    assert plain.returncode != 0 and b"NamespaceNotFound" in plain.stderr


def test_subproc_vec_env_with_spawn_makes_envs_from_env_id_and_the_module_qualified_id():
    """SB3's ``make_vec_env`` sends ``gymnasium.make(env_id, ...)`` to each child: env 0 gets
    ``accd_gym.ENV_ID``, env 1 the module-qualified string id (one spawned pair of processes)."""
    from functools import partial

    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    ids = [accd_gym.ENV_ID, "accd_gym:accd_gym/InAirCapture-v0"]
    spawned = SubprocVecEnv([partial(gym.make, i, **QUICK) for i in ids], start_method="spawn")
    reference = DummyVecEnv([partial(gym.make, i, **QUICK) for i in ids])
    try:
        spawned.seed(3)
        reference.seed(3)
        assert np.array_equal(spawned.reset(), reference.reset())
        for _ in range(3):
            actions = np.full((2, 4), 0.4, np.float32)
            out_s, out_r = spawned.step(actions), reference.step(actions)
            assert np.array_equal(out_s[0], out_r[0])
            # (SubprocVecEnv stacks the rewards as float64, DummyVecEnv keeps float32.)
            assert np.array_equal(out_s[1].astype(np.float32), out_r[1])
    finally:
        spawned.close()
        reference.close()
