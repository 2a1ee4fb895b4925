"""Tether design studies: the open-loop cases of the paper's section 4, reproduced by one command.

``accd-gym study material|length|diameter|selected|max-tension|all --out DIR`` runs them and writes,
per study, a PNG to compare with the paper's figure, and the key numbers beside the paper's as JSON
and as a markdown table. Everything is SI in the towing-aircraft (TA) frame (x forward, y to
starboard, z down) unless a name says otherwise (``_deg``, ``_kN`` in tables).

The studies (paper section 4, calm air unless stated):

=============  ==============================================================  ===========
study          cases                                                           paper
=============  ==============================================================  ===========
material       24 mm UHMWPE vs 24 mm steel, 250 m, no flap deflection          Fig. 15
length         24 mm UHMWPE, 150 / 250 / 300 m, Fig. 12 commands; and 250 /    Figs. 16, 17
               300 m in the aircraft's wake (8 deg, with turbulence)
diameter       UHMWPE 250 m, 16 / 24 / 32 mm, Fig. 12 commands                 Fig. 18
selected       Table 3's tether, no flap deflection                            Fig. 19
max-tension    Table 3's tether towing the captured RLV at full thrust        Figs. 13, 14
fig9           Table 1's chain, simplified vs full elasticity (in ``all``)     Fig. 9
tension        both elasticities: max-tension and a capture episode (by name)  4.1, 2.3.6
sweep          readings behind the two open claims (by name)                   4.1, 4.2
=============  ==============================================================  ===========

``fig9``, ``tension`` and ``sweep`` live in :mod:`accd_gym.studies.fidelity`; :mod:`accd_gym.studies.runner`
runs any of them.

**The Fig. 12 commands, reconstructed.** Fig. 12 ("open loop control rates for sensitivity study")
is an image the text does not tabulate. The text says what it contains: "a simple set of open-loop
control commands, encompassing pitch and yaw adjustments" that make the device "execute pitch
maneuvers and yaw maneuvers by deflecting its flaps" (section 4), and the diameter study compares
the tethers "subjected to the same pitch command" and then "in the lateral direction" (4.3). The
amplitude: the RANS tables behind the device's aerodynamics cover symmetric deflections "up to 10
deg for pitch, yaw, and roll" (2.1), so a command of 10 deg is the largest the paper's data support.
The timing: every run starts from the paper's initial condition (tether straight behind the
aircraft, section 4), which takes about 40 s to settle (4.3, Fig. 19). So :func:`fig12_commands`
is: neutral flaps while the device settles after release (60 s, margin over the 40 s), a pitch
command of +10 deg (nose up, both horizontal flaps; paper Fig. 5) held 10 s (long enough for the
device to reach its new trim), neutral for 30 s (long enough for every UHMWPE case here to settle
again), a yaw command of +10 deg (nose right, both vertical flaps) held 10 s, and neutral for the
last 40 s. Commands are steps; the flap actuators' lag and rate limit shape them (README, ACCD).

**The maximum-tension case (Figs. 13, 14), as read here.** After the capture the RLV (80 t, lift
balancing its weight, drag 50 kN) hangs at the tether's end and the aircraft's four engines go to
their maximum thrust of 260 kN each, "while the TA is flying with minimum drag"; "associated forces
are applied on the ends of the tether" (4.1). At the tip: the RLV's mass (the tether's tip mass),
its drag (-50 kN along x) and its lift (-m g along z, so that lift balances weight). At the
attachment: the aircraft accelerates the whole train with the thrust left over after the RLV's drag,
``a = (F_thrust - D_TA - D_RLV) / (m_TA + m_RLV)``, which enters the tether as the frame
acceleration (every mass feels ``-m a``, paper 2.3.5). The paper gives neither the aircraft's mass
nor its drag: ``m_TA`` is the A340-600's maximum take-off mass, 368 t (Airbus; an assumption), and
``D_TA`` is taken as 0 (the "minimum drag" bound that maximises the tension). The run starts from
the towed cruise equilibrium (tension = RLV drag) and steps the thrust to maximum at
:data:`MAX_TENSION_STEP_S`; the quasi-static tension is then ``D_RLV + m_RLV a`` (plus the tether's
own small share), and the step makes the RLV's mass ring on the tether's axial spring
(``sqrt(k / m_RLV)``, about 1.4 rad/s). The air stays at 185 m/s (the speed gained over the window
changes only the tether's own drag, about 1 % of the tension). At several hundred kN the tether's
stiffest transverse mode is beyond RK4's stability limit at 0.01 s; the tether substeps such
steps automatically, so 0.01 s runs too and agrees with :data:`MAX_TENSION_TIME_STEP_S`
(kept, and giving the same tensions as 0.0025 s) to 1e-7 in the peak. :func:`max_tension_readings` lists what other readings of the paper would give.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

from accd_gym import _core
from accd_gym import files as _files

#: Flap deflection of the reconstructed Fig. 12 pitch and yaw commands, deg (paper 2.1: RANS data
#: up to 10 deg).
FIG12_DEFLECTION_DEG = 10.0
#: Neutral flaps after release before the first command, s (the paper's tether settles in about
#: 40 s, 4.3).
FIG12_RELEASE_S = 60.0
#: How long each command is held, s.
FIG12_HOLD_S = 10.0
#: Neutral flaps between the pitch and the yaw command, s.
FIG12_GAP_S = 30.0
#: Neutral flaps after the yaw command, s.
FIG12_TAIL_S = 40.0
#: Duration of the runs without flap commands (material, selected), s.
UNCOMMANDED_DURATION_S = 120.0
#: Time between samples of the recorded histories, s (a multiple of the physics step).
SAMPLE_INTERVAL_S = 0.05
#: A position counts as settled once it stays within this distance of its reference, m (2 % of
#: the paper's 50 m settled depth).
SETTLING_BAND_M = 1.0
#: The settled depth is the mean depth over this window before the first command (or the end), s.
SETTLED_WINDOW_S = 5.0
#: Wake seed of the runs in the aircraft's wake (Fig. 17).
WAKE_SEED = 1

#: Maximum thrust of one A340-600 engine at sea level, N (paper 4.1).
ENGINE_THRUST_N = 260e3
#: Number of engines of the A340-600 (paper 4.1).
ENGINES = 4
#: Maximum drag of the captured RLV, N (paper 4.1).
RLV_DRAG_N = 50e3
#: Mass of the RLV, kg (paper 2 and 4.1: about 80 t).
RLV_MASS_KG = 80e3
#: Mass of the towing aircraft, kg: the A340-600's maximum take-off mass (Airbus; not in the paper).
TA_MASS_KG = 368e3
#: Drag of the towing aircraft at full thrust, N: 0, the "minimum drag" bound that maximises the
#: tension (the paper gives no value).
TA_DRAG_N = 0.0
#: Time at which the thrust steps to maximum in the maximum-tension run, s.
MAX_TENSION_STEP_S = 5.0
#: Duration of the maximum-tension run, s.
MAX_TENSION_DURATION_S = 65.0
#: RK4 step of the maximum-tension run, s (plain RK4 at 0.01 s diverges under this load; the
#: substepped 0.01 s step agrees, see the module doc).
MAX_TENSION_TIME_STEP_S = 0.005
#: The paper's numbers for Fig. 14: tension "oscillates around 125 kN and peaks at approximately
#: 225 kN" (4.1), N.
PAPER_MAX_TENSION_MEAN_N = 125e3
PAPER_MAX_TENSION_PEAK_N = 225e3

STUDIES = ("material", "length", "diameter", "selected", "max-tension", "fig9")
#: Longer studies, run by name only (not by ``all``): :mod:`accd_gym.studies.fidelity`.
EXTRA_STUDIES = ("tension", "sweep")


@dataclass(frozen=True)
class CommandPhase:
    """Flap commands held over ``[start_s, end_s)``: pitch (nose up) and yaw (nose right), deg."""

    start_s: float
    end_s: float
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0


def fig12_commands(
    release_s: float = FIG12_RELEASE_S,
    hold_s: float = FIG12_HOLD_S,
    gap_s: float = FIG12_GAP_S,
    deflection_deg: float = FIG12_DEFLECTION_DEG,
) -> tuple[CommandPhase, ...]:
    """The reconstructed Fig. 12 commands (module doc): a pitch step, then a yaw step.

    Args:
        release_s: neutral flaps after release, s.
        hold_s: how long each command is held, s.
        gap_s: neutral flaps between the two commands, s.
        deflection_deg: pitch and yaw command, deg.

    Returns:
        The two command phases; outside them the flaps are neutral.
    """
    pitch = CommandPhase(release_s, release_s + hold_s, pitch_deg=deflection_deg)
    yaw_start = pitch.end_s + gap_s
    return (pitch, CommandPhase(yaw_start, yaw_start + hold_s, yaw_deg=deflection_deg))


def fig12_duration(phases: Sequence[CommandPhase], tail_s: float = FIG12_TAIL_S) -> float:
    """Run length for ``phases``: the last command's end plus ``tail_s``, s."""
    return max(p.end_s for p in phases) + tail_s


