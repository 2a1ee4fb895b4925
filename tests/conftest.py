"""Shared fixtures of the Python test suite."""

import signal
import threading

import numpy as np
import pytest

import accd_gym


@pytest.fixture
def table3() -> accd_gym.Tether:
    """Table 3's tether, trailing straight back, in still air."""
    return accd_gym.Tether()


@pytest.fixture
def hanging_directions():
    """Factory: n unit vectors pointing straight down (+z)."""

    def make(n: int) -> np.ndarray:
        d = np.zeros((n, 3))
        d[:, 2] = 1.0
        return d

    return make


@pytest.fixture
def sigint_raises_keyboard_interrupt():
    """SIGINT raises KeyboardInterrupt during the test, as in an interactive Python, and the
    previous handler comes back afterwards. Needed by tests that send SIGINT to their own
    process: a suite started with SIGINT ignored (a background job of a non-interactive shell,
    ``nohup``, some CI runners) gets no KeyboardInterrupt handler from Python, so the signal
    would be ignored and the interrupted loop would run on for hours."""
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signal handlers can only be set in the main thread")
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
