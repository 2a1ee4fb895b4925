"""The MPC baseline (accd_gym.control.mpc): its settings' errors, pickling, the registry, batch
independence, and the constraints on real episodes. The hand-checkable cases (the flap limits
and the speed bound on a double integrator, an infeasible start, a zero horizon) are the Rust
unit tests of crates/sim/src/control/mpc.rs.
"""

import pickle

import numpy as np
import pytest

from accd_gym import ConfigError
from accd_gym.control.lqr import LqrPolicy
from accd_gym.control.mpc import MpcPolicy, MpcTuning
from accd_gym.control.registry import CONTROLLERS, make_controller, residual_bases
from accd_gym.envs.overrides import tier
from accd_gym.evals.episodes import run_episodes
from accd_gym.envs.task import TRAINING_WAKE_SEEDS


@pytest.fixture(scope="module")
def precision():
    return tier("precision").config()


def _observations(config, steps=40, num_envs=5, seed=3):
    """Observations of a few LQR-flown episodes of ``config`` (rows of varied states)."""
    from accd_gym.envs.vector import InAirCaptureVectorEnv

    env = InAirCaptureVectorEnv(num_envs=num_envs, **config)
    lqr = LqrPolicy.for_config(config)
    obs, _ = env.reset(seed=seed)
    out = [obs.astype(np.float64)]
    for _ in range(steps):
        obs, *_ = env.step(lqr.predict(obs))
        out.append(obs.astype(np.float64))
    env.close()
    return out


def test_a_zero_horizon_and_bad_settings_are_config_errors_naming_the_field():
    with pytest.raises(ConfigError, match=r"mpc\.horizon.*\[1, 200\]"):
        MpcPolicy.for_config(tuning={"horizon": 0})
    with pytest.raises(ConfigError, match=r"mpc\.margin"):
        MpcPolicy.for_config(tuning={"margin": 1.5})
    with pytest.raises(ConfigError, match=r"mpc\.lead.*\[1, horizon = 5\]"):
        MpcPolicy.for_config(tuning={"horizon": 5, "lead": 6})
    with pytest.raises(ConfigError, match="horizont"):
        MpcPolicy.for_config(tuning={"horizont": 3})


def test_mpc_is_a_registered_residual_base():
    assert "mpc" in CONTROLLERS and "mpc" in residual_bases()
    policy = make_controller("mpc", 0, tier("precision").config())
    assert isinstance(policy, MpcPolicy) and policy.name == "mpc"
    # The precision tier's closing-speed limit and capture radius, the boom's approach speed.
    assert policy.limits == (1.0, 0.3, 0.5)


def test_commands_keep_the_flap_limits_and_are_never_nan(precision):
    policy = MpcPolicy.for_config(precision)
    for obs in _observations(precision):
        u = policy.predict(obs)
        assert u.dtype == np.float32 and np.all(np.isfinite(u)) and np.all(np.abs(u) <= 1.0)
    # A non-finite observation gives the LQR's fallback path or an error, never a NaN command.
    bad = _observations(precision, steps=1)[-1].copy()
    bad[0, 0] = np.nan
    try:
        u = policy.predict(bad)
    except Exception as e:  # the filter's divergence report
        assert "not finite" in str(e)
    else:
        assert np.all(np.isfinite(u))


def test_without_the_boom_near_it_is_the_lqr():
    """Far from the boom's arrival and inside the flap limits no constraint is active: the
    command is the LQR's (the same law; the MPC's condensed gain differs by rounding)."""
    obs = _observations({}, steps=30, num_envs=8)
    mpc, lqr = MpcPolicy.for_config({}), LqrPolicy.for_config({})
    for o in obs[:-1]:
        lqr.predict(o)
    mpc.set_state(lqr.get_state())  # the same estimates (the MPC runs the LQR's filter)
    um, ul = mpc.peek(obs[-1]), lqr.peek(obs[-1])
    inside = np.all(np.abs(ul) < 0.999, axis=1)
    assert inside.sum() >= 4
    np.testing.assert_allclose(um[inside], ul[inside], atol=1e-5)


def test_commands_are_the_same_bits_whatever_the_batch(precision):
    obs = _observations(precision, steps=60, num_envs=6)
    whole = MpcPolicy.for_config(precision)
    parts = [MpcPolicy.for_config(precision) for _ in range(2)]
    for o in obs:
        a = whole.predict(o)
        b = np.concatenate([parts[0].predict(o[:2]), parts[1].predict(o[2:])])
        assert a.tobytes() == b.tobytes()


def test_the_policy_pickles_with_its_estimates(precision):
    obs = _observations(precision, steps=5)
    policy = MpcPolicy.for_config(precision, tuning={"horizon": 8, "lead": 4})
    for o in obs[:-1]:
        policy.predict(o)
    copy = pickle.loads(pickle.dumps(policy))
    assert copy.tuning.horizon == 8 and copy.limits == policy.limits
    assert copy.predict(obs[-1]).tobytes() == policy.predict(obs[-1]).tobytes()
    state = policy.get_state()
    other = MpcPolicy.for_config(precision, tuning={"horizon": 8, "lead": 4})
    other.set_state(state)
    assert other.peek(obs[-1]).tobytes() == policy.peek(obs[-1]).tobytes()


def test_it_flies_episodes_and_reports_its_solves(precision):
    policy = MpcPolicy.for_config(precision)
    eps = run_episodes(policy, 4, seed=7, wake_seeds=list(TRAINING_WAKE_SEEDS[:4]), num_envs=4, config=precision)
    assert len(eps) == 4
    stats = policy.stats
    assert stats["steps"] > 0 and stats["fallbacks"] + stats["inexact"] + stats["constrained"] <= stats["steps"]
    # The exact solver ends every constrained solve at the optimum: no step falls back.
    assert stats["constrained"] > 0 and stats["fallbacks"] == 0 and stats["inexact"] == 0, stats


def test_it_serves_as_a_residual_base(precision):
    """``residual="mpc"``: a zero correction flies the MPC's commands."""
    from accd_gym.envs.vector import InAirCaptureVectorEnv

    env = InAirCaptureVectorEnv(num_envs=2, residual={"base": "mpc", "observe_base": True}, **precision)
    obs, _ = env.reset(seed=4)
    for _ in range(5):
        obs, _, terminated, truncated, _ = env.step(np.zeros((2, 4), dtype=np.float32))
    assert np.all(np.isfinite(obs)) and not np.any(terminated | truncated)
    env.close()
