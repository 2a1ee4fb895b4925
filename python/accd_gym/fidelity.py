"""Fidelity past the paper (issue 18, items 3-5): Fig. 9 reproduced, the tension under both
elasticities, and the sweeps behind the two open claims of ``docs/paper-reproduction.md``.

Run by ``accd-gym study fig9`` (part of ``all``), ``accd-gym study tension`` and ``accd-gym study
sweep`` (both longer, not part of ``all``). Each writes a PNG, ``<study>.json`` and ``<study>.md``
like the other studies (:mod:`accd_gym.study`). SI units in the towing-aircraft frame (x forward,
z down) unless a name says otherwise.

**Fig. 9 (paper 2.3.6).** Table 1's 10 m chain (n = 4, m_tot = 5 kg, k = 10 000 N/m, c1 = 20 N m s/kg
on the joints and as the axial damping per mass, no air), (a) hanging vertically, released
unstretched, stretching under its own weight; (b) released at rest with every segment at
phi = psi = pi/4, swinging. The paper's "simplified" model is the default attachment element (k,
c_s = c1 m_tot); its "full model" has "springs at every joint". The paper does not say how stiff
each of those springs is, so two readings are run (:data:`FIG9_MODELS`):

* ``full (n k)``: every element ``n k``, ``n c_s``, so the n in series have the whole tether's k
  and c_s and the static stretch under a tip load is the simplified model's (our
  ``elasticity = "distributed"``);
* ``full (k per joint)``: Table 1's ``k`` (and ``c_s``) at every joint, i.e. the distributed
  model with ``axial_stiffness = k / n``, ``axial_damping_per_mass = c1 / n``: a chain n times
  softer in series.

RK4 at :data:`FIG9_TIME_STEP_S` (the chain's axial ring is 7 Hz), every step sampled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

import accd_gym

#: Simulated time of each Fig. 9 run, s (four swings of case (b)).
FIG9_DURATION_S = 10.0
#: RK4 step of the Fig. 9 runs, s (sampled every step).
FIG9_TIME_STEP_S = 1e-3
#: Case (b) starts from phi = psi = pi/4 (paper 2.3.6), rad.
FIG9_RELEASE_ANGLE_RAD = math.pi / 4
#: Case (a) is plotted over its first seconds (the axial ring; the level then stays), s.
FIG9_VERTICAL_PLOT_S = 2.0
#: In case (b) the elongation's swing oscillation is measured after this time, when the axial
#: ring of the release has decayed, s.
FIG9_SWING_FROM_S = 1.0


@dataclass(frozen=True)
class Fig9Model:
    """One elongation model of Fig. 9: ``key``, legend ``label`` and the overrides of Table 1's
    preset that make it (a function of Table 1's config, so that a changed preset follows)."""

    key: str
    label: str

    def overrides(self, table1: dict[str, Any]) -> dict[str, Any]:
        """Config overrides of the ``table1`` preset (given as its dict) for this model."""
        if self.key == "simplified":
            return {}
        if self.key == "full-nk":
            return {"elasticity": "distributed"}
        if self.key == "full-k":
            n = table1["segments"]
            return {
                "elasticity": "distributed",
                "axial_stiffness": table1["axial_stiffness"] / n,
                "axial_damping_per_mass": table1["axial_damping_per_mass"] / n,
            }
        raise ValueError(f"unknown Fig. 9 model {self.key!r}")


#: The models of Fig. 9 (module doc).
FIG9_MODELS = (
    Fig9Model("simplified", "simplified (one element k at the attachment)"),
    Fig9Model("full-nk", "full, elements n k (same static tip-load stretch)"),
    Fig9Model("full-k", "full, Table 1's k at every joint"),
)
#: The cases of Fig. 9: key, title.
FIG9_CASES = (
    ("vertical", "(a) vertical tether stretching under its own weight"),
    ("swing", "(b) swing released from phi = psi = pi/4"),
)


def fig9_tether(model: Fig9Model, case: str, time_step: float = FIG9_TIME_STEP_S) -> accd_gym.Tether:
    """Table 1's chain under ``model`` in the start state of ``case`` (``vertical`` or ``swing``),
    at rest and unstretched, in vacuum."""
    table1 = accd_gym.tether_config("table1")
    tether = accd_gym.Tether({"time_step": time_step, **model.overrides(table1)}, preset="table1")
    n = tether.segments
    if case == "vertical":
        tether.set_state(np.tile([0.0, 0.0, 1.0], (n, 1)))
    elif case == "swing":
        angle = np.full(n, FIG9_RELEASE_ANGLE_RAD)
        tether.set_angles(angle, angle)
    else:
        raise ValueError(f"unknown Fig. 9 case {case!r}; choose from vertical, swing")
    return tether


def simulate_fig9(
    model: Fig9Model, case: str, duration_s: float = FIG9_DURATION_S, time_step: float = FIG9_TIME_STEP_S
) -> tuple[np.ndarray, np.ndarray]:
    """Runs one Fig. 9 case; returns (time in s, total elongation in m), sampled every step from
    t = 0."""
    tether = fig9_tether(model, case, time_step)
    steps = round(duration_s / time_step)
    time, elongation = np.empty(steps + 1), np.empty(steps + 1)
    time[0], elongation[0] = tether.time, tether.total_elongation
    for i in range(1, steps + 1):
        tether.step(1)
        time[i], elongation[i] = tether.time, tether.total_elongation
    return time, elongation


def _maxima(x: np.ndarray) -> np.ndarray:
    return np.nonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:]))[0] + 1


