"""Physics through the Python API, against closed-form results (the Rust suite checks more)."""

import numpy as np
import pytest

import accd_gym

J01 = 2.404825557695773


def test_hanging_tether_stretches_by_weight_over_k(hanging_directions):
    t = accd_gym.Tether({"tip_mass": 50.0})
    c = t.config
    t.set_state(hanging_directions(t.segments))
    t.advance(10.0)
    weight = (c["mass_per_length"] * c["length"] + c["tip_mass"]) * c["gravity"]
    assert t.elongation == pytest.approx(weight / c["axial_stiffness"], rel=1e-9)
    assert t.tensions()[0] == pytest.approx(weight, rel=1e-9)


def test_energy_is_conserved_without_damping_and_air():
    t = accd_gym.Tether(
        {"joint_damping_per_mass": 0.0, "axial_damping_per_mass": 0.0, "time_step": 0.001}, preset="table1"
    )
    d = np.array([0.0, 0.5, 1.0])
    t.set_state(np.tile(d, (t.segments, 1)))
    e0 = t.energy()["total"]
    worst, kinetic = 0.0, 0.0
    for _ in range(50):
        t.step(100)
        e = t.energy()
        worst = max(worst, abs(e["total"] - e0))
        kinetic = max(kinetic, e["kinetic"])
    assert kinetic > 10.0
    assert worst / kinetic < 1e-6


def test_compound_pendulum_period():
    length = 2.0
    t = accd_gym.Tether(
        {
            "segments": 1,
            "length": length,
            "mass_per_length": 0.5,
            "axial_stiffness": 1e6,
            "axial_damping_per_mass": 0.0,
            "joint_damping_per_mass": 0.0,
            "time_step": 2e-4,
        }
    )
    g = t.config["gravity"]
    t.set_angles(np.array([np.pi / 2 + 0.01]), np.zeros(1), elongation=1.0 * g / 1e6)
    times, angle = [], []
    for _ in range(30000):
        t.step(1)
        times.append(t.time)
        angle.append(t.q[1] - np.pi / 2)
    a = np.asarray(angle)
    up = np.nonzero((a[:-1] < 0) & (a[1:] >= 0))[0]
    crossings = [times[i] - a[i] * (times[i + 1] - times[i]) / (a[i + 1] - a[i]) for i in up]
    period = (crossings[-1] - crossings[0]) / (len(crossings) - 1)
    assert period == pytest.approx(2 * np.pi * np.sqrt(2 * length / (3 * g)), rel=1e-3)


def test_acceleration_tilts_the_equilibrium():
    a = 2.0
    t = accd_gym.Tether({"tip_mass": 50.0})
    c = t.config
    g = c["gravity"]
    tilt = np.arctan(a / g)
    n = t.segments
    directions = np.tile([-np.sin(tilt), 0.0, np.cos(tilt)], (n, 1))
    weight = (c["mass_per_length"] * c["length"] + c["tip_mass"]) * np.hypot(g, a)
    t.set_state(directions, elongation=weight / c["axial_stiffness"])
    t.set_surroundings(frame_acceleration=np.array([a, 0.0, 0.0]))
    assert np.abs(t.accelerations()).max() < 1e-9
    # And without the acceleration it is not an equilibrium.
    t.set_surroundings(frame_acceleration=np.zeros(3))
    assert np.abs(t.accelerations()).max() > 1e-3


def test_towed_table3_settles_about_50_m_below():
    t = accd_gym.towed_tether()
    assert t.config["tip_mass"] == accd_gym.stand_in_body()["mass"]
    t.advance(60.0)
    depth = t.tip_position[2]
    assert np.linalg.norm(t.tip_velocity) < 0.05
    assert depth == pytest.approx(50.0, rel=0.15)
    assert t.tip_position[0] < -240.0
