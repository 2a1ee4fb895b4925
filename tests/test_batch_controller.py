"""The LQR's Kalman filter (and the MPC on it) stepped per env inside the Rust batch's threads
(``_core.BatchEnv.set_controller``): the residual base of every env class and the evaluation of
the ``lqr`` and ``mpc`` baselines. Checked against the calling-thread path (the policy's own
``predict``, stepped from Python), bit for bit, whatever the batch size and thread count, across
automatic resets, corrections, pickles and states."""

import pickle

import numpy as np
import pytest

import accd_gym.envs.residual as residual
from accd_gym import AccdVecEnv, InAirCaptureVectorEnv, StateError
from accd_gym.control.lqr import LqrPolicy
from accd_gym.control.mpc import MpcPolicy
from accd_gym.envs.task import ACT_DIM, OBS_DIM
from accd_gym.envs.tiers import tier
from accd_gym.evals.episodes import run_episodes

# Short episodes (truncated after 3 s = 30 steps), so that a rollout crosses automatic resets.
SHORT = dict(capture_window=3.0)


@pytest.fixture
def calling_thread(monkeypatch):
    """Makes envs built inside the context step their residual base on the calling thread
    (the path before the batch ran it)."""
    monkeypatch.setattr(residual, "BATCH_BASES", ())


def rollout(env, steps, seed, rng_seed=0):
    """Observations, rewards, dones and final observations of ``steps`` steps with random actions."""
    rng = np.random.default_rng(rng_seed)
    out = []
    sb3 = isinstance(env, AccdVecEnv)
    obs = env.reset() if sb3 else env.reset(seed=seed)[0]
    out.append(obs.copy())
    for _ in range(steps):
        a = rng.uniform(-1.2, 1.2, (env.num_envs, ACT_DIM)).astype(np.float32)
        if sb3:
            obs, r, dones, infos = env.step(a)
            finals = [infos[i]["terminal_observation"] for i in np.flatnonzero(dones)]
            out += [obs.copy(), r.copy(), dones.copy(), *finals]
        else:
            obs, r, term, trunc, infos = env.step(a)
            finals = [f for f in infos.get("final_obs", []) if f is not None]
            out += [obs.copy(), r.copy(), term.copy(), trunc.copy(), *finals]
    return out


def assert_same(a, b):
    assert len(a) == len(b)
    for t, (x, y) in enumerate(zip(a, b)):
        assert np.asarray(x).dtype == np.asarray(y).dtype and np.array_equal(x, y), t


@pytest.mark.parametrize("mode", ["next_step", "same_step", "sb3"])
def test_the_batch_steps_the_lqr_base_with_the_bits_of_the_calling_thread(mode, monkeypatch):
    kw = dict(tier="hard", residual={"base": "lqr", "scale": 0.3}, **SHORT)
    make = (lambda: AccdVecEnv(3, seed=4, **kw)) if mode == "sb3" else \
        (lambda: InAirCaptureVectorEnv(3, autoreset_mode=mode, **kw))
    env = make()
    assert env._core.has_controller  # the batch runs the base
    threaded = rollout(env, 70, seed=4)
    monkeypatch.setattr(residual, "BATCH_BASES", ())
    env = make()
    assert not env._core.has_controller
    assert_same(threaded, rollout(env, 70, seed=4))


def test_the_mpc_base_runs_in_the_batch_with_the_bits_of_the_calling_thread(monkeypatch):
    kw = dict(tier="precision", residual={"base": "mpc", "scale": 0.3}, **SHORT)
    env = InAirCaptureVectorEnv(2, autoreset_mode="same_step", **kw)
    assert env._core.has_controller
    threaded = rollout(env, 35, seed=8)
    steps = env._core.controller_stats()[0]
    assert steps >= 2 * 35  # every env's MPC solved each step in the batch
    monkeypatch.setattr(residual, "BATCH_BASES", ())
    assert_same(threaded, rollout(InAirCaptureVectorEnv(2, autoreset_mode="same_step", **kw), 35, seed=8))


def test_batch_size_and_threads_change_no_bit_of_the_base_commands():
    kw = dict(tier="hard", residual={"base": "lqr", "scale": 0.3}, **SHORT)
    runs = {}
    for n, threads in [(1, 1), (3, 1), (3, 2), (4, 3)]:
        env = AccdVecEnv(n, seed=20, num_threads=threads, **kw)
        obs = env.reset()
        rows = [[obs[0].copy()]]
        rng = np.random.default_rng(1)
        for _ in range(45):  # past an automatic reset of every env
            a = np.repeat(rng.uniform(-1, 1, (1, ACT_DIM)).astype(np.float32), n, axis=0)
            obs, _, dones, infos = env.step(a)
            rows.append([obs[0].copy(), dones[0]] + ([infos[0]["terminal_observation"]] if dones[0] else []))
        runs[(n, threads)] = rows
    first = runs[(1, 1)]
    for key, rows in runs.items():
        for t, (x, y) in enumerate(zip(first, rows)):
            assert all(np.array_equal(p, q) for p, q in zip(x, y)), (key, t)