def command_at(phases: Sequence[CommandPhase], time: float) -> tuple[float, float]:
    """(pitch, yaw) command in deg at ``time`` (s); (0, 0) outside every phase."""
    for p in phases:
        if p.start_s <= time < p.end_s:
            return p.pitch_deg, p.yaw_deg
    return 0.0, 0.0


@dataclass(frozen=True)
class Case:
    """One open-loop run of the capture simulation.

    Attributes:
        key: short identifier, used in file and JSON names.
        label: legend text.
        preset: tether preset (``table3``, ``<material>-<L>m-<d>mm``).
        duration_s: simulated time, s.
        commands: flap command phases (empty: neutral flaps throughout).
        wake: fly in the aircraft's wake with its turbulence (wake seed :data:`WAKE_SEED`);
            otherwise calm air.
        paper: the paper's numbers for this case (text, with the figure), keyed like the metrics;
            missing keys are reported as "n/a".
        tether: overrides of the preset's tether config (the sweeps' readings); empty for the
            studies.
    """

    key: str
    label: str
    preset: str
    duration_s: float
    commands: tuple[CommandPhase, ...] = ()
    wake: bool = False
    paper: dict[str, str] = field(default_factory=dict)
    tether: dict[str, Any] = field(default_factory=dict)


@dataclass
class CaseResult:
    """Sampled history of one run (TA frame, SI).

    Attributes:
        case: the case run.
        time: sample times, s, shape (k,).
        position: the ACCD's centre of gravity (the tether tip), m, shape (k, 3).
        tension: tension at the attachment, N, shape (k,).
        command_deg: (pitch, yaw) command in force over the step ending at each sample, deg,
            shape (k, 2).
    """

    case: Case
    time: np.ndarray
    position: np.ndarray
    tension: np.ndarray
    command_deg: np.ndarray


