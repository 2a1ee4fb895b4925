"""The towed tether settling behind the aircraft (paper Fig. 19): simulate, summarise, plot."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from accd_gym._core import stand_in_body, towed_tether
from accd_gym import files as _files
from accd_gym.errors import ConfigError

#: Depth band, as a fraction of the final depth, used for the settling time.
SETTLING_BAND = 0.02
#: The files :func:`run` writes into its folder.
OUTPUT_FILES = ("summary.json", "settle.png", "history.npz")
#: The longest simulated time :func:`simulate` takes, s (an hour of towing; the histories are
#: kept in memory, 10 samples a second).
MAX_DURATION_S = 3600.0
#: Times (s) at which the tether's shape is kept for the side-view plot (plus the final time).
SNAPSHOT_TIMES = (1.0, 2.0, 4.0, 6.0, 10.0, 20.0)


@dataclass
class SettleResult:
    """Time histories and key numbers of one settling run (SI units, TA frame, z down).

    Attributes:
        time: sample times, s, shape (k,).
        tip: tip positions, m, shape (k, 3).
        attachment_tension: tension at the attachment, N, shape (k,).
        snapshots: joint positions at a few times, m, each shape (n + 1, 3), with the attachment
            origin prepended.
        snapshot_times: the times of ``snapshots``, s.
        final_depth: tip depth below the aircraft at the end, m.
        final_trail: tip distance behind the aircraft at the end, m.
        settling_time: time after which the depth stays within 2 % of its final value, s.
        final_tension: attachment tension at the end, N.
        tip_speed: tip speed relative to the aircraft at the end, m/s.
        config: the tether configuration used.
    """

    time: np.ndarray
    tip: np.ndarray
    attachment_tension: np.ndarray
    snapshots: list
    snapshot_times: list
    final_depth: float
    final_trail: float
    settling_time: float
    final_tension: float
    tip_speed: float
    config: dict

    def summary(self) -> dict[str, Any]:
        """The key numbers as a JSON-ready dict, with the paper's values beside them."""
        return {
            "final_depth_m": self.final_depth,
            "final_trail_m": self.final_trail,
            "settling_time_s": self.settling_time,
            "settling_band": SETTLING_BAND,
            "final_attachment_tension_N": self.final_tension,
            "final_tip_speed_m_per_s": self.tip_speed,
            "paper": {"depth_m": "about 50 (Fig. 19)", "settling_time_s": "about 40 (section 4.3)"},
            "tether": self.config,
            "tip_body": dict(stand_in_body()),
        }


def settling_time(time: np.ndarray, depth: np.ndarray, band: float = SETTLING_BAND) -> float:
    """Time after which ``depth`` stays within ``band`` (relative) of its final value, s."""
    final = depth[-1]
    outside = np.nonzero(np.abs(depth - final) > band * abs(final))[0]
    return float(time[outside[-1] + 1]) if outside.size else float(time[0])


