"""The implicit axial scheme (tether config ``scheme = "implicit_axial"``) from Python: a
configuration refused at the default 0.01 s step for its stiff axial elements is accepted, it
reaches the closed-form static stretch of a hanging chain, and the field is validated and reaches
the capture environment's configuration."""

import numpy as np
import pytest

import accd_gym


def test_distributed_table3_is_refused_explicitly_and_steps_implicitly():
    with pytest.raises(accd_gym.ConfigError, match="implicit_axial"):
        accd_gym.Tether({"elasticity": "distributed"}, preset="table3")
    t = accd_gym.Tether({"elasticity": "distributed", "scheme": "implicit_axial"}, preset="table3")
    assert t.scheme == "implicit_axial" and t.config["scheme"] == "implicit_axial"
    assert t.time_step == 0.01
    n = t.segments
    # Hanging straight down, released unstretched: 60 s of 0.01 s steps settle on the closed form,
    # element k carrying the weight below it, (n + 1) / (2n) M g / k in all.
    t.set_state(np.tile([0.0, 0.0, 1.0], (n, 1)))
    assert t.advance(60.0) == 6000
    c = t.config
    weight = c["mass_per_length"] * c["length"] * c["gravity"]
    want = (n + 1) / (2 * n) * weight / c["axial_stiffness"]
    assert t.total_elongation == pytest.approx(want, rel=1e-9)
    below = weight * (n - np.arange(n)) / n
    assert np.allclose(t.stretches, below / (n * c["axial_stiffness"]), rtol=1e-9, atol=0)


def test_stiff_attachment_element_steps_implicitly():
    stiff = {"segments": 4, "axial_stiffness": 1e12}
    with pytest.raises(accd_gym.ConfigError, match="time_step"):
        accd_gym.Tether(stiff, preset="table3")
    t = accd_gym.Tether({**stiff, "scheme": "implicit_axial"}, preset="table3")
    t.set_state(np.tile([0.0, 0.0, 1.0], (4, 1)))
    t.step(5)
    c = t.config
    want = c["mass_per_length"] * c["length"] * c["gravity"] / 1e12
    assert t.elongation == pytest.approx(want, rel=1e-9)


def test_scheme_is_validated_and_reaches_the_environment_config():
    with pytest.raises(accd_gym.ConfigError, match="scheme"):
        accd_gym.Tether({"scheme": "implicit"}, preset="table1")
    assert accd_gym.Tether(preset="table1").scheme == "explicit"
    assert "scheme" not in accd_gym.tether_config()  # the default is left out of the JSON
    assert accd_gym.tether_config(overrides={"scheme": "implicit_axial"})["scheme"] == "implicit_axial"
    env = accd_gym.InAirCaptureEnv(
        tether={"elasticity": "distributed", "scheme": "implicit_axial"}, capture_window=6.0
    )
    assert env._config["tether"]["scheme"] == "implicit_axial"
    obs, _ = env.reset(seed=1)
    for _ in range(20):
        obs, *_ = env.step(np.zeros(4, np.float32))
    assert np.all(np.isfinite(obs))
    with pytest.raises(accd_gym.ConfigError, match="tether.scheme"):
        accd_gym.InAirCaptureEnv(tether={"scheme": "implicit"})