def simulate_case(case: Case, sample_interval: float = SAMPLE_INTERVAL_S, bar: Any = None) -> CaseResult:
    """Runs ``case`` in :class:`accd_gym.CaptureSim` from the paper's initial condition.

    Args:
        case: what to run.
        sample_interval: time between recorded samples, s (rounded to whole physics steps).
        bar: a tqdm bar to advance by one per sample, or None.

    Returns:
        The sampled history.
    """
    config = {"tether": dict(case.tether)} if case.tether else None
    sim = _core.CaptureSim(config, tether_preset=case.preset, calm=not case.wake, seed=0, wake_seed=WAKE_SEED)
    steps = max(1, round(sample_interval / sim.time_step))
    samples = round(case.duration_s / (steps * sim.time_step))
    state = sim.state()
    times, positions, tensions, commands = (
        [state["time"]],
        [state["position"]],
        [state["attachment_tension"]],
        [(0.0, 0.0)],
    )
    for _ in range(samples):
        pitch, yaw = command_at(case.commands, sim.time)
        state = sim.step(_core.mix_flaps(pitch, yaw, 0.0), steps=steps)
        times.append(state["time"])
        positions.append(state["position"])
        tensions.append(state["attachment_tension"])
        commands.append((pitch, yaw))
        if bar is not None:
            bar.update(1)
    return CaseResult(case, np.asarray(times), np.asarray(positions), np.asarray(tensions), np.asarray(commands))


def settling_time(time: np.ndarray, signal: np.ndarray, reference: float, band: float = SETTLING_BAND_M) -> float:
    """Time (s, from ``time[0]``) after which ``signal`` stays within ``band`` of ``reference``.

    Returns ``time[-1] - time[0]`` if the last sample is still outside (not settled in the window).
    """
    outside = np.nonzero(np.abs(signal - reference) > band)[0]
    if outside.size == 0:
        return 0.0
    return float(time[min(outside[-1] + 1, time.size - 1)] - time[0])


def overshoot(signal: np.ndarray, reference: float, direction: float) -> float:
    """Largest excursion of ``signal`` beyond ``reference`` after it first reaches it, in its units.

    ``direction`` is the sign of the approach (+1: ``signal`` rises to ``reference``). The first
    swing past the reference is the oscillation amplitude of a settling response; 0 if the signal
    never reaches the reference.
    """
    reached = np.nonzero(direction * (signal - reference) >= 0.0)[0]
    if reached.size == 0:
        return 0.0
    return float(max(0.0, np.max(direction * (signal[reached[0] :] - reference))))


