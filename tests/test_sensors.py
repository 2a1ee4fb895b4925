"""The sensor model of the observation (``sensors``) through the Python envs.

Switching the sensors on changes the observation only: rewards, flags and info values are
bitwise those of the same seeds and actions without them. The single env, the native gymnasium
vector env and the SB3 VecEnv sense the same observations for the same seeds (against
gymnasium's ``SyncVectorEnv`` and SB3's ``DummyVecEnv`` of single envs, exactly, across
automatic resets). A state saved mid-episode with sensors continues bit for bit. Each sensor
draws from its own stream: changing the vision's timing leaves every other sensor's observation
values bit for bit as they were. The sensor
statistics themselves are tested in Rust (``crates/sim/src/task/sensors.rs``); here one of them is
checked across the boundary against an independent computation.
"""

import pickle
import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

import accd_gym
from accd_gym import ENV_ID, ConfigError
from accd_gym.envs.config import SENSORS_TIER, default_config, env_config
from accd_gym.envs.task import OBSERVATION_INDEX, OBSERVATION_SCALE

N = 3
# Short episodes and a tight envelope so that random flaps end episodes at different steps.
CONFIG = dict(capture_window=2.5, initial={"settle_time": 20.0}, limits={"max_distance": 16.0})
SENSORS = dict(SENSORS_TIER, delay_steps=2)
INFO_KEYS = ("time", "distance", "relative_speed", "peak_tension", "captured", "overload", "envelope_exit", "diverged")


def assert_same(a, b, what):
    assert data_equivalence(a, b, exact=True), f"{what}:\n{a!r}\n{b!r}"


def actions(k, n=None):
    """A fixed action sequence (not a function of the observation, so both runs take it)."""
    rows = [[np.sin(0.3 * k + i), 0.4 * np.cos(0.2 * k), -0.3, 0.2 * i] for i in range(n or 1)]
    a = np.array(rows, np.float32)
    return a if n else a[0]


def run_single(env, seed, steps):
    obs, info = env.reset(seed=seed)
    out = [(obs, None, False, False, info)]
    for k in range(steps):
        o, r, term, trunc, info = env.step(actions(k))
        out.append((o, r, term, trunc, info))
        if term or trunc:
            break
    return out


@pytest.mark.parametrize("seed", [1, 2])
def test_sensors_change_the_observation_only(seed):
    off = run_single(accd_gym.InAirCaptureEnv(capture_window=3.0, initial={"settle_time": 20.0}), seed, 30)
    on = run_single(accd_gym.InAirCaptureEnv(capture_window=3.0, initial={"settle_time": 20.0}, sensors=SENSORS), seed, 30)
    assert len(off) == len(on) == 31
    for k, ((oa, ra, ta, ua, ia), (ob, rb, tb, ub, ib)) in enumerate(zip(off, on)):
        assert (ra, ta, ua) == (rb, tb, ub), f"step {k}"
        for key in INFO_KEYS:
            assert np.array_equal(ia.get(key), ib.get(key)), f"step {k}: {key}"
        assert oa.shape == ob.shape == (25,) and ob.dtype == np.float32
        assert not np.array_equal(oa, ob), f"step {k}: the sensed observation is the truth"
    # Entries no sensor touches are the truth itself, delayed by delay_steps.
    exact = [OBSERVATION_INDEX[n] for n in ("flap_right", "flap_left", "flap_top", "flap_bottom", "time_left")]
    for k in range(len(on)):
        assert np.array_equal(on[k][0][exact], off[max(k - 2, 0)][0][exact]), f"step {k}"


def test_single_vector_and_sb3_envs_sense_the_same_observations():
    native = gym.make_vec(ENV_ID, num_envs=N, vectorization_mode="vector_entry_point", sensors=SENSORS, **CONFIG)
    reference = gym.make_vec(ENV_ID, num_envs=N, vectorization_mode="sync", sensors=SENSORS, **CONFIG)
    rng = np.random.default_rng(5)
    assert_same(native.reset(seed=9), reference.reset(seed=9), "reset")
    ended = 0
    for k in range(40):
        a = rng.uniform(-1, 1, size=(N, 4)).astype(np.float32)
        out_n, out_r = native.step(a), reference.step(a)
        assert_same(out_n, out_r, f"vector step {k}")
        ended += int(np.sum(out_r[2] | out_r[3]))
    assert ended >= 3, "automatic resets (and the sensors' resets) are covered"

    from stable_baselines3.common.vec_env import DummyVecEnv

    sb3 = accd_gym.AccdVecEnv(N, sensors=SENSORS, **CONFIG)
    dummy = DummyVecEnv([lambda: gym.make(ENV_ID, sensors=SENSORS, **CONFIG) for _ in range(N)])
    assert_same(sb3.seed(9), dummy.seed(9), "seed")
    assert_same(sb3.reset(), dummy.reset(), "sb3 reset")
    rng = np.random.default_rng(5)
    for k in range(40):
        a = rng.uniform(-1, 1, size=(N, 4)).astype(np.float32)
        for name, x, y in zip(("obs", "rewards", "dones", "infos"), sb3.step(a), dummy.step(a)):
            assert_same(x, y, f"sb3 step {k}: {name}")
    # The SB3 env's first observations are the vector env's (both seed env i with 9 + i).
    first = accd_gym.AccdVecEnv(N, sensors=SENSORS, **CONFIG)
    first.seed(9)
    vec = accd_gym.InAirCaptureVectorEnv(N, sensors=SENSORS, **CONFIG)
    assert np.array_equal(first.reset(), vec.reset(seed=9)[0])


