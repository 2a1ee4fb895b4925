"""`accd-gym study`: the paper's section-4 design studies against the expected settling of the reference design.

Every study here runs at full length (the whole command takes a few seconds), through the same
functions the command uses; the JSON each writes is what the assertions read.
"""

import json
import math

import pytest

import accd_gym
from accd_gym.studies import runner, study
from accd_gym.cli import main

# Longer than the suite's default time limit (pyproject.toml): the module fixtures run the design studies (timed with the first test that uses them).
pytestmark = pytest.mark.timeout(1800)

#: The expected settling: "settles about 50 m below" / "about 70 m below", within 15 %.
DEPTH_TOLERANCE = 0.15


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    """A folder with every study's output, run once (the command's ``all``)."""
    folder = tmp_path_factory.mktemp("study")
    runner.run(["all"], folder, progress=False)
    return folder


@pytest.fixture(scope="module")
def docs(out):
    """{study: its JSON document as written}."""
    return {name: json.loads((out / f"{name}.json").read_text()) for name in study.STUDIES}


def metrics(docs, name, case):
    return docs[name]["cases"][case]["metrics"]


def test_material_uhmwpe_about_50_m_steel_below_100_m_and_rings_longer(docs):
    uhmwpe, steel = metrics(docs, "material", "uhmwpe"), metrics(docs, "material", "steel")
    assert uhmwpe["settled_depth_m"] == pytest.approx(50.0, rel=DEPTH_TOLERANCE)
    assert steel["settled_depth_m"] > 100.0
    assert steel["settling_time_s"] > uhmwpe["settling_time_s"]
    assert steel["oscillation_amplitude_m"] > uhmwpe["oscillation_amplitude_m"]


def test_selected_tether_settles_about_50_m_below_within_40_s_at_0_01_s_steps(docs):
    m = metrics(docs, "selected", "table3")
    assert accd_gym.CaptureSim(calm=True).time_step == 0.01
    assert m["settled_depth_m"] == pytest.approx(50.0, rel=DEPTH_TOLERANCE)
    assert 5.0 < m["settling_time_s"] <= 40.0
    assert 0.0 < m["mean_tension_N"] < m["peak_tension_N"] < accd_gym.tether_config("table3")["breaking_tension"]


def test_length_300_m_about_70_m_below_and_moves_more_than_150_m(docs):
    short, mid, long = (metrics(docs, "length", k) for k in ("150m", "250m", "300m"))
    assert long["settled_depth_m"] == pytest.approx(70.0, rel=DEPTH_TOLERANCE)
    assert short["settled_depth_m"] < mid["settled_depth_m"] < long["settled_depth_m"]
    # "more significant movement (especially in Z)" and "greater amplitude in vibrations" (4.2):
    assert long["oscillation_amplitude_m"] > 1.3 * short["oscillation_amplitude_m"]
    assert long["pitch_overshoot_m"] > short["pitch_overshoot_m"]


@pytest.mark.xfail(
    strict=True,
    reason="known deviation (docs/paper-reproduction.md): in this model the 150 m tether rings longer "
    "than the 300 m one after release and after each command; the paper reports the opposite, and no "
    "reading of `accd-gym study sweep` (drag velocity, discretization, joint damping, C_n) reproduces it",
)
def test_length_300_m_settles_slower_than_150_m(docs):
    short, long = metrics(docs, "length", "150m"), metrics(docs, "length", "300m")
    assert long["settling_time_s"] > short["settling_time_s"]
    assert long["pitch_settling_time_s"] > short["pitch_settling_time_s"]


def test_length_in_the_wake_both_pushed_down_similarly(docs):
    for key in ("250m", "300m"):
        calm, wake = metrics(docs, "length", key), metrics(docs, "length", f"{key}-wake")
        assert wake["settled_depth_m"] > calm["settled_depth_m"] + 3.0
        assert wake["depth_std_settled_m"] > 0.1 and wake["settling_time_s"] is None
    shift = [
        metrics(docs, "length", f"{k}-wake")["settled_depth_m"] - metrics(docs, "length", k)["settled_depth_m"]
        for k in ("250m", "300m")
    ]
    assert shift[1] == pytest.approx(shift[0], rel=0.5)  # "both ropes are similarly affected" (4.2)


def test_diameter_16_mm_moves_more_under_the_same_commands(docs):
    d16, d24, d32 = (metrics(docs, "diameter", k) for k in ("16mm", "24mm", "32mm"))
    for axis in ("pitch_excursion_m", "yaw_excursion_m"):
        assert d16[axis] > 1.2 * d24[axis] and d24[axis] > d32[axis], axis
    # Thicker: heavier, settles lower and swings further after release (4.3).
    assert d16["settled_depth_m"] < d32["settled_depth_m"]
    assert d32["oscillation_amplitude_m"] > d16["oscillation_amplitude_m"]