def case_metrics(result: CaseResult) -> dict[str, Any]:
    """The key numbers of one run (SI; see ``docs/paper-reproduction.md`` for the definitions).

    * ``settled_depth_m``: mean depth over the :data:`SETTLED_WINDOW_S` before the first command
      (or the end of an uncommanded run).
    * ``settling_time_s``: after release, when the depth stays within :data:`SETTLING_BAND_M` of it.
    * ``oscillation_amplitude_m``: the depth's first swing past the settled depth after release.
    * ``peak_tension_N``, ``mean_tension_N``: attachment tension over the whole run.
    * with commands: ``pitch_excursion_m`` (largest rise above the settled depth from the pitch
      command to the next command), ``pitch_overshoot_m`` / ``pitch_settling_time_s`` (the depth's
      swing past the settled depth, and the time to settle, after the pitch command ends), and the
      same for yaw (lateral position, reference 0: calm air is symmetric).
    """
    case, t, pos, tension = result.case, result.time, result.position, result.tension
    first = min((p.start_s for p in case.commands), default=case.duration_s)
    pre = t <= first + 1e-9
    window = pre & (t > first - SETTLED_WINDOW_S - 1e-9)
    settled = float(np.mean(pos[window, 2]))
    m: dict[str, Any] = {
        "settled_depth_m": settled,
        "settled_trail_m": float(-np.mean(pos[window, 0])),
        "settling_time_s": settling_time(t[pre], pos[pre, 2], settled),
        "oscillation_amplitude_m": overshoot(pos[pre, 2], settled, +1.0),
        "peak_tension_N": float(np.max(tension)),
        "mean_tension_N": float(np.mean(tension)),
        "settled_tension_N": float(np.mean(tension[window])),
    }
    phases = sorted(case.commands, key=lambda p: p.start_s)
    for i, p in enumerate(phases):
        axis, name, direction = (2, "pitch", +1.0) if p.pitch_deg else (1, "yaw", -math.copysign(1.0, p.yaw_deg))
        reference = settled if axis == 2 else 0.0
        nxt = phases[i + 1].start_s if i + 1 < len(phases) else case.duration_s
        during = (t >= p.start_s) & (t <= nxt + 1e-9)
        after = (t >= p.end_s) & (t <= nxt + 1e-9)
        moved = pos[during, axis] - reference
        m[f"{name}_excursion_m"] = float(np.max(np.abs(moved)))
        m[f"{name}_overshoot_m"] = overshoot(pos[after, axis], reference, direction)
        m[f"{name}_settling_time_s"] = settling_time(t[after], pos[after, axis], reference)
    if case.wake:
        # Turbulence keeps the device moving: a settling time to a 1 m band is not defined.
        # Report how much it moves about its settled position instead.
        for key in [k for k in m if k.endswith("settling_time_s")]:
            m[key] = None
        m["depth_std_settled_m"] = float(np.std(pos[window, 2]))
        m["lateral_std_settled_m"] = float(np.std(pos[window, 1]))
    return m


# ----------------------------------------------------------------------------------------------
# The maximum-tension case


@dataclass(frozen=True)
class MaxTensionCase:
    """Inputs of the maximum-tension case (paper 4.1, Figs. 13, 14; module doc), SI.

    Attributes:
        thrust_N: maximum thrust of all engines, N.
        rlv_drag_N: drag of the RLV, N.
        rlv_mass_kg: mass of the RLV (the tether's tip mass), kg.
        ta_mass_kg: mass of the towing aircraft, kg.
        ta_drag_N: drag of the towing aircraft at full thrust, N.
        preset: tether preset.
        step_s: time at which the thrust steps from cruise to maximum, s.
        duration_s: simulated time, s.
        time_step: RK4 step, s.
        airspeed: airspeed, m/s; altitude: m (ISA).
        pre_stretched: start from the towed cruise equilibrium (stretched by the RLV's drag, the
            RLV's drag and lift applied) and step the thrust at ``step_s`` (this study); False: the
            literal reading of section 4's initial condition, the tether straight and unstretched
            with every load applied from t = 0 (``step_s`` is then ignored).
    """

    thrust_N: float = ENGINES * ENGINE_THRUST_N
    rlv_drag_N: float = RLV_DRAG_N
    rlv_mass_kg: float = RLV_MASS_KG
    ta_mass_kg: float = TA_MASS_KG
    ta_drag_N: float = TA_DRAG_N
    preset: str = "table3"
    step_s: float = MAX_TENSION_STEP_S
    duration_s: float = MAX_TENSION_DURATION_S
    time_step: float = MAX_TENSION_TIME_STEP_S
    airspeed: float = 185.0
    altitude: float = 6000.0
    pre_stretched: bool = True

    def acceleration(self) -> float:
        """Acceleration of aircraft and RLV together at full thrust, m/s^2."""
        return (self.thrust_N - self.ta_drag_N - self.rlv_drag_N) / (self.ta_mass_kg + self.rlv_mass_kg)

    def quasi_static_tension(self) -> float:
        """Tension that pulls the RLV along at :meth:`acceleration`: D_RLV + m_RLV a, N."""
        return self.rlv_drag_N + self.rlv_mass_kg * self.acceleration()


@dataclass
class MaxTensionResult:
    """Sampled history of the maximum-tension run (TA frame, SI): ``time`` (s), ``tension`` at the
    attachment (N), ``position`` of the tip (m), and the inputs ``case``."""

    case: MaxTensionCase
    time: np.ndarray
    tension: np.ndarray
    position: np.ndarray