def fig9_metrics(case: str, time: np.ndarray, elongation: np.ndarray) -> dict[str, float]:
    """Amplitude (m) and frequency (Hz) of the elongation's oscillation in one Fig. 9 run.

    * ``vertical``: the axial ring of the release. ``static_m`` the level it settles to (mean over
      the last second), ``first_peak_m``, ``amplitude_m`` = first peak minus the static level,
      ``frequency_hz`` from the first two maxima.
    * ``swing``: the elongation follows the swing (it peaks as the chain passes the bottom, twice
      per swing). After :data:`FIG9_SWING_FROM_S`: ``amplitude_m`` half the range,
      ``mean_m`` the mean, ``frequency_hz`` from the spacing of the maxima of the elongation
      smoothed over 0.2 s (the axial ring is gone by then), ``first_peak_m`` the largest value
      before it (the release's ring).
    """
    if case == "vertical":
        static = float(np.mean(elongation[time >= time[-1] - 1.0]))
        peaks = _maxima(elongation)
        first = float(elongation[peaks[0]]) if peaks.size else float("nan")
        freq = 1.0 / float(time[peaks[1]] - time[peaks[0]]) if peaks.size > 1 else float("nan")
        return {"static_m": static, "first_peak_m": first, "amplitude_m": first - static, "frequency_hz": freq}
    late = time >= FIG9_SWING_FROM_S
    t, s = time[late], elongation[late]
    dt = float(time[1] - time[0])
    width = max(1, round(0.2 / dt))
    smooth = np.convolve(s, np.ones(width) / width, mode="valid")
    peaks = _maxima(smooth)
    freq = 1.0 / float(np.mean(np.diff(t[peaks]))) if peaks.size > 1 else float("nan")
    return {
        "mean_m": float(np.mean(s)),
        "amplitude_m": 0.5 * float(np.max(s) - np.min(s)),
        "frequency_hz": freq,
        "first_peak_m": float(np.max(elongation[~late])),
    }


def fig9_closed_forms() -> dict[str, float]:
    """What the vertical case must give, from Table 1 alone: the simplified model's static stretch
    ``M g / k`` and axial ring ``sqrt(k / M) / 2 pi`` (the element carries the whole chain; damped
    by ``zeta = c_s / 2 sqrt(k M)``), and the full model's (elements ``n k``) hanging stretch
    ``(n + 1) / (2 n) M g / k`` (rods lumped: docs/design-notes.md)."""
    c = accd_gym.tether_config("table1")
    n, k, mass, g = c["segments"], c["axial_stiffness"], c["mass_per_length"] * c["length"], c["gravity"]
    zeta = c["axial_damping_per_mass"] * mass / (2.0 * math.sqrt(k * mass))
    return {
        "simplified_static_m": mass * g / k,
        "simplified_frequency_hz": math.sqrt(k / mass) * math.sqrt(1.0 - zeta**2) / (2.0 * math.pi),
        "simplified_damping_ratio": zeta,
        "full_nk_static_m": (n + 1) / (2.0 * n) * mass * g / k,
        "full_k_static_m": n * (n + 1) / (2.0 * n) * mass * g / k,
    }


