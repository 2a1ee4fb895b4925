"""Off-screen rendering of an episode: side and top views of the aircraft's attachment point, the
tether, the capturing device and the RLV's boom tip. Uses matplotlib's Agg canvas only: works on a
machine with no display and no OpenGL.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np


def render_frame(data: Mapping[str, Any], width: int = 640, height: int = 480) -> np.ndarray:
    """An RGB picture (height, width, 3) uint8 of one env's state.

    ``data`` is what ``BatchEnv.render_data`` returns (TA frame, m). Left: side view (x forward,
    depth below the aircraft up the page flipped so that down is down); right: top view (x, y).
    Each view shows the whole tether at a glance and an inset around the capture point.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    joints = np.asarray(data["joints"])
    accd = np.asarray(data["accd_position"])
    capture = np.asarray(data["capture_point"])
    boom = np.asarray(data["boom_tip"])
    eq = np.asarray(data["equilibrium"])

    fig = Figure(figsize=(width / 100.0, height / 100.0), dpi=100)
    canvas = FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2)
    views = [(2, "depth below aircraft z [m]", True), (1, "lateral y [m]", False)]
    for row, (k, label, flip) in enumerate(views):
        whole, near = axes[row]
        for ax, zoom in ((whole, False), (near, True)):
            ax.plot(joints[:, 0], joints[:, k], "-", color="0.35", lw=1.0, label="tether")
            ax.plot([0.0], [0.0], "k^", ms=6, label="attachment (TA)")
            ax.plot([accd[0]], [accd[k]], "o", color="tab:blue", ms=5, label="ACCD")
            ax.plot([capture[0]], [capture[k]], ".", color="tab:green", ms=6, label="capture point")
            ax.plot([boom[0]], [boom[k]], "x", color="tab:red", ms=8, mew=2, label="boom tip")
            ax.plot([eq[0]], [eq[k]], "+", color="0.6", ms=6, label="open-loop equilibrium")
            if zoom:
                c = 0.5 * (capture + boom)
                half = max(4.0, 0.6 * float(np.max(np.abs(capture - boom))))
                ax.set_xlim(c[0] - half, c[0] + half)
                lo, hi = c[k] - half, c[k] + half
                ax.set_ylim((hi, lo) if flip else (lo, hi))
                ax.set_title(f"close-up, distance {float(data['distance']):.2f} m", fontsize=8)
            else:
                if flip:
                    ax.invert_yaxis()
                ax.set_title(("side view" if k == 2 else "top view") + f", t = {float(data['time']):.1f} s", fontsize=8)
            ax.set_xlabel("x forward [m]", fontsize=7)
            ax.set_ylabel(label, fontsize=7)
            ax.tick_params(labelsize=6)
            ax.grid(True, lw=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=6, fontsize=6, frameon=False)
    fig.tight_layout(rect=(0.0, 0.04, 1.0, 1.0))
    canvas.draw()
    image = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    return image


class HumanViewer:
    """A window showing rendered frames (``render_mode="human"``); needs a display."""

    def __init__(self) -> None:
        import matplotlib.pyplot as plt

        self._plt = plt
        self._fig, self._ax = plt.subplots(figsize=(6.4, 4.8))
        self._ax.axis("off")
        self._image = None

    def show(self, frame: np.ndarray, fps: float) -> None:
        """Draws ``frame`` and waits one frame period."""
        if self._image is None:
            self._image = self._ax.imshow(frame)
        else:
            self._image.set_data(frame)
        self._plt.pause(1.0 / fps)

    def close(self) -> None:
        """Closes the window."""
        self._plt.close(self._fig)