def simulate_max_tension(
    case: MaxTensionCase = MaxTensionCase(),
    sample_interval: float = SAMPLE_INTERVAL_S,
    bar: Any = None,
    overrides: Optional[dict[str, Any]] = None,
) -> MaxTensionResult:
    """Runs the maximum-tension case with :class:`accd_gym.Tether` (module doc).

    The tether starts straight behind the aircraft, stretched by the cruise tension (the RLV's
    drag), with the RLV at its tip; the thrust steps to maximum at ``case.step_s``.

    Args:
        case: the inputs.
        sample_interval: time between samples, s (rounded to whole steps).
        bar: a tqdm bar to advance by one per sample, or None.
        overrides: further tether config overrides (e.g. ``{"elasticity": "distributed",
            "segments": 10}``); with the distributed elasticity every element starts stretched by
            the cruise tension.
    """
    tether = _core.Tether(
        {"tip_mass": case.rlv_mass_kg, "time_step": case.time_step, **(overrides or {})}, preset=case.preset
    )
    tether.tow(airspeed=case.airspeed, altitude=case.altitude)
    cfg = tether.config
    lift = -case.rlv_mass_kg * cfg["gravity"]  # balances the RLV's weight (z down)
    tether.set_surroundings(tip_force=np.array([-case.rlv_drag_N, 0.0, lift]), frame_acceleration=np.zeros(3))
    directions = np.tile([-1.0, 0.0, 0.0], (tether.segments, 1))
    if not case.pre_stretched:
        case = dataclasses.replace(case, step_s=0.0)
    stretch = case.rlv_drag_N / cfg["axial_stiffness"] if case.pre_stretched else 0.0
    tether.set_state(directions, elongation=stretch)
    if tether.elasticity == "distributed" and case.pre_stretched:
        n = tether.segments
        q = tether.q
        q[0] = q[2 * n + 1 :] = case.rlv_drag_N / (n * cfg["axial_stiffness"])
        tether.set_coordinates(q, np.zeros_like(q))
    steps = max(1, round(sample_interval / tether.time_step))
    samples = round(case.duration_s / (steps * tether.time_step))
    step_sample = round(case.step_s / (steps * tether.time_step))
    times, tensions, positions = [tether.time], [tether.attachment_tension], [tether.tip_position]
    for i in range(samples):
        if i == step_sample:
            tether.set_surroundings(frame_acceleration=np.array([case.acceleration(), 0.0, 0.0]))
        tether.step(steps)
        times.append(tether.time)
        tensions.append(tether.attachment_tension)
        positions.append(tether.tip_position)
        if bar is not None:
            bar.update(1)
    return MaxTensionResult(case, np.asarray(times), np.asarray(tensions), np.asarray(positions))


def max_tension_metrics(result: MaxTensionResult) -> dict[str, Any]:
    """Key numbers of the maximum-tension run, N and s: tension before the step (cruise), mean,
    peak and minimum after it, the quasi-static value D_RLV + m_RLV a, the oscillation period
    (mean spacing of the tension's maxima) and the breaking tension of the tether."""
    c, t, T = result.case, result.time, result.tension
    loaded = t > c.step_s + 1e-9
    cruise = (t > c.step_s - 1.0) & ~loaded
    x = T[loaded] - np.mean(T[loaded])
    peaks = np.nonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:]) & (x[1:-1] > 0))[0] + 1
    period = float(np.mean(np.diff(t[loaded][peaks]))) if peaks.size > 1 else float("nan")
    return {
        "acceleration_m_per_s2": c.acceleration(),
        "quasi_static_tension_N": c.quasi_static_tension(),
        "cruise_tension_N": float(np.mean(T[cruise])),
        "mean_tension_N": float(np.mean(T[loaded])),
        "peak_tension_N": float(np.max(T[loaded])),
        "min_tension_N": float(np.min(T[loaded])),
        "oscillation_period_s": period,
        "axial_period_s": 2 * math.pi / math.sqrt(_core.tether_config(c.preset)["axial_stiffness"] / c.rlv_mass_kg),
        "breaking_tension_N": _core.tether_config(c.preset)["breaking_tension"],
        "paper_mean_tension_N": PAPER_MAX_TENSION_MEAN_N,
        "paper_peak_tension_N": PAPER_MAX_TENSION_PEAK_N,
    }