def run_fig9(out_dir: Path, dpi: int = 90, duration_s: float = FIG9_DURATION_S) -> tuple[dict[str, Any], str]:
    """Runs Fig. 9 (both cases, every model), plots it side by side as the paper does, and returns
    (the JSON document, the markdown) for :func:`accd_gym.study.run_study` to write."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 3.8), constrained_layout=True)
    results: dict[str, dict[str, Any]] = {}
    for ax, (case, title) in zip(axes, FIG9_CASES):
        results[case] = {}
        for model in FIG9_MODELS:
            t, s = simulate_fig9(model, case, duration_s)
            results[case][model.key] = fig9_metrics(case, t, s)
            ax.plot(t, s * 1e3, lw=0.9, label=model.label)
        if case == "vertical":
            ax.set_xlim(0.0, min(FIG9_VERTICAL_PLOT_S, duration_s))  # the ring; then it stays level
        ax.set_xlabel("time [s]")
        ax.set_ylabel("elongation of the tether [mm]")
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("Fig. 9: comparison of elongation approaches (Table 1: n = 4, L = 10 m, 5 kg, k = 1e4 N/m, c1 = 20)")
    fig.savefig(out_dir / "fig9.png", dpi=dpi)
    plt.close(fig)
    closed = fig9_closed_forms()
    verdict = fig9_verdict(results)
    doc = {
        "study": "fig9",
        "figures": ["fig9.png"],
        "inputs": {
            "preset": "table1",
            "time_step": FIG9_TIME_STEP_S,
            "duration_s": duration_s,
            "models": {m.key: {"label": m.label, "overrides": m.overrides(accd_gym.tether_config("table1"))} for m in FIG9_MODELS},
        },
        "cases": results,
        "closed_forms": closed,
        "paper": "the full model 'appears to have larger amplitude of oscillations' in both (a) and (b) (2.3.6)",
        "verdict": verdict,
    }
    lines = [
        "## fig9 (paper 2.3.6, Fig. 9)",
        "",
        "![fig9](fig9.png)",
        "",
        "| case | model | amplitude [mm] | frequency [Hz] | level [mm] | first peak [mm] |",
        "|---|---|---|---|---|---|",
    ]
    for case, _ in FIG9_CASES:
        for model in FIG9_MODELS:
            m = results[case][model.key]
            level = m.get("static_m", m.get("mean_m"))
            lines.append(
                f"| {case} | {model.label} | {m['amplitude_m'] * 1e3:.2f} | {m['frequency_hz']:.2f} | "
                f"{level * 1e3:.2f} | {m['first_peak_m'] * 1e3:.2f} |"
            )
    lines += [
        "",
        (
            "Level: the static stretch (vertical) or the mean over the swing (swing). Closed forms (vertical): "
            f"simplified M g / k = {closed['simplified_static_m'] * 1e3:.2f} mm ringing at "
            f"{closed['simplified_frequency_hz']:.2f} Hz; full (n k) (n + 1)/(2n) M g / k = "
            f"{closed['full_nk_static_m'] * 1e3:.2f} mm; full (k per joint) {closed['full_k_static_m'] * 1e3:.2f} mm."
        ),
        "",
        verdict,
        "",
    ]
    return doc, "\n".join(lines)


def fig9_verdict(results: dict[str, dict[str, Any]]) -> str:
    """The sentence comparing the models' amplitudes with the paper's "the full model has larger
    amplitude", from the measured amplitudes."""

    def ratio(case: str, key: str) -> float:
        return results[case][key]["amplitude_m"] / results[case]["simplified"]["amplitude_m"]

    parts = []
    for key, name in (("full-nk", "with elements n k"), ("full-k", "with Table 1's k at every joint")):
        rv, rs = ratio("vertical", key), ratio("swing", key)
        agree = "as the paper says" if rv > 1 and rs > 1 else ("against the paper" if rv < 1 and rs < 1 else "in part as the paper says")
        parts.append(
            f"the full model {name} has {rv:.2f} times the simplified model's amplitude in (a) and {rs:.2f} times in (b) ({agree})"
        )
    return (
        "Paper: the full model 'appears to have larger amplitude of oscillations' in (a) and (b). Here "
        + "; ".join(parts)
        + ". So the paper's observation holds if its full model put Table 1's k at every joint (a chain n times softer), "
        "not if the elements are stiffened to keep the tether's k."
        if ratio("vertical", "full-k") > 1 and ratio("swing", "full-k") > 1 and ratio("vertical", "full-nk") < 1
        else "Paper: the full model 'appears to have larger amplitude of oscillations' in (a) and (b). Here " + "; ".join(parts) + "."
    )