@pytest.mark.parametrize("cls", ["vector", "sb3"])
def test_pickles_and_states_mid_episode_continue_exactly_and_across_the_two_paths(cls, monkeypatch):
    kw = dict(tier="hard", residual={"base": "lqr", "scale": 0.3}, history=1, **SHORT)
    make = (lambda: AccdVecEnv(2, seed=3, **kw)) if cls == "sb3" else (lambda: InAirCaptureVectorEnv(2, **kw))
    env = make()
    env.reset() if cls == "sb3" else env.reset(seed=3)
    rng = np.random.default_rng(5)
    for _ in range(12):  # mid-episode
        env.step(rng.uniform(-1, 1, (2, ACT_DIM)).astype(np.float32))
    state = env.get_state()
    copy = pickle.loads(pickle.dumps(env))
    monkeypatch.setattr(residual, "BATCH_BASES", ())
    python_path = make()  # the state of the batch's controllers restores into the calling-thread path
    python_path.set_state(state)
    monkeypatch.undo()
    back = make()  # and the calling-thread path's state into the batch's controllers
    back.set_state(python_path.get_state())
    envs = (env, copy, python_path, back)
    assert [e._core.has_controller for e in envs] == [True, True, False, True]
    for t in range(40):
        a = rng.uniform(-1, 1, (2, ACT_DIM)).astype(np.float32)
        outs = [e.step(a) for e in envs]
        for other in outs[1:]:
            assert np.array_equal(outs[0][0], other[0]) and np.array_equal(outs[0][1], other[1]), t


def test_a_controller_state_that_does_not_fit_is_refused_and_changes_nothing():
    env = InAirCaptureVectorEnv(2, residual="lqr", **SHORT)
    env.reset(seed=0)
    z, u, fresh, command = env._core.controller_state()
    with pytest.raises(StateError):
        env._core.set_controller_state(z[:, :-1].copy(), u, fresh, command)
    with pytest.raises(StateError):
        env._core.set_controller_state(z[:1].copy(), u[:1].copy(), fresh[:1].copy(), command[:1].copy())
    after = env._core.controller_state()
    assert all(np.array_equal(a, b) for a, b in zip((z, u, fresh, command), after))
    plain = InAirCaptureVectorEnv(2, **SHORT)
    with pytest.raises(StateError, match="no controllers"):
        plain.controller_commands()


class CallingThread:
    """A policy's predict and reset without its Rust stepper: evaluation steps it from Python."""

    def __init__(self, policy):
        self.policy = policy
        self.name = policy.name

    def predict(self, obs):
        return self.policy.predict(obs)

    def reset(self, mask=None):
        self.policy.reset(mask)


def outcomes(episodes):
    return [(e.outcome, e.steps, float(e.min_distance).hex(), float(e.final_distance).hex()) for e in episodes]


def test_evaluating_the_lqr_in_the_batch_gives_the_calling_thread_episodes_whatever_batch_and_threads():
    cfg = tier("hard").config()
    lqr = LqrPolicy.for_config(cfg)
    before = outcomes(run_episodes(CallingThread(lqr), 5, num_envs=2, config=cfg))
    for batch, threads in [(2, 1), (3, 2), (5, 0)]:
        assert outcomes(run_episodes(LqrPolicy.for_config(cfg), 5, num_envs=batch, num_threads=threads,
                                     config=cfg)) == before, (batch, threads)


def test_evaluating_the_mpc_in_the_batch_gives_the_calling_thread_episodes_and_counts_its_solves():
    cfg = {**tier("precision").config(), **SHORT}
    mpc = MpcPolicy.for_config(cfg)
    before = outcomes(run_episodes(CallingThread(mpc), 3, num_envs=2, config=cfg))
    threaded = MpcPolicy.for_config(cfg)
    assert outcomes(run_episodes(threaded, 3, num_envs=2, config=cfg)) == before
    assert threaded.stats["steps"] >= mpc.stats["steps"] > 0


def test_non_finite_or_out_of_range_controller_values_are_refused_naming_the_field():
    env = InAirCaptureVectorEnv(2, residual="lqr", **SHORT)
    env.reset(seed=0)
    z, u, fresh, command = env._core.controller_state()
    bad_u = u.copy()
    bad_u[0, 0] = np.nan
    with pytest.raises(StateError, match="controller.u"):
        env._core.set_controller_state(z, bad_u, fresh, command)
    bad_command = command.copy()
    bad_command[1, 2] = 2.0
    with pytest.raises(StateError, match="controller.command"):
        env._core.set_controller_state(z, u, fresh, bad_command)
    after = env._core.controller_state()
    assert all(np.array_equal(a, b) for a, b in zip((z, u, fresh, command), after))
    policy = LqrPolicy.for_config(env.config)
    policy.predict(np.zeros((2, OBS_DIM)))
    state = policy.get_state()
    with pytest.raises(StateError, match="offset"):
        policy.sent(np.full((2, 4), np.inf))
    assert all(np.array_equal(a, b) for a, b in zip(state.values(), policy.get_state().values()))


def test_set_controller_is_refused_on_a_residual_env():
    env = InAirCaptureVectorEnv(2, residual="lqr", **SHORT)
    with pytest.raises(Exception, match="residual"):
        env.set_controller(LqrPolicy.for_config(env.config))
    assert OBS_DIM == 25