def test_a_state_saved_mid_episode_with_sensors_continues_bit_for_bit():
    env = accd_gym.InAirCaptureEnv(sensors=SENSORS, **CONFIG)
    env.reset(seed=4)
    for k in range(7):
        env.step(actions(k))
    state = env.get_state()
    pickled = pickle.dumps(env)
    later = [env.step(actions(k)) for k in range(7, 20)]
    restored = accd_gym.InAirCaptureEnv(sensors=SENSORS, **CONFIG)
    restored.reset(seed=99)
    restored.set_state(state)
    assert_same([restored.step(actions(k)) for k in range(7, 20)], later, "set_state")
    unpickled = pickle.loads(pickled)
    assert_same([unpickled.step(actions(k)) for k in range(7, 20)], later, "pickle")
    # The vector env too.
    vec = accd_gym.InAirCaptureVectorEnv(N, sensors=SENSORS, **CONFIG)
    vec.reset(seed=3)
    for k in range(5):
        vec.step(actions(k, N))
    saved = vec.get_state()
    later = [vec.step(actions(k, N)) for k in range(5, 15)]
    other = accd_gym.InAirCaptureVectorEnv(N, sensors=SENSORS, **CONFIG)
    other.set_state(saved)
    assert_same([other.step(actions(k, N)) for k in range(5, 15)], later, "vector continued")
    # A state with sensors is a state of another configuration for an env without them.
    with pytest.raises(accd_gym.StateError, match="another configuration"):
        accd_gym.InAirCaptureEnv(**CONFIG).set_state(state)


def test_tension_noise_has_the_configured_spread():
    """Only the load cell on (every other error zero): the sensed minus the true tension, over
    400 agent steps, has mean 0 and standard deviation 150 N. Tolerances: 4 standard errors of
    the mean (150 / sqrt(400) = 7.5 N), 15 % on the standard deviation (its standard error is
    3.5 %); the observation's float32 rounding (1e-4 scale) is far below both."""
    quiet = {
        "enabled": True,
        "tension_noise": 150.0,
        "vision": {"noise_floor": 0, "range_noise": 0, "bearing_noise": 0, "dropout": 0},
        "imu": {"rate_noise": 0, "rate_bias": 0, "attitude_noise_deg": 0, "attitude_bias_deg": 0},
        "gnss": {"position_noise": 0, "velocity_noise": 0},
    }
    cfg = dict(capture_window=40.0, initial={"settle_time": 20.0}, boom={"capture_radius": 1e-3})
    off = run_single(accd_gym.InAirCaptureEnv(**cfg), 6, 400)
    on = run_single(accd_gym.InAirCaptureEnv(sensors=quiet, **cfg), 6, 400)
    i = OBSERVATION_INDEX["tension"]
    scale = OBSERVATION_SCALE["tension"]
    err = np.array([(b[0][i] - a[0][i]) / scale for a, b in zip(off, on)], np.float64)
    assert len(err) == 401
    assert abs(err.mean()) < 4 * 150.0 / np.sqrt(len(err)), err.mean()
    assert abs(err.std(ddof=1) / 150.0 - 1.0) < 0.15, err.std(ddof=1)
    # Attitude and rates are the truth (zero errors); the quaternion renormalised.
    q = [OBSERVATION_INDEX[n] for n in ("quat_w", "quat_x", "quat_y", "quat_z", "rate_p", "rate_q", "rate_r")]
    assert max(np.abs(b[0][q] - a[0][q]).max() for a, b in zip(off, on)) < 1e-6


def test_changing_the_vision_leaves_every_other_sensors_values_bit_identical():
    """The vision at 30 Hz with 20 % dropouts draws more numbers than at the tier's 20 Hz; the
    gyros, AHRS, GNSS and load cell draw from streams of their own, so their values (and the
    exact ones) are bitwise those of the tier's vision, through the whole-vector delay."""
    vision = dict(SENSORS["vision"], update_rate=30.0, dropout=0.2)
    base = run_single(accd_gym.InAirCaptureEnv(sensors=SENSORS, **CONFIG), 4, 25)
    other = run_single(accd_gym.InAirCaptureEnv(sensors=dict(SENSORS, vision=vision), **CONFIG), 4, 25)
    own = [OBSERVATION_INDEX[f"boom_rel_{c}"] for c in ("x", "y", "z", "vx", "vy", "vz")]
    rest = [i for i in range(len(base[0][0])) if i not in own]
    assert len(base) == len(other) > 10
    for k, (a, b) in enumerate(zip(base, other)):
        assert_same(a[0][rest], b[0][rest], f"step {k}")
    assert any(not np.array_equal(a[0][own], b[0][own]) for a, b in zip(base, other)), "the vision changed"


def test_the_sensors_section_is_opt_in_and_checked_by_name():
    assert "sensors" not in default_config(), "left out at its default: config hashes unchanged"
    full = env_config(sensors=SENSORS_TIER)["sensors"]
    assert full["enabled"] is True and full["vision"]["latency"] == SENSORS_TIER["vision"]["latency"]
    assert full["vision"]["update_rate"] == 20.0, "keys not given keep their defaults"
    for sensors, field, allowed in [
        ({"vision": {"dropout": 0.6}}, "sensors.vision.dropout", "[0, 0.5]"),
        ({"delay_steps": 101}, "sensors.delay_steps", "[0, 100]"),
        ({"imu": {"rate_bias": -1}}, "sensors.imu.rate_bias", "[0, 1] rad/s"),
        ({"enabled": True, "vision": {"update_rate": 200}}, "sensors.vision.update_rate", "1 / tether.time_step = 100"),
    ]:
        with pytest.raises(ConfigError, match=f"`{field}`.*{re.escape(allowed)}"):
            accd_gym.InAirCaptureEnv(sensors=sensors)
    with pytest.raises(ConfigError, match="sensors.vision.rat"):
        env_config(sensors={"vision": {"rat": 3}})