def max_tension_readings(case: MaxTensionCase = MaxTensionCase()) -> list[dict[str, Any]]:
    """Quasi-static tension (N) under other readings of the paper's case, and what its 125 kN
    mean would require; each entry has ``reading``, ``quasi_static_tension_N`` or a requirement."""
    sigma = _core.isa(case.altitude)["density"] / _core.isa(0.0)["density"]
    lapsed = MaxTensionCase(
        thrust_N=case.thrust_N * sigma,
        rlv_drag_N=case.rlv_drag_N,
        rlv_mass_kg=case.rlv_mass_kg,
        ta_mass_kg=case.ta_mass_kg,
        ta_drag_N=case.ta_drag_N,
    )
    needed_a = (PAPER_MAX_TENSION_MEAN_N - case.rlv_drag_N) / case.rlv_mass_kg
    return [
        {
            "reading": f"this study: thrust {case.thrust_N / 1e3:.0f} kN (sea level), TA drag "
            f"{case.ta_drag_N / 1e3:.0f} kN, TA {case.ta_mass_kg / 1e3:.0f} t",
            "quasi_static_tension_N": case.quasi_static_tension(),
        },
        {
            "reading": f"thrust lapsed with the density ratio at {case.altitude:.0f} m ({sigma:.3f})",
            "quasi_static_tension_N": lapsed.quasi_static_tension(),
        },
        {"reading": "RLV's drag alone (no acceleration)", "quasi_static_tension_N": case.rlv_drag_N},
        {
            "reading": "the paper's 125 kN mean needs this acceleration (m/s^2) of the 80 t RLV",
            "acceleration_m_per_s2": needed_a,
            "total_mass_kg_at_sea_level_thrust": (case.thrust_N - case.ta_drag_N - case.rlv_drag_N) / needed_a,
        },
    ]


# ----------------------------------------------------------------------------------------------
# The studies


def _paper_depth(text: str) -> dict[str, str]:
    return {"settled_depth_m": text}


def study_cases(study: str, commands: Optional[Sequence[CommandPhase]] = None) -> dict[str, list[Case]]:
    """The runs of ``study`` (not ``max-tension``), grouped by figure: {figure key: cases}.

    Args:
        study: one of ``material``, ``length``, ``diameter``, ``selected``.
        commands: flap commands for the commanded studies (default :func:`fig12_commands`).

    Raises:
        ValueError: an unknown study.
    """
    cmds = tuple(commands) if commands is not None else fig12_commands()
    dur = fig12_duration(cmds)
    still = UNCOMMANDED_DURATION_S
    fast = "settles quickly (Fig. 15); about 40 s for Table 3 (4.3)"
    if study == "material":
        return {
            "material": [
                Case(
                    "uhmwpe",
                    "UHMWPE 24 mm, 250 m",
                    "uhmwpe-250m-24mm",
                    still,
                    paper={"settled_depth_m": "about 50 (Fig. 15)", "settling_time_s": fast},
                ),
                Case(
                    "steel",
                    "steel 24 mm, 250 m",
                    "steel-250m-24mm",
                    still,
                    paper={
                        "settled_depth_m": "more than 100 (Fig. 15)",
                        "settling_time_s": "longer than UHMWPE (Fig. 15)",
                        "oscillation_amplitude_m": "oscillates longer (Fig. 15)",
                    },
                ),
            ]
        }
    if study == "length":
        longer = "greater amplitude, longer settling for 300 m (4.2)"
        calm = [
            Case(
                "150m",
                "150 m",
                "uhmwpe-150m-24mm",
                dur,
                cmds,
                paper={"pitch_excursion_m": "smaller than 300 m (Fig. 16)"},
            ),
            Case("250m", "250 m", "uhmwpe-250m-24mm", dur, cmds, paper=_paper_depth("about 50 (Figs. 15, 19)")),
            Case(
                "300m",
                "300 m",
                "uhmwpe-300m-24mm",
                dur,
                cmds,
                paper={
                    "settled_depth_m": "about 70 (Fig. 16b)",
                    "oscillation_amplitude_m": longer,
                    "settling_time_s": longer,
                    "pitch_excursion_m": "larger than 150 m (Fig. 16)",
                },
            ),
        ]
        wake_note = "both similarly affected by the wake (Fig. 17)"
        wake = [
            Case(
                "250m-wake",
                "250 m, in the wake",
                "uhmwpe-250m-24mm",
                dur,
                cmds,
                wake=True,
                paper={"settled_depth_m": wake_note},
            ),
            Case(
                "300m-wake",
                "300 m, in the wake",
                "uhmwpe-300m-24mm",
                dur,
                cmds,
                wake=True,
                paper={"settled_depth_m": wake_note},
            ),
        ]
        return {"length": calm, "length-wake": wake}
    if study == "diameter":
        more = "moves more than 24 / 32 mm (Fig. 18)"
        stiffer = "vibrations more pronounced, longer (Fig. 18)"
        return {
            "diameter": [
                Case(
                    "16mm",
                    "16 mm",
                    "uhmwpe-250m-16mm",
                    dur,
                    cmds,
                    paper={"pitch_excursion_m": more, "yaw_excursion_m": more},
                ),
                Case("24mm", "24 mm", "uhmwpe-250m-24mm", dur, cmds, paper=_paper_depth("about 50 (Figs. 15, 19)")),
                Case(
                    "32mm",
                    "32 mm",
                    "uhmwpe-250m-32mm",
                    dur,
                    cmds,
                    paper={"oscillation_amplitude_m": stiffer, "settling_time_s": stiffer},
                ),
            ]
        }
    if study == "selected":
        return {
            "selected": [
                Case(
                    "table3",
                    "Table 3 (UHMWPE 24 mm, 250 m)",
                    "table3",
                    still,
                    paper={"settled_depth_m": "about 50 (Fig. 19)", "settling_time_s": "about 40 (4.3)"},
                ),
            ]
        }
    raise ValueError(f"unknown study {study!r}; choose from {', '.join(STUDIES)}")


