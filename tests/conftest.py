"""Shared fixtures of the Python test suite."""

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
