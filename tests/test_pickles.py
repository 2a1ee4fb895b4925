"""Pickles of every env class are self-contained: a user aerodynamic table is
carried as its contents (the file may be gone when the pickle is loaded), and seeds and wake
options given before a reset survive the pickle."""

import json
import os
import pickle

import numpy as np
import pytest

import accd_gym
from accd_gym.envs.sb3 import AccdVecEnv

QUICK = dict(capture_window=1.0, initial={"settle_time": 5.0})


@pytest.fixture
def table_file(tmp_path):
    table = json.loads(accd_gym.default_aero_table_json())
    table["damping"]["clp"] = -20.0  # not the default: the pickle must carry this table
    path = tmp_path / "aero.json"
    path.write_text(json.dumps(table))
    return str(path)


def run(env, steps, n):
    out = []
    for _ in range(steps):
        _, r, d, infos = env.step(np.full((n, 4), 0.3, np.float32))
        out.append((r.copy(), d.copy(), [i["wake_seed"] for i in infos]))
    return out


@pytest.mark.parametrize("make", ["single", "vector", "sb3"])
def test_a_user_aero_table_travels_inside_the_pickle(make, table_file):
    if make == "single":
        env = accd_gym.InAirCaptureEnv(accd={"aero_table": table_file}, **QUICK)
        env.reset(seed=3)
    elif make == "vector":
        env = accd_gym.InAirCaptureVectorEnv(2, accd={"aero_table": table_file}, **QUICK)
        env.reset(seed=3)
    else:
        env = AccdVecEnv(num_envs=2, seed=3, accd={"aero_table": table_file}, **QUICK)
        env.reset()
    blob = pickle.dumps(env)
    os.remove(table_file)
    copy = pickle.loads(blob)
    if make == "single":
        a = [env.step(np.full(4, 0.3, np.float32))[1] for _ in range(5)]
        b = [copy.step(np.full(4, 0.3, np.float32))[1] for _ in range(5)]
    elif make == "vector":
        a = [env.step(np.full((2, 4), 0.3, np.float32))[1].tolist() for _ in range(5)]
        b = [copy.step(np.full((2, 4), 0.3, np.float32))[1].tolist() for _ in range(5)]
    else:
        a, b = run(env, 5, 2), run(copy, 5, 2)
        a, b = [(x[0].tolist(), x[2]) for x in a], [(x[0].tolist(), x[2]) for x in b]
    assert a == b


def test_seed_and_options_set_before_a_reset_survive_the_pickle():
    held_out = [1_000_000_000 + k for k in range(8)]
    env = AccdVecEnv(num_envs=2, **QUICK)
    env.seed(11)
    env.set_options({"wake_seeds": held_out})
    copy = pickle.loads(pickle.dumps(env))
    reference = AccdVecEnv(num_envs=2, seed=11, **QUICK)
    reference.set_options({"wake_seeds": held_out})
    for e in (copy, reference):
        e.reset()
    a, b = run(copy, 25, 2), run(reference, 25, 2)
    assert [x[2] for x in a] == [x[2] for x in b]
    assert all(w in held_out for x in a for w in x[2])
    assert [x[0].tolist() for x in a] == [x[0].tolist() for x in b]


@pytest.mark.parametrize("make", ["single", "vector", "sb3"])
def test_a_pickle_taken_mid_run_continues_the_wake_seed_schedule(make):
    """The schedule's position (which held-out seed each env's next episode takes), the episodes
    in progress and their random streams travel inside the pickle."""
    held_out = [1_000_000_000 + k for k in range(8)]
    action = np.full((2, 4), 0.3, np.float32)
    if make == "single":
        env = accd_gym.InAirCaptureEnv(**QUICK)
        env.reset(seed=4, options={"wake_seeds": held_out})
    elif make == "vector":
        env = accd_gym.InAirCaptureVectorEnv(2, **QUICK)
        env.reset(seed=4, options={"wake_seeds": held_out})
    else:
        env = AccdVecEnv(num_envs=2, seed=4, **QUICK)
        env.set_options({"wake_seeds": held_out})
        env.reset()

    def go(e):
        """30 steps: the rewards and the wake seed of each step's episode."""
        rewards, wakes = [], []
        for _ in range(30):
            if make == "single":
                _, r, terminated, truncated, info = e.step(action[0])
                rewards.append(r)
                wakes.append(info["wake_seed"])
                if terminated or truncated:
                    e.reset()
            elif make == "vector":
                _, r, _, _, info = e.step(action)
                rewards += r.tolist()
                wakes += info["wake_seed"].tolist()
            else:
                _, r, _, infos = e.step(action)
                rewards += r.tolist()
                wakes += [i["wake_seed"] for i in infos]
        return rewards, wakes

    go(env)  # into the run: several episodes done, one in progress
    copy = pickle.loads(pickle.dumps(env))
    a, b = go(env), go(copy)
    assert a == b
    assert set(a[1]) <= set(held_out) and len(set(a[1])) > 2