# ----------------------------------------------------------------------------------------------
# Item 4: the tension under both elasticities


@dataclass(frozen=True)
class TensionRun:
    """One tether discretization of the tension study: ``elasticity``, ``segments`` and the RK4
    ``time_step`` (s) it needs (the distributed model's stiff axial modes set it, see
    :data:`TENSION_RUNS`); ``window_s`` limits the maximum-tension run to its first seconds
    (None: the whole run)."""

    elasticity: str
    segments: int
    time_step: float
    window_s: Optional[float] = None

    @property
    def key(self) -> str:
        """Short name, ``<elasticity>-n<segments>-dt<time_step>``."""
        return f"{self.elasticity}-n{self.segments}-dt{self.time_step:g}"

    def overrides(self) -> dict[str, Any]:
        """Tether config overrides of this run."""
        return {"elasticity": self.elasticity, "segments": self.segments, "time_step": self.time_step}


#: The runs of the tension study. With Table 3's axial damping (c_k = 100 per kg) the distributed
#: model's highest axial mode is overdamped with a rate of about ``4 n c_s / m = 4 n^2 c_s / m_tot``
#: (3.6e5 1/s at n = 30, 4e4 at n = 10, 1e4 at n = 5), so its stable step falls as 1/n^2
#: (6.25e-6 s at n = 30). The damping is the paper's (no other reading of it is taken): the
#: discretization is what changes. The elasticity is compared at equal n (5 and 10, the whole
#: runs) and at the study's n = 30 over the peak of the maximum-tension run only (its first
#: :data:`TENSION_N30_WINDOW_S`). Steps: each the largest of 0.01 / 0.005 / 0.002 ... s that
#: needs at most :data:`accd_gym` MAX_SUBSTEPS (64) substeps; the attachment runs at the study's
#: steps (the maximum-tension study's 0.005 s, the capture's 0.01 s).
TENSION_N30_WINDOW_S = 10.0
TENSION_RUNS = (
    TensionRun("attachment", 30, 0.005),
    TensionRun("attachment", 10, 0.005),
    TensionRun("attachment", 5, 0.005),
    TensionRun("distributed", 5, 0.005),
    TensionRun("distributed", 10, 0.002),
    TensionRun("distributed", 30, 2.5e-4, window_s=TENSION_N30_WINDOW_S),
)
#: The capture episode of the tension study: the default env (wake and turbulence) flown by the
#: default guidance baseline from this reset seed (it captures after 16.8 s).
CAPTURE_SEED = 3
#: Before the replayed commands the tether settles this long behind the aircraft with neutral
#: flaps (the env's ``initial.settle_time``), s.
CAPTURE_SETTLE_S = 40.0
#: The capture runs: the elasticity at the env's n = 30 (both at the distributed model's
#: 2.5e-4 s step, and the attachment model also at the env's 0.01 s) and at n = 10 (0.002 s).
CAPTURE_RUNS = (
    TensionRun("attachment", 30, 0.01),
    TensionRun("attachment", 30, 2.5e-4),
    TensionRun("distributed", 30, 2.5e-4),
    TensionRun("attachment", 10, 0.002),
    TensionRun("distributed", 10, 0.002),
)


def guidance_episode(seed: int = CAPTURE_SEED) -> dict[str, Any]:
    """One episode of the default env flown by :class:`accd_gym.baselines.GuidancePolicy`: its
    flap commands (deg, shape (k, 4), one per agent step), agent step (s), wake seed, the peak
    attachment tension per agent step (N) and whether it captured."""
    import gymnasium as gym

    from accd_gym.baselines import GuidancePolicy

    env = gym.make(accd_gym.ENV_ID)
    policy = GuidancePolicy()
    obs, info = env.reset(seed=seed)
    wake_seed, actions, peaks, done = info["wake_seed"], [], [], False
    while not done:
        action = policy.predict(obs[None])[0]
        actions.append(action)
        obs, _, terminated, truncated, info = env.step(action)
        peaks.append(info["peak_tension"])
        done = terminated or truncated
    cfg = env.unwrapped.config
    env.close()
    return {
        "flap_commands_deg": np.asarray(actions) * cfg["accd"]["flap_limit_deg"],
        "agent_step": cfg["agent_step"],
        "wake_seed": int(wake_seed),
        "peak_tension_N": np.asarray(peaks),
        "captured": bool(info["captured"]),
        "seed": seed,
    }