# ----------------------------------------------------------------------------------------------
# Output: plots, JSON, markdown

_METRIC_COLUMNS = (
    ("settled_depth_m", "settled depth [m]", 1.0, "{:.1f}"),
    ("settling_time_s", "settling time [s]", 1.0, "{:.1f}"),
    ("oscillation_amplitude_m", "oscillation amplitude [m]", 1.0, "{:.1f}"),
    ("peak_tension_N", "peak tension [kN]", 1e-3, "{:.2f}"),
    ("mean_tension_N", "mean tension [kN]", 1e-3, "{:.2f}"),
)
_MANOEUVRE_COLUMNS = (
    ("pitch_excursion_m", "pitch: rise [m]", 1.0, "{:.1f}"),
    ("pitch_overshoot_m", "pitch: swing back [m]", 1.0, "{:.1f}"),
    ("pitch_settling_time_s", "pitch: settling [s]", 1.0, "{:.1f}"),
    ("yaw_excursion_m", "yaw: lateral [m]", 1.0, "{:.1f}"),
    ("yaw_overshoot_m", "yaw: swing back [m]", 1.0, "{:.1f}"),
    ("yaw_settling_time_s", "yaw: settling [s]", 1.0, "{:.1f}"),
)


def _value(metrics: dict[str, Any], key: str, scale: float, fmt: str) -> str:
    value = metrics.get(key)
    return "-" if value is None else fmt.format(value * scale)


def _cell(metrics: dict[str, Any], paper: dict[str, str], key: str, scale: float, fmt: str) -> str:
    return f"{_value(metrics, key, scale, fmt)} (paper: {paper.get(key, 'n/a')})"


def markdown_table(rows: list[tuple[Case, dict[str, Any]]]) -> str:
    """Markdown tables of the key numbers, model beside paper ("n/a" where the paper gives none)."""
    lines = ["| case | " + " | ".join(c[1] for c in _METRIC_COLUMNS) + " |", "|---" * (len(_METRIC_COLUMNS) + 1) + "|"]
    for case, m in rows:
        cells = [_cell(m, case.paper, key, scale, fmt) for key, _, scale, fmt in _METRIC_COLUMNS]
        lines.append(f"| {case.label} | " + " | ".join(cells) + " |")
    commanded = [(c, m) for c, m in rows if c.commands]
    if commanded:
        lines += ["", "Response to the reconstructed Fig. 12 commands (paper: qualitative only):", ""]
        lines.append("| case | " + " | ".join(c[1] for c in _MANOEUVRE_COLUMNS) + " |")
        lines.append("|---" * (len(_MANOEUVRE_COLUMNS) + 1) + "|")
        for case, m in commanded:
            cells = []
            for key, _, scale, fmt in _MANOEUVRE_COLUMNS:
                value = _value(m, key, scale, fmt)
                cells.append(f"{value} (paper: {case.paper[key]})" if key in case.paper else value)
            lines.append(f"| {case.label} | " + " | ".join(cells) + " |")
    wake = [(c, m) for c, m in rows if c.wake]
    if wake:
        lines += [
            "",
            (
                "In the wake the turbulence keeps the device moving, so no settling time is given; "
                f"standard deviation of its position over the {SETTLED_WINDOW_S:.0f} s before the first command:"
            ),
            "",
        ]
        lines += [
            f"- {c.label}: depth {m['depth_std_settled_m']:.2f} m, lateral {m['lateral_std_settled_m']:.2f} m"
            for c, m in wake
        ]
    return "\n".join(lines) + "\n"