def test_max_tension_is_the_rlvs_drag_plus_its_inertia_rung_on_the_axial_spring(docs):
    doc = docs["max-tension"]
    m, inputs = doc["metrics"], doc["inputs"]
    tether = accd_gym.tether_config(inputs["preset"])
    a = (inputs["thrust_N"] - inputs["ta_drag_N"] - inputs["rlv_drag_N"]) / (
        inputs["ta_mass_kg"] + inputs["rlv_mass_kg"]
    )
    assert m["quasi_static_tension_N"] == pytest.approx(inputs["rlv_drag_N"] + inputs["rlv_mass_kg"] * a)
    # Mean: the quasi-static pull plus the tether's own share (its drag in cruise, its mass times a).
    own = m["cruise_tension_N"] - inputs["rlv_drag_N"] + tether["mass_per_length"] * tether["length"] * a
    assert m["mean_tension_N"] == pytest.approx(m["quasi_static_tension_N"] + own, rel=0.02)
    # The suddenly applied load rings on the axial spring with the RLV's mass: period 2 pi sqrt(m/k),
    # first overshoot exp(-pi zeta / sqrt(1 - zeta^2)) with zeta = c / (2 sqrt(k m)), c = c_k m_tether.
    k, mass = tether["axial_stiffness"], inputs["rlv_mass_kg"]
    assert m["oscillation_period_s"] == pytest.approx(2 * math.pi * math.sqrt(mass / k), rel=0.03)
    zeta = tether["axial_damping_per_mass"] * tether["mass_per_length"] * tether["length"] / (2 * math.sqrt(k * mass))
    static = m["quasi_static_tension_N"] + own
    ratio = (m["peak_tension_N"] - static) / (static - m["cruise_tension_N"])
    assert ratio == pytest.approx(math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), abs=0.05)
    # Shape of the paper's Fig. 14 (peak / mean = 225 / 125): a step load nearly doubling at its peak.
    paper_ratio = study.PAPER_MAX_TENSION_PEAK_N / study.PAPER_MAX_TENSION_MEAN_N
    assert m["peak_tension_N"] / m["mean_tension_N"] == pytest.approx(paper_ratio, rel=0.1)
    assert m["peak_tension_N"] < tether["breaking_tension"]


def test_max_tension_runs_at_the_documented_step_and_at_0_01_s_now_that_steps_substep():
    case = study.MaxTensionCase(duration_s=12.0)
    fine = study.max_tension_metrics(study.simulate_max_tension(case))
    finer = study.max_tension_metrics(
        study.simulate_max_tension(study.MaxTensionCase(duration_s=12.0, time_step=0.0025))
    )
    assert fine["peak_tension_N"] == pytest.approx(finer["peak_tension_N"], rel=1e-3)
    # Plain RK4 diverged at 0.01 s here; the
    # substepped step now follows the stiff transverse mode and agrees with the documented step.
    coarse = study.max_tension_metrics(study.simulate_max_tension(study.MaxTensionCase(duration_s=12.0, time_step=0.01)))
    assert coarse["peak_tension_N"] == pytest.approx(fine["peak_tension_N"], rel=1e-3)


def test_fig12_commands_and_their_effect_on_the_flaps():
    pitch, yaw = study.fig12_commands()
    assert pitch.pitch_deg == yaw.yaw_deg == study.FIG12_DEFLECTION_DEG and pitch.end_s <= yaw.start_s
    assert study.command_at((pitch, yaw), pitch.start_s) == (study.FIG12_DEFLECTION_DEG, 0.0)
    assert study.command_at((pitch, yaw), pitch.end_s) == (0.0, 0.0)
    assert study.command_at((pitch, yaw), yaw.start_s + 1.0) == (0.0, study.FIG12_DEFLECTION_DEG)
    # A shortened schedule runs through the same path; the flaps follow the command.
    cmds = study.fig12_commands(release_s=2.0, hold_s=1.0, gap_s=1.0)
    case = study.Case("short", "short", "table3", study.fig12_duration(cmds, tail_s=1.0), cmds)
    r = study.simulate_case(case)
    assert r.command_deg[:, 0].max() == study.FIG12_DEFLECTION_DEG and r.time[-1] == pytest.approx(case.duration_s)


def test_outputs_and_cli(out, docs, tmp_path, capsys):
    for name in study.STUDIES:
        for figure in docs[name]["figures"]:
            png = (out / figure).read_bytes()
            assert png[:8] == b"\x89PNG\r\n\x1a\n" and 20_000 < len(png) < 300_000, figure
        assert "paper" in (out / f"{name}.md").read_text()
    assert "n/a" in (out / "summary.md").read_text()
    assert main(["study", "selected", "--out", str(tmp_path), "--quiet"]) == 0
    assert json.loads((tmp_path / "selected.json").read_text())["cases"]["table3"]["paper"]
    with pytest.raises(SystemExit) as e:
        main(["study", "wingspan", "--out", str(tmp_path)])
    assert e.value.code == 2 and "invalid choice" in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown study"):
        runner.run(["wingspan"], tmp_path)
