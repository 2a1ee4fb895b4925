"""Off-screen rendering of an episode: side and top views of the aircraft's attachment point, the
tether, the capturing device and the RLV's boom tip, each whole and as a close-up around the
capture point.

Frames are drawn with Pillow's ``ImageDraw`` (lines, markers, and text in its default font with
each label rendered once) into an RGB buffer: no display, no OpenGL and no matplotlib figure, so
a 640 x 480 frame takes a few milliseconds and recording a whole episode (``RecordVideo``,
``VecVideoRecorder``) takes seconds.
"""

from __future__ import annotations

import functools
import math
from typing import Any, Mapping, Optional, Sequence

import numpy as np

#: Colours (RGB) of the drawn items, also used by the legend.
COLOURS: dict[str, tuple[int, int, int]] = {
    "tether": (89, 89, 89),
    "attachment (TA)": (0, 0, 0),
    "ACCD": (31, 119, 180),
    "capture point": (44, 160, 44),
    "boom tip": (214, 39, 40),
    "open-loop equilibrium": (153, 153, 153),
}
_GRID = (224, 224, 224)
_FRAME = (64, 64, 64)
_TEXT = (0, 0, 0)
_LEGEND_HEIGHT = 18


@functools.lru_cache(maxsize=1)
def _font() -> Any:
    """Pillow's default font (loaded once)."""
    from PIL import ImageFont

    return ImageFont.load_default()


@functools.lru_cache(maxsize=2048)
def _text_mask(text: str) -> Any:
    """``text`` rendered once as an 8-bit mask (tick labels and names repeat every frame)."""
    from PIL import Image, ImageDraw

    font = _font()
    left, top, right, bottom = font.getbbox(text)
    mask = Image.new("L", (max(1, int(right) + 1), max(1, int(bottom) + 1)), 0)
    ImageDraw.Draw(mask).text((0, 0), text, fill=255, font=font)
    return mask


def _text(image: Any, xy: tuple[float, float], text: str, anchor: str = "l") -> None:
    """Writes ``text`` at ``xy`` (its top left; ``anchor`` ``"c"``/``"r"``: its top centre or
    top right) in the text colour."""
    mask = _text_mask(text)
    x = xy[0] - {"l": 0.0, "c": 0.5, "r": 1.0}[anchor] * mask.width
    image.paste(_TEXT, (int(round(x)), int(round(xy[1]))), mask)


def _nice_ticks(lo: float, hi: float, count: int = 5) -> list[float]:
    """Round tick values between ``lo`` and ``hi`` (about ``count`` of them)."""
    span = hi - lo
    if not span > 0:
        return [lo]
    raw = span / count
    magnitude = 10.0 ** math.floor(math.log10(raw))
    step = next(m * magnitude for m in (1.0, 2.0, 5.0, 10.0) if m * magnitude >= raw)
    first = math.ceil(lo / step) * step
    return [first + k * step for k in range(int((hi - first) / step) + 1)]


def _format_tick(value: float) -> str:
    """A tick label: integers without decimals, others with one."""
    return f"{value:.0f}" if abs(value - round(value)) < 1e-9 else f"{value:.1f}"