def max_tension_markdown(m: dict[str, Any], readings: list[dict[str, Any]]) -> str:
    """Markdown table of the maximum-tension case beside the paper's Fig. 14, and the readings."""

    def kn(value: float) -> str:
        return f"{value / 1e3:.1f}"

    lines = [
        "| quantity | model | paper |",
        "|---|---|---|",
        f"| mean tension after full thrust [kN] | {kn(m['mean_tension_N'])} | about {kn(m['paper_mean_tension_N'])} (Fig. 14) |",
        f"| peak tension [kN] | {kn(m['peak_tension_N'])} | about {kn(m['paper_peak_tension_N'])} (Fig. 14) |",
        f"| quasi-static D_RLV + m_RLV a [kN] | {kn(m['quasi_static_tension_N'])} | n/a |",
        f"| tension in cruise before the step [kN] | {kn(m['cruise_tension_N'])} | n/a |",
        f"| lowest tension after the step [kN] | {kn(m['min_tension_N'])} | n/a |",
        (
            f"| oscillation period [s] (axial mode 2 pi sqrt(m_RLV / k): {m['axial_period_s']:.2f}) "
            f"| {m['oscillation_period_s']:.2f} | n/a |"
        ),
        f"| acceleration of aircraft and RLV [m/s^2] | {m['acceleration_m_per_s2']:.3f} | n/a |",
        f"| breaking tension, 24 mm UHMWPE [kN] | {kn(m['breaking_tension_N'])} | 550 (Table 2) |",
        "",
        "| other reading | quasi-static tension [kN] |",
        "|---|---|",
    ]
    for r in readings:
        if "quasi_static_tension_N" in r:
            lines.append(f"| {r['reading']} | {kn(r['quasi_static_tension_N'])} |")
        else:
            lines.append(
                f"| {r['reading']} | a = {r['acceleration_m_per_s2']:.3f}; with sea-level thrust and no TA drag "
                f"that is a train of {r['total_mass_kg_at_sea_level_thrust'] / 1e3:.0f} t |"
            )
    return "\n".join(lines) + "\n"


def _shade(ax: Any, commands: Sequence[CommandPhase]) -> None:
    for p in commands:
        color = "tab:orange" if p.pitch_deg else "tab:purple"
        ax.axvspan(p.start_s, p.end_s, color=color, alpha=0.12, lw=0)


def plot_cases(results: list[CaseResult], path: Path, title: str, dpi: int = 90) -> None:
    """Saves lateral and vertical position of the ACCD behind the aircraft, and the attachment
    tension, over time (one line per case; shaded: pitch command orange, yaw purple)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    panels = (
        (lambda r: r.position[:, 1], "lateral position y [m] (starboard +)", "(a) lateral"),
        (lambda r: -r.position[:, 2], "height relative to the aircraft [m] (up +)", "(b) vertical"),
        (lambda r: r.tension / 1e3, "tension at the attachment [kN]", "tension"),
    )
    for ax, (get, ylabel, name) in zip(axes, panels):
        for r in results:
            ax.plot(r.time, get(r), lw=1.0, label=r.case.label)
        _shade(ax, results[0].case.commands)
        low, high = ax.get_ylim()
        if high - low < 2.0:  # a flat line (no lateral motion): show it on a metre scale
            mid = 0.5 * (low + high)
            ax.set_ylim(mid - 1.0, mid + 1.0)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(ylabel)
        ax.set_title(name, fontsize=10)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=11)
    _files.save_figure(fig, path, dpi=dpi)
    plt.close(fig)


def plot_max_tension(result: MaxTensionResult, metrics: dict[str, Any], path: Path, dpi: int = 90) -> None:
    """Saves the attachment tension over time with the paper's Fig. 14 levels, and the tether's
    stretch (the tip's distance behind the aircraft minus the tether length)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = result.case
    length = _core.tether_config(c.preset)["length"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6), constrained_layout=True)
    ax = axes[0]
    ax.plot(result.time, result.tension / 1e3, lw=1.0, label="model")
    ax.axhline(metrics["mean_tension_N"] / 1e3, color="tab:blue", ls="--", lw=0.8, label="model mean")
    ax.axhline(PAPER_MAX_TENSION_MEAN_N / 1e3, color="tab:red", ls=":", lw=1.0, label="paper: about 125 kN")
    ax.axhline(PAPER_MAX_TENSION_PEAK_N / 1e3, color="tab:red", ls="-.", lw=1.0, label="paper peak: about 225 kN")
    ax.axvline(c.step_s, color="tab:gray", lw=0.7)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("tension at the attachment [kN]")
    ax.set_title("tension (full thrust from the grey line)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.plot(result.time, -result.position[:, 0] - length, lw=1.0)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("tip behind the aircraft minus L [m]")
    ax.set_title("stretch of the tether", fontsize=10)
    ax.grid(True, alpha=0.3)
    fig.suptitle(
        f"maximum tension: {c.thrust_N / 1e3:.0f} kN thrust, RLV {c.rlv_mass_kg / 1e3:.0f} t with "
        f"{c.rlv_drag_N / 1e3:.0f} kN drag, TA {c.ta_mass_kg / 1e3:.0f} t, {c.preset}",
        fontsize=11,
    )
    _files.save_figure(fig, path, dpi=dpi)
    plt.close(fig)
