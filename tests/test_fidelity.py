"""Issue 18 items 3-5: the Python `Tether` under the distributed elasticity, `accd-gym study fig9`
against closed forms of Table 1's chain, and the tension comparison's building blocks.

Everything here runs in seconds; the long studies (``tension``, ``sweep``) are exercised on
shortened inputs through the same functions.
"""

import json
import math

import numpy as np
import pytest

import accd_gym
from accd_gym import fidelity, study


def test_python_tether_takes_the_distributed_elasticity():
    n = 4
    t = accd_gym.Tether({"elasticity": "distributed"}, preset="table1")
    assert t.elasticity == "distributed" and t.dofs == 3 * n and t.config["elasticity"] == "distributed"
    assert accd_gym.Tether(preset="table1").elasticity == "attachment"
    # States from directions or angles land in the distributed layout, elongation on element 1.
    t.set_state(np.tile([0.0, 0.0, 1.0], (n, 1)), elongation=0.002)
    assert t.q.shape == (3 * n,) and t.stretches.tolist() == [0.002, 0.0, 0.0, 0.0]
    t.set_angles(np.full(n, 0.5), np.zeros(n), elongation=0.001)
    assert t.total_elongation == pytest.approx(0.001)
    q = np.zeros(3 * n)
    q[1::2][:n] = math.pi / 2  # hanging
    q[2 * n + 1 :] = [1e-3, 2e-3, 3e-3]
    t.set_coordinates(q, np.zeros(3 * n))
    assert t.stretches.tolist() == [0.0, 1e-3, 2e-3, 3e-3] and t.total_elongation == pytest.approx(6e-3)
    # The tip sits beyond every stretched element: 10 m + 6 mm below the attachment.
    assert t.tip_position[2] == pytest.approx(10.006, abs=1e-12)
    # Segment 1's element carries the attachment tension: n k s_1 + n c_s s_1'.
    t.set_coordinates(np.r_[1e-3, q[1:]], np.zeros(3 * n))
    assert t.attachment_tension == pytest.approx(n * 1e4 * 1e-3)
    with pytest.raises(accd_gym.ConfigError, match="elasticity"):
        accd_gym.Tether({"elasticity": "everywhere"}, preset="table1")
    with pytest.raises(accd_gym.StateError, match="q"):
        t.set_coordinates(np.zeros(2 * n + 1), np.zeros(2 * n + 1))


def test_attachment_tether_stretches_are_its_one_element():
    t = accd_gym.Tether(preset="table1")
    t.set_state(np.tile([0.0, 0.0, 1.0], (4, 1)), elongation=0.003)
    assert t.stretches.tolist() == [0.003, 0.0, 0.0, 0.0] and t.total_elongation == t.elongation == 0.003


@pytest.fixture(scope="module")
def fig9(tmp_path_factory):
    """`accd-gym study fig9` run once, its JSON as written."""
    folder = tmp_path_factory.mktemp("fig9")
    study.run(["fig9"], folder, progress=False)
    return folder, json.loads((folder / "fig9.json").read_text())


def test_fig9_vertical_case_matches_the_closed_forms(fig9):
    _, doc = fig9
    closed, vertical = doc["closed_forms"], doc["cases"]["vertical"]
    assert vertical["simplified"]["static_m"] == pytest.approx(closed["simplified_static_m"], rel=1e-6)
    assert vertical["full-nk"]["static_m"] == pytest.approx(closed["full_nk_static_m"], rel=1e-6)
    assert vertical["full-k"]["static_m"] == pytest.approx(closed["full_k_static_m"], rel=1e-6)
    # The element carries the whole chain: a damped mass-spring ring, period to a sampling step.
    assert vertical["simplified"]["frequency_hz"] == pytest.approx(closed["simplified_frequency_hz"], rel=0.01)
    # Released unstretched, the first overshoot of a damped oscillator: exp(-pi zeta / sqrt(1 - zeta^2)).
    z = closed["simplified_damping_ratio"]
    s = vertical["simplified"]
    assert s["amplitude_m"] / s["static_m"] == pytest.approx(math.exp(-math.pi * z / math.sqrt(1 - z * z)), rel=0.02)
    # The full model's chain of n springs n k rings faster than one spring k with all the mass;
    # Table 1's k at every joint (n times softer) slower.
    assert vertical["full-k"]["frequency_hz"] < s["frequency_hz"] < vertical["full-nk"]["frequency_hz"]


def test_fig9_swing_and_the_comparison_with_the_paper(fig9):
    folder, doc = fig9
    swing = doc["cases"]["swing"]
    # Every model swings alike (the elongation is mm on a 10 m chain): the same frequency.
    freqs = [swing[k]["frequency_hz"] for k in ("simplified", "full-nk", "full-k")]
    assert max(freqs) - min(freqs) < 0.03 * min(freqs) and 0.2 < freqs[0] < 0.6
    amp = {k: swing[k]["amplitude_m"] / swing["simplified"]["amplitude_m"] for k in swing}
    vert = {k: doc["cases"]["vertical"][k]["amplitude_m"] / doc["cases"]["vertical"]["simplified"]["amplitude_m"] for k in swing}
    # Stiffened to keep the tether's k the full model rings less; with Table 1's k per joint more.
    assert amp["full-nk"] < 1 and vert["full-nk"] < 1 and amp["full-k"] > 2 and vert["full-k"] > 2
    assert "as the paper says" in doc["verdict"] and "against the paper" in doc["verdict"]
    assert doc["verdict"] in (folder / "fig9.md").read_text()
    png = (folder / "fig9.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and 20_000 < len(png) < 300_000


def test_fig9_step_is_converged():
    model = fidelity.FIG9_MODELS[1]
    coarse = fidelity.fig9_metrics("vertical", *fidelity.simulate_fig9(model, "vertical", 2.0))
    fine = fidelity.fig9_metrics("vertical", *fidelity.simulate_fig9(model, "vertical", 2.0, time_step=5e-4))
    assert coarse["amplitude_m"] == pytest.approx(fine["amplitude_m"], rel=0.01)
    assert coarse["frequency_hz"] == pytest.approx(fine["frequency_hz"], rel=0.02)
