"""The state format: a snapshot is a header (magic, format version, kind of
env, number of envs, config hash, CRC-32) and a serde-encoded payload. Every corrupted,
truncated or foreign blob raises StateError naming what is wrong and changes nothing; a good one
restores bit for bit."""

from pathlib import Path

import numpy as np
import pytest

import accd_gym
from accd_gym import StateError
from accd_gym.envs.sb3 import AccdVecEnv

QUICK = dict(capture_window=2.0, initial={"settle_time": 5.0})
HEADER_LEN = 68
DATA = Path(__file__).parent / "data"


def actions(n, k):
    return np.array([[np.sin(k + i), 0.3, -0.2 * i, 0.1] for i in range(n)], np.float32)


@pytest.fixture(scope="module")
def vec():
    """A 3-env vector env a few steps in, its state, and its state two steps later."""
    env = accd_gym.InAirCaptureVectorEnv(3, **QUICK)
    env.reset(seed=4)
    for k in range(4):
        env.step(actions(3, k))
    good = env.get_state()
    for k in range(4, 6):
        env.step(actions(3, k))
    return env, good, env.get_state()


def test_header_layout(vec):
    _, good, _ = vec
    assert good[:8] == b"ACCDSNAP"
    version, kind = np.frombuffer(good[8:16], "<u4")
    num_envs, = np.frombuffer(good[16:24], "<u8")
    payload, = np.frombuffer(good[56:64], "<u8")
    assert (version, kind, num_envs) == (5, 4, 3)  # format 5, gymnasium vector env, 3 envs
    assert payload == len(good) - HEADER_LEN
    import zlib

    assert zlib.crc32(good[:64] + good[HEADER_LEN:]) == int(np.frombuffer(good[64:68], "<u4")[0])


def test_restore_continues_bit_for_bit(vec):
    env, good, _ = vec
    other = accd_gym.InAirCaptureVectorEnv(3, **QUICK)
    other.set_state(good)
    env.set_state(good)
    for k in range(4, 14):
        a, b = env.step(actions(3, k)), other.step(actions(3, k))
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
        assert np.array_equal(a[2], b[2]) and np.array_equal(a[3], b[3])
    assert env.get_state() == other.get_state()


def test_bit_flips_and_truncations_raise_state_error_and_change_nothing(vec):
    env, good, _ = vec
    env.set_state(good)
    env.step(actions(3, 99))
    current = env.get_state()
    assert current != good
    rng = np.random.default_rng(20261201)
    # 500 single-bit flips anywhere, and 100 more within the header.
    bits = np.concatenate([rng.integers(0, 8 * len(good), 500), rng.integers(0, 8 * HEADER_LEN, 100)])
    for bit in bits:
        blob = bytearray(good)
        blob[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(StateError) as e:
            env.set_state(bytes(blob))
        if bit >= 8 * HEADER_LEN:
            assert "corrupted" in str(e.value) and "CRC-32" in str(e.value), str(e.value)
    # 100 truncations: random lengths, and each length around the header's end.
    cuts = np.concatenate([rng.integers(0, len(good), 94), [0, 1, 8, HEADER_LEN - 1, HEADER_LEN, len(good) - 1]])
    for cut in cuts:
        with pytest.raises(StateError, match="truncated"):
            env.set_state(good[:cut])
    assert env.get_state() == current, "a refused state changed the env"


def test_foreign_states_name_what_differs(vec):
    env, good, current = vec
    env.set_state(current)
    other_config = accd_gym.InAirCaptureVectorEnv(3, capture_window=3.0, initial={"settle_time": 5.0})
    other_config.reset(seed=4)
    with pytest.raises(StateError, match="another configuration"):
        env.set_state(other_config.get_state())
    fewer = accd_gym.InAirCaptureVectorEnv(2, **QUICK)
    fewer.reset(seed=4)
    with pytest.raises(StateError, match="2 envs, expected a state of 3 envs"):
        env.set_state(fewer.get_state())
    # The single env's state into a vector env of one env (same config, same size).
    single = accd_gym.InAirCaptureEnv(**QUICK)
    single.reset(seed=4)
    one = accd_gym.InAirCaptureVectorEnv(1, **QUICK)
    with pytest.raises(StateError, match=r"a state of a single env \(InAirCaptureEnv\), expected a state of a gymnasium vector env"):
        one.set_state(single.get_state())
    with pytest.raises(StateError, match="expected a state of a single env"):
        single.set_state(one.get_state())
    sb3 = AccdVecEnv(num_envs=3, seed=4, **QUICK)
    sb3.reset()
    with pytest.raises(StateError, match="stable-baselines3"):
        env.set_state(sb3.get_state())
    rng = np.random.default_rng(7)
    for n in (0, 1, 7, 67, 68, 1000, len(good)):
        with pytest.raises(StateError):
            env.set_state(rng.bytes(n))
    with pytest.raises(StateError, match="magic"):
        env.set_state(rng.bytes(500))
    with pytest.raises(StateError, match="bytes"):
        env.set_state("not bytes")
    # Trailing bytes.
    with pytest.raises(StateError, match="trailing"):
        env.set_state(good + b"\0")
    assert env.get_state() == current


def test_a_state_of_the_old_format_is_refused_with_the_reason():
    """``state_format_v2_vector_env.bin`` was written by ``InAirCaptureVectorEnv(2, ...).get_state()``
    of main at 4405b6c (the hand-written codec, magic ``ACCDST02`` after two flag bytes)."""
    old = (DATA / "state_format_v2_vector_env.bin").read_bytes()
    assert old[2:10] == b"ACCDST02"
    cfg = dict(capture_window=1.0, initial={"settle_time": 5.0}, wake={"enabled": False}, turbulence={"wake_turbulence": False})
    env = accd_gym.InAirCaptureVectorEnv(2, **cfg)
    with pytest.raises(StateError, match="old format.*the state format changed"):
        env.set_state(old)
    with pytest.raises(StateError, match="old format"):
        env.set_state(old[2:])  # as the Rust BatchEnv wrote it