def replay_capture(episode: dict[str, Any], run: TensionRun) -> tuple[np.ndarray, np.ndarray]:
    """The episode's flap commands replayed open loop in :class:`accd_gym.CaptureSim` (the same
    wake seed, wake and turbulence on) under ``run``'s tether, after :data:`CAPTURE_SETTLE_S` of
    settling with neutral flaps. Returns (time from the first command in s, attachment tension in
    N), every physics step."""
    sim = accd_gym.CaptureSim({"tether": run.overrides()}, seed=0, wake_seed=episode["wake_seed"])
    sim.settle(CAPTURE_SETTLE_S)
    start = sim.time
    per_command = round(episode["agent_step"] / sim.time_step)
    time, tension = [], []
    for command in episode["flap_commands_deg"]:
        for _ in range(per_command):
            state = sim.step(command, steps=1)
            time.append(state["time"] - start)
            tension.append(state["attachment_tension"])
    return np.asarray(time), np.asarray(tension)


def run_tension(out_dir: Path, dpi: int = 90, progress: bool = True) -> tuple[dict[str, Any], str]:
    """Item 4: the maximum-tension case (:func:`accd_gym.study.simulate_max_tension`) and one
    capture episode's tension (:func:`replay_capture`) under both elasticities, the peak ratios,
    and what they say about the paper's factor of safety of 3. Writes ``tension.png``."""
    import time as clock

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from accd_gym import study

    base = study.MaxTensionCase()
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.8), constrained_layout=True)
    max_runs: dict[str, Any] = {}
    for run in TENSION_RUNS:
        case = study.MaxTensionCase(
            duration_s=run.window_s if run.window_s is not None else base.duration_s, time_step=run.time_step
        )
        sample = run.time_step * max(1, round(0.01 / run.time_step))
        cpu = clock.process_time()
        result = study.simulate_max_tension(case, sample_interval=sample, overrides=run.overrides())
        cpu = clock.process_time() - cpu
        m = study.max_tension_metrics(result)
        max_runs[run.key] = {
            "elasticity": run.elasticity,
            "segments": run.segments,
            "time_step": run.time_step,
            "duration_s": case.duration_s,
            "cpu_s": cpu,
            "cpu_s_per_simulated_s": cpu / case.duration_s,
            "peak_tension_N": m["peak_tension_N"],
            "mean_tension_N": m["mean_tension_N"] if run.window_s is None else None,
            "oscillation_period_s": m["oscillation_period_s"] if run.window_s is None else None,
        }
        if progress:
            print(f"tension: max-tension {run.key}: peak {m['peak_tension_N'] / 1e3:.1f} kN, {cpu:.1f} s CPU")
        axes[0].plot(result.time, result.tension / 1e3, lw=0.9, label=run.key)
    episode = guidance_episode()
    cap_runs: dict[str, Any] = {}
    for run in CAPTURE_RUNS:
        cpu = clock.process_time()
        t, tension = replay_capture(episode, run)
        cpu = clock.process_time() - cpu
        cap_runs[run.key] = {
            "elasticity": run.elasticity,
            "segments": run.segments,
            "time_step": run.time_step,
            "cpu_s": cpu,
            "peak_tension_N": float(np.max(tension)),
            "mean_tension_N": float(np.mean(tension)),
        }
        if progress:
            print(f"tension: capture {run.key}: peak {np.max(tension) / 1e3:.2f} kN, {cpu:.1f} s CPU")
        axes[1].plot(t, tension / 1e3, lw=0.8, label=run.key)
    axes[0].axhline(study.PAPER_MAX_TENSION_PEAK_N / 1e3, color="tab:red", ls="-.", lw=0.8, label="paper peak")
    axes[0].set_title("maximum-tension case (full thrust at 5 s)", fontsize=10)
    axes[1].set_title(
        f"capture episode (seed {episode['seed']}, guidance commands replayed after {CAPTURE_SETTLE_S:.0f} s)", fontsize=10
    )
    for ax in axes:
        ax.set_xlabel("time [s]")
        ax.set_ylabel("tension at the attachment [kN]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("Attachment tension: simplified (attachment) vs full (distributed) elasticity")
    fig.savefig(out_dir / "tension.png", dpi=dpi)
    plt.close(fig)

    def ratio(runs: dict[str, Any], a: str, b: str) -> float:
        return runs[a]["peak_tension_N"] / runs[b]["peak_tension_N"]

    ratios = {
        "max_tension_distributed_over_attachment_n5": ratio(max_runs, "distributed-n5-dt0.005", "attachment-n5-dt0.005"),
        "max_tension_distributed_over_attachment_n10": ratio(max_runs, "distributed-n10-dt0.002", "attachment-n10-dt0.005"),
        "max_tension_distributed_over_attachment_n30": ratio(max_runs, "distributed-n30-dt0.00025", "attachment-n30-dt0.005"),
        "capture_distributed_over_attachment_n30": ratio(cap_runs, "distributed-n30-dt0.00025", "attachment-n30-dt0.00025"),
        "capture_distributed_over_attachment_n10": ratio(cap_runs, "distributed-n10-dt0.002", "attachment-n10-dt0.002"),
        "capture_attachment_step_2.5e-4_over_0.01_n30": ratio(cap_runs, "attachment-n30-dt0.00025", "attachment-n30-dt0.01"),
        "capture_attachment_n10_over_n30": ratio(cap_runs, "attachment-n10-dt0.002", "attachment-n30-dt0.01"),
    }
    breaking = accd_gym.tether_config("table3")["breaking_tension"]
    peak = max_runs["attachment-n30-dt0.005"]["peak_tension_N"]
    doc = {
        "study": "tension",
        "figures": ["tension.png"],
        "max_tension": max_runs,
        "capture": {
            "seed": episode["seed"],
            "wake_seed": episode["wake_seed"],
            "captured_in_env": episode["captured"],
            "commands": len(episode["flap_commands_deg"]),
            "env_peak_tension_N": float(np.max(episode["peak_tension_N"])),
            "runs": cap_runs,
        },
        "peak_ratios": ratios,
        "breaking_tension_N": breaking,
        "safety_factor_on_peak": breaking / peak,
    }
    lines = [
        "## tension (issue 18 item 4)",
        "",
        "![tension](tension.png)",
        "",
        "| run | case | n | step [s] | simulated [s] | peak [kN] | mean [kN] | CPU [s] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for key, r in max_runs.items():
        mean = "-" if r["mean_tension_N"] is None else f"{r['mean_tension_N'] / 1e3:.1f}"
        lines.append(
            f"| {key} | max-tension | {r['segments']} | {r['time_step']:g} | {r['duration_s']:.0f} | "
            f"{r['peak_tension_N'] / 1e3:.1f} | {mean} | {r['cpu_s']:.1f} |"
        )
    for key, r in cap_runs.items():
        lines.append(
            f"| {key} | capture | {r['segments']} | {r['time_step']:g} | "
            f"{len(episode['flap_commands_deg']) * episode['agent_step']:.1f} | {r['peak_tension_N'] / 1e3:.2f} | "
            f"{r['mean_tension_N'] / 1e3:.2f} | {r['cpu_s']:.1f} |"
        )
    lines += ["", "| peak ratio | value |", "|---|---|"]
    lines += [f"| {k} | {v:.4f} |" for k, v in ratios.items()]
    lines += [
        "",
        (
            f"Breaking tension {breaking / 1e3:.0f} kN over the model's peak {peak / 1e3:.0f} kN: a margin of "
            f"{breaking / peak:.2f}. The full model moves the peaks by "
            f"{100 * (ratios['max_tension_distributed_over_attachment_n30'] - 1):+.2f} % (max-tension, n = 30) and "
            f"{100 * (ratios['capture_distributed_over_attachment_n30'] - 1):+.2f} % (capture, n = 30); "
            f"the discretization alone (attachment, n = 10 against 30) moves the capture's by "
            f"{100 * (ratios['capture_attachment_n10_over_n30'] - 1):+.2f} %."
        ),
        "",
    ]
    return doc, "\n".join(lines)


def run_study(study: str, out_dir: Path, dpi: int = 90, progress: bool = True) -> tuple[dict[str, Any], str]:
    """Runs ``fig9``, ``tension`` or ``sweep`` into ``out_dir`` (its PNGs); returns (the JSON
    document, the markdown) for :func:`accd_gym.study.run_study` to write."""
    if study == "fig9":
        return run_fig9(out_dir, dpi=dpi)
    if study == "tension":
        return run_tension(out_dir, dpi=dpi, progress=progress)
    raise ValueError(f"unknown study {study!r}")