def simulate(
    preset: str = "table3",
    duration: float = 120.0,
    sample_interval: float = 0.1,
    config: Optional[dict] = None,
    progress: bool = False,
) -> SettleResult:
    """Tows ``preset`` (with ``config`` overrides) with the stand-in device from straight trailing.

    Args:
        preset: tether preset name (see :func:`accd_gym.tether_config`).
        duration: simulated time, s, in (0, :data:`MAX_DURATION_S`].
        sample_interval: time between samples, s (a multiple of the tether's time step).
        config: overrides of the preset's fields.
        progress: show a progress bar (tqdm) on stderr.

    Returns:
        The time histories and key numbers.
    """
    if not 0 < duration <= MAX_DURATION_S:  # also refuses NaN
        raise ConfigError(f"invalid config: `duration` = {duration} is outside the allowed range (0, {MAX_DURATION_S:g}] s")
    tether = towed_tether(preset, config)
    steps_per_sample = max(1, round(sample_interval / tether.time_step))
    samples = max(1, round(duration / (steps_per_sample * tether.time_step)))
    wanted = [t for t in SNAPSHOT_TIMES if t < duration] + [duration]
    snapshot_samples = {round(t / (steps_per_sample * tether.time_step)) for t in wanted}
    times, tips, tensions, snaps, snap_times = [0.0], [tether.tip_position], [tether.attachment_tension], [], []
    origin = np.zeros((1, 3))
    snaps.append(np.vstack([origin, tether.joint_positions]))
    snap_times.append(0.0)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=samples, desc=f"settling {preset}", unit="sample")
    for i in range(1, samples + 1):
        tether.step(steps_per_sample)
        times.append(tether.time)
        tips.append(tether.tip_position)
        tensions.append(tether.attachment_tension)
        if i in snapshot_samples:
            snaps.append(np.vstack([origin, tether.joint_positions]))
            snap_times.append(tether.time)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    time = np.asarray(times)
    tip = np.asarray(tips)
    return SettleResult(
        time=time,
        tip=tip,
        attachment_tension=np.asarray(tensions),
        snapshots=snaps,
        snapshot_times=snap_times,
        final_depth=float(tip[-1, 2]),
        final_trail=float(-tip[-1, 0]),
        settling_time=settling_time(time, tip[:, 2]),
        final_tension=float(tensions[-1]),
        tip_speed=float(np.linalg.norm(tether.tip_velocity)),
        config=tether.config,
    )


def plot(result: SettleResult, path: Path, title: str = "") -> None:
    """Saves a three-panel PNG: tether shapes (side view), tip depth and attachment tension."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    ax = axes[0]
    cmap = plt.get_cmap("viridis")
    for i, (pts, t) in enumerate(zip(result.snapshots, result.snapshot_times)):
        ax.plot(pts[:, 0], -pts[:, 2], "-", color=cmap(i / max(1, len(result.snapshots) - 1)), label=f"t = {t:.0f} s")
    ax.plot([0], [0], "k^", label="attachment")
    ax.set_xlabel("x (forward) [m]")
    ax.set_ylabel("height relative to the aircraft [m] (up)")
    ax.set_title("tether shape, side view")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    ax = axes[1]
    ax.plot(result.time, result.tip[:, 2], label="tip depth")
    ax.axhline(result.final_depth, color="k", lw=0.7, ls="--", label=f"final {result.final_depth:.1f} m")
    ax.axhline(50.0, color="tab:red", lw=0.7, ls=":", label="paper: about 50 m")
    ax.axvline(result.settling_time, color="tab:gray", lw=0.7, label=f"within 2 % after {result.settling_time:.0f} s")
    ax.invert_yaxis()
    ax.set_xlabel("time [s]")
    ax.set_ylabel("depth below the aircraft [m]")
    ax.set_title("tip depth (z down)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    ax = axes[2]
    ax.plot(result.time, result.attachment_tension / 1e3)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("tension at the attachment [kN]")
    ax.set_title("attachment tension")
    ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    _files.save_figure(fig, path, dpi=120)
    plt.close(fig)


def run(out_dir: Path, preset: str = "table3", duration: float = 120.0, progress: bool = True) -> dict[str, Any]:
    """Simulates, writes ``settle.png`` and ``summary.json`` into ``out_dir``; returns the summary."""
    out_dir = _files.writable_folder(out_dir, "out_dir", OUTPUT_FILES)
    result = simulate(preset=preset, duration=duration, progress=progress)
    summary = result.summary()
    summary["preset"] = preset
    summary["duration_s"] = duration
    _files.write_text(out_dir / "summary.json", json.dumps(summary, indent=2))
    body = stand_in_body()
    plot(
        result,
        out_dir / "settle.png",
        title=f"{preset}: towed at 185 m/s, 6000 m with a {body['mass']:.0f} kg stand-in capturing device",
    )
    _files.save_npz(out_dir / "history.npz", **{k: v for k, v in asdict(result).items() if isinstance(v, np.ndarray)})
    return summary