class _Panel:
    """One view: a data rectangle mapped onto a pixel box (``flip``: larger values lower)."""

    def __init__(self, box: tuple[int, int, int, int], xlim: tuple[float, float], ylim: tuple[float, float]) -> None:
        self.box = box
        self.xlim = xlim
        self.ylim = ylim

    def to_pixels(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Pixel coordinates (n, 2) of data points (larger y is lower on the page)."""
        left, top, right, bottom = self.box
        px = left + (np.asarray(x, dtype=float) - self.xlim[0]) / (self.xlim[1] - self.xlim[0]) * (right - left)
        py = top + (np.asarray(y, dtype=float) - self.ylim[0]) / (self.ylim[1] - self.ylim[0]) * (bottom - top)
        return np.stack([px, py], axis=-1)


def _limits(values: np.ndarray, pad: float = 0.08, minimum: float = 2.0) -> tuple[float, float]:
    """Data limits covering ``values`` with a margin, at least ``minimum`` wide."""
    lo, hi = float(np.min(values)), float(np.max(values))
    centre, half = 0.5 * (lo + hi), max(0.5 * (hi - lo), 0.5 * minimum)
    half *= 1.0 + pad
    return centre - half, centre + half


def _marker(draw: Any, p: Sequence[float], kind: str, colour: tuple[int, int, int], size: int) -> None:
    """Draws a marker centred on pixel ``p``: circle (``o``, ``.``), cross, plus or triangle."""
    x, y = float(p[0]), float(p[1])
    if kind in ("o", "."):
        draw.ellipse((x - size, y - size, x + size, y + size), fill=colour)
    elif kind == "x":
        draw.line((x - size, y - size, x + size, y + size), fill=colour, width=2)
        draw.line((x - size, y + size, x + size, y - size), fill=colour, width=2)
    elif kind == "+":
        draw.line((x - size, y, x + size, y), fill=colour, width=1)
        draw.line((x, y - size, x, y + size), fill=colour, width=1)
    elif kind == "^":
        draw.polygon([(x, y - size), (x - size, y + size), (x + size, y + size)], fill=colour)


_MARKERS = (
    ("attachment (TA)", "^", 5),
    ("open-loop equilibrium", "+", 5),
    ("ACCD", "o", 4),
    ("capture point", ".", 3),
    ("boom tip", "x", 5),
)


def _draw_panel(image: Any, panel: _Panel, title: str, xlabel: str, ylabel: str,
                points: Mapping[str, np.ndarray], tether: np.ndarray) -> None:
    """Grid, tether and markers of one view, clipped to its box (drawn on a tile pasted into
    ``image``), then the frame, tick labels, axis labels and title around it."""
    from PIL import Image, ImageDraw

    left, top, right, bottom = panel.box
    tile = Image.new("RGB", (right - left, bottom - top), (255, 255, 255))
    local = _Panel((0, 0, right - left, bottom - top), panel.xlim, panel.ylim)
    draw = ImageDraw.Draw(tile)
    xticks, yticks = _nice_ticks(*panel.xlim), _nice_ticks(*panel.ylim)
    tick_px = local.to_pixels(np.array(xticks), np.full(len(xticks), panel.ylim[0]))[:, 0]
    tick_py = local.to_pixels(np.full(len(yticks), panel.xlim[0]), np.array(yticks))[:, 1]
    for px in tick_px:
        draw.line((px, 0, px, bottom - top), fill=_GRID)
    for py in tick_py:
        draw.line((0, py, right - left, py), fill=_GRID)
    draw.line([tuple(p) for p in local.to_pixels(tether[:, 0], tether[:, 1])], fill=COLOURS["tether"], width=1)
    for name, kind, size in _MARKERS:
        _marker(draw, local.to_pixels(points[name][:1], points[name][1:2])[0], kind, COLOURS[name], size)
    image.paste(tile, (left, top))
    draw = ImageDraw.Draw(image)
    draw.rectangle((left, top, right, bottom), outline=_FRAME)
    for value, px in zip(xticks, tick_px):
        _text(image, (left + px, bottom + 2), _format_tick(value), "c")
    for value, py in zip(yticks, tick_py):
        _text(image, (left - 3, top + py - 5), _format_tick(value), "r")
    _text(image, (right, top - 13), title, "r")
    _text(image, (0.5 * (left + right), bottom + 13), xlabel, "c")
    _text(image, (left - 42, top - 13), ylabel)


def render_frame(data: Mapping[str, Any], width: int = 640, height: int = 480) -> np.ndarray:
    """An RGB picture (height, width, 3) uint8 of one env's state.

    ``data`` is what ``BatchEnv.render_data`` returns (TA frame, m). Top row: side view
    (x forward, depth below the aircraft z, down is down), whole and close-up; bottom row: top
    view (x forward, lateral y), whole and close-up. Close-ups are square, centred between the
    capture point and the boom tip, at least 8 m wide. A legend runs along the bottom.
    """
    from PIL import Image, ImageDraw

    joints = np.asarray(data["joints"], dtype=float)
    named = {
        "attachment (TA)": np.zeros(3),
        "ACCD": np.asarray(data["accd_position"], dtype=float),
        "capture point": np.asarray(data["capture_point"], dtype=float),
        "boom tip": np.asarray(data["boom_tip"], dtype=float),
        "open-loop equilibrium": np.asarray(data["equilibrium"], dtype=float),
    }
    capture, boom = named["capture point"], named["boom tip"]
    image = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(image)
    columns, rows = 2, 2
    cell_w, cell_h = width / columns, (height - _LEGEND_HEIGHT) / rows
    everything = np.vstack([joints, *named.values()])
    centre = 0.5 * (capture + boom)
    half = max(4.0, 0.6 * float(np.max(np.abs(capture - boom))))
    views = [(2, "depth z [m]", "side view"), (1, "lateral y [m]", "top view")]
    for row, (k, ylabel, name) in enumerate(views):
        for col, zoom in enumerate((False, True)):
            box = (
                int(col * cell_w + 50),
                int(row * cell_h + 16),
                int((col + 1) * cell_w - 12),
                int((row + 1) * cell_h - 26),
            )
            if zoom:
                xlim = (centre[0] - half, centre[0] + half)
                ylim = (centre[k] - half, centre[k] + half)
                title = f"close-up, distance {float(data['distance']):.2f} m"
            else:
                xlim, ylim = _limits(everything[:, 0]), _limits(everything[:, k])
                title = f"{name}, t = {float(data['time']):.1f} s"
            panel = _Panel(box, xlim, ylim)
            points = {n: p[[0, k]] for n, p in named.items()}
            _draw_panel(image, panel, title, "x forward [m]", ylabel, points, joints[:, [0, k]])
    x = 8
    y = height - _LEGEND_HEIGHT + 4
    for name, kind, size in (("tether", "-", 0), *_MARKERS):
        if kind == "-":
            draw.line((x, y + 5, x + 14, y + 5), fill=COLOURS[name], width=2)
        else:
            _marker(draw, (x + 7, y + 5), kind, COLOURS[name], size)
        _text(image, (x + 18, y), name)
        x += 18 + _text_mask(name).width + 16
    return np.asarray(image, dtype=np.uint8).copy()


class HumanViewer:
    """A window showing rendered frames (``render_mode="human"``); needs a display."""

    def __init__(self) -> None:
        import matplotlib.pyplot as plt

        self._plt = plt
        self._fig, self._ax = plt.subplots(figsize=(6.4, 4.8))
        self._ax.axis("off")
        self._image: Optional[Any] = None

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
