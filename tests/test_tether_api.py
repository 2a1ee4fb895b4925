"""accd_gym.Tether from Python: construction, configuration errors, state, outputs, threading."""

import inspect
import threading

import numpy as np
import pytest

import accd_gym
from accd_gym import ConfigError, SimulationError, StateError


def test_presets_and_config_round_trip():
    t3 = accd_gym.tether_config()
    assert t3["segments"] == 30 and t3["length"] == 250.0
    assert t3["mass_per_length"] * t3["length"] == pytest.approx(82.25)
    assert accd_gym.tether_config("table1")["segments"] == 4
    steel = accd_gym.tether_config("steel-250m-24mm")
    assert steel["mass_per_length"] == pytest.approx(2.34)
    tether = accd_gym.Tether({"segments": 12, "tip_mass": 50.0}, preset="uhmwpe-300m-16mm")
    assert tether.segments == 12 and tether.dofs == 25
    assert tether.config["tip_mass"] == 50.0 and tether.config["length"] == 300.0


@pytest.mark.parametrize(
    "overrides, words",
    [
        ({"length": -1.0}, ["`length`", "-1", "(0, 5000] m"]),
        ({"segments": 0}, ["`segments`", "0", "[1, 1000]"]),
        ({"time_step": 5.0}, ["`time_step`", "5", "(0, 1] s"]),
        ({"normal_drag_coefficient": float("nan")}, ["`normal_drag_coefficient`", "nan"]),
        ({"lenght": 3.0}, ["lenght", "length"]),
        ({"length": "long"}, ["invalid type"]),
    ],
)
def test_bad_config_names_field_value_and_range(overrides, words):
    with pytest.raises(ConfigError) as info:
        accd_gym.Tether(overrides)
    message = str(info.value)
    for word in words:
        assert word.lower() in message.lower(), message
    assert isinstance(info.value, ValueError) and isinstance(info.value, accd_gym.AccdError)


def test_bad_preset_and_surroundings():
    with pytest.raises(ConfigError, match="preset"):
        accd_gym.Tether(preset="rubber-3m-1mm")
    t = accd_gym.Tether()
    with pytest.raises(ConfigError, match="air_density"):
        t.set_surroundings(air_density=-1.0)
    with pytest.raises(ConfigError, match="altitude"):
        t.tow(altitude=40_000.0)
    with pytest.raises(StateError, match="air_velocity"):
        t.set_surroundings(air_velocity=np.array([1.0, np.nan, 0.0]))


def test_state_errors(table3, hanging_directions):
    with pytest.raises(StateError, match=r"\(30, 3\)"):
        table3.set_state(hanging_directions(29))
    bad = hanging_directions(30)
    bad[3] = 0.0
    with pytest.raises(StateError, match=r"directions\[3\]"):
        table3.set_state(bad)
    lateral = hanging_directions(30)
    lateral[0] = [0.0, 1.0, 0.0]
    with pytest.raises(StateError, match="lateral"):
        table3.set_state(lateral)
    with pytest.raises(StateError, match="phi"):
        table3.set_angles(np.zeros(3), np.zeros(30))
    with pytest.raises(StateError, match="duration"):
        table3.advance(-1.0)


def test_state_round_trip(table3):
    rng = np.random.default_rng(3)
    n = table3.segments
    phi = rng.uniform(0.0, 1.5, n)
    psi = rng.uniform(-0.3, 0.3, n)
    table3.set_angles(phi, psi, phi_rate=np.full(n, 0.1), elongation=0.01, time=2.5)
    q = table3.q
    assert q[0] == 0.01 and table3.time == 2.5
    np.testing.assert_allclose(q[1::2], phi)
    np.testing.assert_allclose(q[2::2], psi)
    dirs = table3.segment_directions
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    joints = table3.joint_positions
    assert joints.shape == (n + 1, 3)
    np.testing.assert_allclose(joints[-1], table3.tip_position)
    seg = table3.config["length"] / n
    np.testing.assert_allclose(np.linalg.norm(np.diff(joints, axis=0), axis=1), seg)
    # Coordinates set directly reproduce the same state.
    other = accd_gym.Tether()
    other.set_coordinates(table3.q, table3.qd)
    np.testing.assert_array_equal(other.joint_positions, joints)


def test_outputs_shapes_and_mass_matrix(table3):
    table3.tow()
    table3.step(5)
    m = table3.mass_matrix()
    assert m.shape == (61, 61)
    np.testing.assert_array_equal(m, m.T)
    assert np.linalg.eigvalsh(m).min() > 0
    assert table3.accelerations().shape == (61,)
    tensions = table3.tensions()
    assert tensions.shape == (31,)
    assert tensions[0] == pytest.approx(table3.attachment_tension, rel=1e-9)
    energy = table3.energy()
    assert energy["total"] == pytest.approx(sum(energy[k] for k in ("kinetic", "gravity", "axial", "bending")))


def test_divergence_is_reported_not_nan():
    # A 1 mm tether with a huge step explodes: it must raise, keeping the last good state.
    t = accd_gym.Tether({"time_step": 1.0, "diameter": 0.5, "normal_drag_coefficient": 5.0, "segments": 10})
    t.tow()
    with pytest.raises(SimulationError, match="diverged"):
        t.step(200)
    assert np.isfinite(t.q).all() and np.isfinite(t.tip_position).all()


def test_steps_are_deterministic_and_parallel_threads_agree():
    def run(out, i):
        t = accd_gym.towed_tether()
        t.step(300)
        out[i] = t.q

    sequential = {}
    run(sequential, 0)
    parallel = {}
    threads = [threading.Thread(target=run, args=(parallel, i)) for i in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    np.testing.assert_array_equal(parallel[0], sequential[0])
    np.testing.assert_array_equal(parallel[1], sequential[0])


def test_every_public_name_has_a_docstring():
    for name in accd_gym.__all__:
        obj = getattr(accd_gym, name)
        if name == "__version__":
            continue
        assert inspect.getdoc(obj), name
        if inspect.isclass(obj):
            for attr, member in vars(obj).items():
                if not attr.startswith("_"):
                    assert inspect.getdoc(member), f"{name}.{attr}"


def test_array_arguments_accept_lists():
    t = accd_gym.Tether()
    t.set_surroundings(air_velocity=[-185, 0, 0], tip_force=[0.0, 0.0, 10.0])
    assert list(t.surroundings()["air_velocity"]) == [-185.0, 0.0, 0.0]
    t.set_angles(phi=[0.1] * 30, psi=[0] * 30)
    assert abs(t.q[1] - 0.1) < 1e-15
