"""Replays of recorded episodes: a self-contained HTML page with a 3D view and time plots, and an
MP4 video.

:func:`replay_html` turns a :class:`~accd_gym.replays.recording.Recording` into one HTML file that opens
offline: plotly.js (from the ``plotly`` package, which ships it) and the episode's data are
inside it; the page requests nothing. It shows

* a 3D view of the whole system (orbit, zoom, pan: plotly's scene controls): the attachment
  point on the aircraft, the tether coloured by its tension, the ACCD, the boom tip, the open-loop
  equilibrium and the trails of the capture point and the boom tip;
* a 3D close-up following the capture point: the ACCD as a body (1.5 m cylinder with a nose
  cone, at its recorded attitude) with its four flaps at their recorded deflections, the last
  tether segments, the capture point and its trail, the boom tip with a rod behind it and a
  sphere of the capture radius around it;
* time plots of the distance (with the capture radius), the relative speed (with the closing
  speed limit), the attachment tension (and the peak of each step), and the flap deflections
  (solid) with their commands (dashed), each with a cursor at the shown time;
* play/pause, a time slider, playback speed, and a readout of the current values. Clicking a
  time plot moves to that time. ``page.html#t=12.5`` opens at 12.5 s.

Plot coordinates: the TA frame turned by 180 deg about x, so that up is up: (x forward,
-y = port, -z = height above the attachment); a proper rotation, so the ACCD is not mirrored.

Size: plotly.js is 4.8 MB; the data of a 70 s episode at the agent rate (701 samples, 31
joints) about 1.5 MB. Samples beyond ``max_frames`` (1000) are decimated for the 3D views
(every k-th sample and the last); the time plots keep every sample.

:func:`write_video` draws the recording's frames with :func:`accd_gym.envs.render.render_frame` and
encodes an H.264 MP4 with imageio-ffmpeg (which ships its ffmpeg binary).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Optional

import numpy as np

from accd_gym import files
from accd_gym.envs.render import render_frame
from accd_gym.errors import ConfigError
from accd_gym.evals.episodes import Episode
from accd_gym.evals.evaluation import ReplayWriter
from accd_gym.evals.policies import load_policy
from accd_gym.replays.browser import screenshot
from accd_gym.replays.recording import Recording, iter_recordings, record_episodes

#: Largest number of 3D frames a page holds (more samples are decimated).
MAX_FRAMES = 1000


def plotly_js() -> str:
    """plotly.js, minified, from the installed ``plotly`` package."""
    try:
        import plotly
    except ModuleNotFoundError as e:
        raise ModuleNotFoundError(f"replay pages need plotly ({e}): pip install 'accd-gym[replay]'", name=e.name) from e
    path = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"
    return path.read_text(encoding="utf-8")


def _r(a: Any, digits: int) -> Any:
    """An array rounded to ``digits`` decimals as nested lists (NaN and inf as None: JSON null)."""
    arr = np.round(np.asarray(a, dtype=float), digits)
    if np.isfinite(arr).all():
        return arr.tolist()
    obj = arr.astype(object)
    obj[~np.isfinite(arr)] = None
    return obj.tolist()


def frame_indices(samples: int, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """The sample indices shown in 3D: all of them up to ``max_frames``, else every k-th
    (k = ceil(samples / max_frames)) and the last."""
    if samples <= max_frames:
        return np.arange(samples)
    stride = math.ceil(samples / max_frames)
    idx = np.arange(0, samples, stride)
    if idx[-1] != samples - 1:
        idx = np.append(idx, samples - 1)
    return idx


def page_data(rec: Recording, max_frames: int = MAX_FRAMES) -> dict[str, Any]:
    """What the page's JavaScript reads: metadata, the time series (every sample) and the 3D
    frames (decimated), rounded to 1 mm, 0.01 deg, 1 N and 1e-6 in the quaternion."""
    a = rec.arrays
    cfg = rec.meta["config"]
    idx = frame_indices(len(a["time"]), max_frames)
    step_t = a["info_time"] if rec.steps else np.zeros(0)
    captured_at = next((float(a["time"][k]) for k in range(len(a["time"])) if a["captured"][k]), None)
    seeds = rec.meta.get("seeds", {})
    meta = {
        "policy": rec.meta.get("policy"),
        "episode": rec.meta.get("episode"),
        "seeds": {k: str(v) for k, v in seeds.items()},
        "outcome": rec.outcome,
        "divergence": rec.meta.get("divergence"),
        "steps": rec.steps,
        "duration": rec.duration,
        "min_distance": rec.min_distance,
        "time_of_min_distance": float(a["time"][int(np.argmin(a["distance"]))]),
        "captured_at": captured_at,
        "capture_radius": float(cfg["boom"]["capture_radius"]),
        "max_closing_speed": float(cfg["boom"]["max_closing_speed"]),
        "flap_limit_deg": float(cfg["accd"]["flap_limit_deg"]),
        "agent_step": float(cfg["agent_step"]),
        "segments": int(cfg["tether"]["segments"]),
        "tether_length": float(cfg["tether"]["length"]),
        "geometry": rec.meta["accd_geometry"],
        "decimation": int(idx[1] - idx[0]) if len(idx) > 1 else 1,
        "version": rec.meta.get("accd_gym_version"),
    }
    return {
        "meta": meta,
        "t": _r(a["time"], 3),
        "dist": _r(a["distance"], 4),
        "vrel": _r(a["relative_speed"], 4),
        "tension": _r(a["attachment_tension"] / 1e3, 4),
        "step_t": _r(step_t, 3),
        "peak": _r(a["info_peak_tension"] / 1e3, 4),
        "reward": _r(a["reward"], 4),
        "defl": _r(a["flap_deflection_deg"], 2),
        "cmd": _r(a["flap_command_deg"], 2),
        "alpha": _r(np.degrees(a["alpha"]), 2),
        "beta": _r(np.degrees(a["beta"]), 2),
        "cap": _r(a["capture_point"], 3),
        "boom": _r(a["boom_tip"], 3),
        "pos": _r(a["position"], 3),
        "quat": _r(a["attitude"], 6),
        "equilibrium": _r(a["equilibrium"], 3),
        "frames": idx.tolist(),
        "joints": [_r(a["joints"][k].ravel(), 3) for k in idx],
        "tensions": [_r(a["tensions"][k] / 1e3, 3) for k in idx],
    }


def replay_html(rec: Recording, *, max_frames: int = MAX_FRAMES, title: Optional[str] = None) -> str:
    """The self-contained replay page of ``rec`` (see the module docstring)."""
    data = page_data(rec, max_frames)
    m = data["meta"]
    heading = title or (f"{m['policy']} · episode {m['episode']} · {m['outcome']}"
                        f" · miss {m['min_distance']:.2f} m")
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    return (_TEMPLATE.replace("__TITLE__", _escape(heading))
            .replace("__PLOTLY__", plotly_js().replace("</script", "<\\/script"))
            .replace("__DATA__", payload)
            .replace("__APP__", _APP))


def _escape(text: str) -> str:
    """HTML-escaped text."""
    import html

    return html.escape(text, quote=True)


def write_replay(rec: Recording, path: str | Path, **kwargs: Any) -> Path:
    """Writes :func:`replay_html` of ``rec`` to ``path`` (UTF-8, atomically); returns the path."""
    return files.write_text(path, replay_html(rec, **kwargs))


def write_video(rec: Recording, path: str | Path, *, fps: Optional[float] = None, width: int = 640,
                height: int = 480) -> Path:
    """Writes the recording as an H.264 MP4 (one frame per sample, ``render_frame``'s side and top
    views) at ``fps`` frames per second (default: real time, ``1 / agent_step``); returns the path."""
    try:
        import imageio_ffmpeg
    except ModuleNotFoundError as e:
        raise ModuleNotFoundError(f"videos need imageio-ffmpeg ({e}): pip install 'accd-gym[replay]'", name=e.name) from e
    p = Path(path)
    rate = float(fps) if fps is not None else 1.0 / float(rec.meta["agent_step"])
    with files.atomic_path(p) as tmp:  # a failed encoding leaves the previous video, never half of one
        writer = imageio_ffmpeg.write_frames(str(tmp), (width, height), fps=rate, codec="libx264", pix_fmt_out="yuv420p",
                                             macro_block_size=16, quality=7, ffmpeg_log_level="error")
        writer.send(None)
        try:
            for k in range(len(rec["time"])):
                writer.send(np.ascontiguousarray(render_frame(rec.frame_data(k), width, height)))
        finally:
            writer.close()
    return p


def screenshot_replay(html: str | Path, png: str | Path, time: Optional[float] = None,
                      width: int = 1400, height: int = 900) -> list[str]:
    """A screenshot of a replay page at ``time`` (s; default the capture, or for an episode
    without one the closest approach) taken with headless Chromium (:mod:`accd_gym.replays.browser`);
    returns the page's JavaScript errors."""
    default = "accdReplay.meta.captured_at !== null ? accdReplay.meta.captured_at : accdReplay.meta.time_of_min_distance"
    setup = f"accdReplay.setTime({default})" if time is None else f"accdReplay.setTime({float(time)!r})"
    return screenshot(html, png, setup=setup, width=width, height=height)


_TEMPLATE = r"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="default-src 'none'; script-src 'unsafe-inline' 'unsafe-eval'; style-src 'unsafe-inline'; img-src data: blob:; font-src data:; connect-src 'none'; worker-src blob:">
<title>__TITLE__</title>
<style>
body { font: 13px/1.35 system-ui, sans-serif; margin: 0; color: #222; background: #fff; }
header { padding: 6px 12px; border-bottom: 1px solid #ddd; }
header h1 { font-size: 15px; margin: 0 0 2px 0; }
#summary { color: #555; }
#views { display: flex; height: 46vh; min-height: 300px; }
#whole, #close { flex: 1; min-width: 0; }
#controls { display: flex; align-items: center; gap: 10px; padding: 4px 12px; border-top: 1px solid #eee; border-bottom: 1px solid #eee; }
#slider { flex: 1; }
#readout { font-family: ui-monospace, monospace; font-size: 12px; white-space: pre; padding: 2px 12px; color: #333; }
#plots { height: 34vh; min-height: 260px; }
button, select { font: inherit; }
</style>
<script>__PLOTLY__</script>
</head>
<body>
<header><h1>__TITLE__</h1><div id="summary"></div></header>
<div id="views"><div id="whole"></div><div id="close"></div></div>
<div id="controls">
  <button id="play" type="button">Play</button>
  <input id="slider" type="range" min="0" max="0" step="1" value="0" aria-label="time">
  <span id="clock"></span>
  <label>speed <select id="speed"><option>0.5</option><option selected>1</option><option>2</option><option>5</option></select>x</label>
</div>
<div id="readout"></div>
<div id="plots"></div>
<script type="application/json" id="accd-data">__DATA__</script>
<script>__APP__</script>
</body>
</html>
"""

_APP = r"""
"use strict";
(function () {
const D = JSON.parse(document.getElementById("accd-data").textContent);
const M = D.meta, G = M.geometry, F = D.frames;
const P = (v) => [v[0], -v[1], -v[2]];          // TA frame -> plot (x forward, port, up)
function rot(q, v) {                              // body -> TA frame, q = (w, x, y, z)
  const [w, x, y, z] = q;
  return [
    (1 - 2 * (y * y + z * z)) * v[0] + 2 * (x * y - w * z) * v[1] + 2 * (x * z + w * y) * v[2],
    2 * (x * y + w * z) * v[0] + (1 - 2 * (x * x + z * z)) * v[1] + 2 * (y * z - w * x) * v[2],
    2 * (x * z - w * y) * v[0] + 2 * (y * z + w * x) * v[1] + (1 - 2 * (x * x + y * y)) * v[2]];
}
function bodyPoint(k, v) {                        // a body-frame point at sample k, TA frame
  const r = rot(D.quat[k], v), p = D.pos[k];
  return [p[0] + r[0], p[1] + r[1], p[2] + r[2]];
}
// ACCD body: nose cone then cylinder, body axes (x forward, y right, z down), origin at the CG.
const RING = 16, R = G.diameter / 2, NOSE = G.cg_from_nose, TAIL = -(G.length - G.cg_from_nose);
const SHOULDER = NOSE - 0.3 * G.length;
const bodyLocal = [[NOSE, 0, 0]];
for (const xs of [SHOULDER, TAIL])
  for (let j = 0; j < RING; j++) { const a = 2 * Math.PI * j / RING; bodyLocal.push([xs, R * Math.cos(a), R * Math.sin(a)]); }
bodyLocal.push([TAIL, 0, 0]);
const BI = [], BJ = [], BK = [];
for (let j = 0; j < RING; j++) {
  const a = 1 + j, b = 1 + (j + 1) % RING, c = 1 + RING + j, d = 1 + RING + (j + 1) % RING;
  BI.push(0, a, b, c); BJ.push(a, c, d, d); BK.push(b, b, b, 1 + 2 * RING);
}
// Flaps: plates hinged HINGE behind the CG, chord C, from the body surface outwards by SPAN;
// right, left (horizontal: trailing edge up for +), top, bottom (vertical: trailing edge to starboard for +).
const HINGE = TAIL + 0.3, C = 0.3, SPAN = 0.3;
function flapLocal(f, deg) {
  const d = deg * Math.PI / 180, dir = [[0, 1, 0], [0, -1, 0], [0, 0, -1], [0, 0, 1]][f];
  const te = f < 2 ? [-C * Math.cos(d), 0, -C * Math.sin(d)] : [-C * Math.cos(d), C * Math.sin(d), 0];
  const root = [HINGE, dir[1] * R, dir[2] * R], tip = [HINGE, dir[1] * (R + SPAN), dir[2] * (R + SPAN)];
  const add = (p, o) => [p[0] + o[0], p[1] + o[1], p[2] + o[2]];
  return [root, tip, add(tip, te), add(root, te)];
}
const FI = [], FJ = [], FK = [];
for (let f = 0; f < 4; f++) { FI.push(4 * f, 4 * f); FJ.push(4 * f + 1, 4 * f + 2); FK.push(4 * f + 2, 4 * f + 3); }
function xyz(points) { return { x: points.map(p => p[0]), y: points.map(p => p[1]), z: points.map(p => p[2]) }; }
function bodyMesh(k) { return xyz(bodyLocal.map(v => P(bodyPoint(k, v)))); }
function flapMesh(k) {
  const pts = [];
  for (let f = 0; f < 4; f++) for (const v of flapLocal(f, D.defl[k][f])) pts.push(P(bodyPoint(k, v)));
  return xyz(pts);
}
function jointsOf(j) {                            // frame j: attachment (origin) then the joints
  const a = D.joints[j], pts = [[0, 0, 0]];
  for (let i = 0; i < a.length; i += 3) pts.push(P([a[i], a[i + 1], a[i + 2]]));
  return xyz(pts);
}
function trail(arr, k) { return xyz(arr.slice(0, k + 1).map(P)); }
const TRAIL_S = 5;
function recent(arr, k) {                         // the last TRAIL_S seconds of a trail
  let s = k; while (s > 0 && D.t[k] - D.t[s - 1] <= TRAIL_S) s--;
  return xyz(arr.slice(s, k + 1).map(P));
}
function sphere(c, r) {                           // three great circles around c (TA frame)
  const pts = [];
  for (let ax = 0; ax < 3; ax++) {
    for (let j = 0; j <= 48; j++) {
      const a = 2 * Math.PI * j / 48, u = [0, 0, 0];
      u[(ax + 1) % 3] = r * Math.cos(a); u[(ax + 2) % 3] = r * Math.sin(a);
      pts.push(P([c[0] + u[0], c[1] + u[1], c[2] + u[2]]));
    }
    pts.push([null, null, null]);
  }
  return xyz(pts);
}
function boomRod(k) { const b = D.boom[k]; return xyz([P(b), P([b[0] - 4, b[1], b[2] + 0.8])]); }
function lastSegments(j) {
  const a = D.joints[j], n = a.length / 3, pts = [];
  for (let i = Math.max(0, n - 3); i < n; i++) pts.push(P([a[3 * i], a[3 * i + 1], a[3 * i + 2]]));
  return xyz(pts);
}
const tmax = Math.max(...D.tensions.map(t => Math.max(...t)));
// Whole-system view ranges, fixed over the episode.
function span(values, pad, minimum) {
  let lo = Math.min(...values), hi = Math.max(...values);
  const c = (lo + hi) / 2, h = Math.max((hi - lo) / 2 * (1 + pad), minimum / 2);
  return [c - h, c + h];
}
const allX = [0], allY = [0], allZ = [0];
for (const j of [0, F.length - 1, Math.floor(F.length / 2)]) { const s = jointsOf(j); allX.push(...s.x); allY.push(...s.y); allZ.push(...s.z); }
for (const arr of [D.boom, D.cap]) for (const v of arr) { const p = P(v); allX.push(p[0]); allY.push(p[1]); allZ.push(p[2]); }
const wx = span(allX, 0.05, 20), wy = span(allY, 0.3, 40), wz = span(allZ, 0.1, 20);
const axis = (title, range) => ({ title: { text: title }, range: range, autorange: false, backgroundcolor: "#fafafa", showbackground: true });
const scene = (x, y, z, extra) => Object.assign({
  xaxis: axis("x forward [m]", x), yaxis: axis("port, -y [m]", y), zaxis: axis("height, -z [m]", z),
  camera: { eye: { x: 0.9, y: -1.6, z: 0.7 }, up: { x: 0, y: 0, z: 1 } },
}, extra);
const wholeLayout = {
  title: { text: "whole system (drag: orbit, wheel: zoom)", font: { size: 12 } }, margin: { l: 0, r: 0, t: 28, b: 40 },
  showlegend: true, legend: { orientation: "h", x: 0, y: 0, yanchor: "top", font: { size: 10 } }, uirevision: "keep",
  scene: scene(wx, wy, wz, { aspectmode: "manual", aspectratio: { x: 2.2, y: 0.9, z: 0.9 } }),
};
const closeLayout = {
  title: { text: "close-up on the capture point", font: { size: 12 } }, margin: { l: 0, r: 0, t: 28, b: 40 },
  showlegend: true, legend: { orientation: "h", x: 0, y: 0, yanchor: "top", font: { size: 10 } }, uirevision: "keep",
  scene: scene([-1, 1], [-1, 1], [-1, 1], { aspectmode: "cube", camera: { eye: { x: 0.6, y: -1.5, z: 0.6 }, up: { x: 0, y: 0, z: 1 } } }),
};
function closeRanges(k) {
  const c = D.cap[k], b = D.boom[k], mid = P([(c[0] + b[0]) / 2, (c[1] + b[1]) / 2, (c[2] + b[2]) / 2]);
  const half = Math.max(2.5, Math.ceil(0.65 * D.dist[k]));
  return [[mid[0] - half, mid[0] + half], [mid[1] - half, mid[1] + half], [mid[2] - half, mid[2] + half]];
}
const mk = (name, colour, symbol, size) => ({ type: "scatter3d", mode: "markers", name: name, marker: { color: colour, symbol: symbol, size: size } });
function wholeTraces(j) {
  const k = F[j], J = jointsOf(j), t = [0].concat(D.tensions[j]);
  return [
    Object.assign({ type: "scatter3d", mode: "lines", name: "tether (colour: tension, kN)", line: { width: 5, color: t, colorscale: "Viridis", cmin: 0, cmax: tmax, colorbar: { title: { text: "kN" }, len: 0.5, thickness: 10, x: 1.0 } } }, J),
    Object.assign(mk("attachment (TA)", "#000", "diamond", 5), xyz([[0, 0, 0]])),
    Object.assign(mk("ACCD", "#1f77b4", "circle", 5), xyz([P(D.pos[k])])),
    Object.assign(mk("boom tip", "#d62728", "x", 5), xyz([P(D.boom[k])])),
    Object.assign(mk("open-loop equilibrium", "#999", "cross", 4), xyz([P(D.equilibrium)])),
    Object.assign({ type: "scatter3d", mode: "lines", name: "capture point trail", line: { color: "#2ca02c", width: 3 } }, trail(D.cap, k)),
    Object.assign({ type: "scatter3d", mode: "lines", name: "boom tip trail", line: { color: "#d62728", width: 2, dash: "dot" } }, trail(D.boom, k)),
  ];
}
function closeTraces(j) {
  const k = F[j];
  return [
    Object.assign({ type: "mesh3d", name: "ACCD", color: "#6baed6", opacity: 1, flatshading: true, i: BI, j: BJ, k: BK, showlegend: true, hoverinfo: "name", lighting: { ambient: 0.8, diffuse: 0.5 } }, bodyMesh(k)),
    Object.assign({ type: "mesh3d", name: "flaps", color: "#ff7f0e", opacity: 1, flatshading: true, i: FI, j: FJ, k: FK, showlegend: true, hoverinfo: "name" }, flapMesh(k)),
    Object.assign({ type: "scatter3d", mode: "lines", name: "tether", line: { color: "#595959", width: 4 } }, lastSegments(j)),
    Object.assign(mk("capture point", "#2ca02c", "circle", 4), xyz([P(D.cap[k])])),
    Object.assign({ type: "scatter3d", mode: "lines", name: "capture point, last " + TRAIL_S + " s", line: { color: "#2ca02c", width: 3 } }, recent(D.cap, k)),
    Object.assign(mk("boom tip", "#d62728", "x", 5), xyz([P(D.boom[k])])),
    Object.assign({ type: "scatter3d", mode: "lines", name: "boom (drawn)", line: { color: "#d62728", width: 6 } }, boomRod(k)),
    Object.assign({ type: "scatter3d", mode: "lines", name: "capture radius " + M.capture_radius + " m", line: { color: "#d62728", width: 1 } }, sphere(D.boom[k], M.capture_radius)),
  ];
}
// Time plots: four rows sharing the time axis.
const names = ["right", "left", "top", "bottom"], colours = ["#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd"];
const tp = [
  { x: D.t, y: D.dist, name: "distance [m]", yaxis: "y", line: { color: "#000" } },
  { x: [D.t[0], D.t[D.t.length - 1]], y: [M.capture_radius, M.capture_radius], name: "capture radius", yaxis: "y", line: { color: "#d62728", dash: "dot", width: 1 } },
  { x: D.t, y: D.vrel, name: "relative speed [m/s]", yaxis: "y2", line: { color: "#8c564b" } },
  { x: [D.t[0], D.t[D.t.length - 1]], y: [M.max_closing_speed, M.max_closing_speed], name: "closing-speed limit", yaxis: "y2", line: { color: "#8c564b", dash: "dot", width: 1 } },
  { x: D.t, y: D.tension, name: "attachment tension [kN]", yaxis: "y3", line: { color: "#17becf" } },
  { x: D.step_t, y: D.peak, name: "peak in step [kN]", yaxis: "y3", line: { color: "#17becf", width: 1, dash: "dot" } },
];
for (let f = 0; f < 4; f++) {
  tp.push({ x: D.t, y: D.defl.map(r => r[f]), name: names[f] + " flap [deg]", yaxis: "y4", line: { color: colours[f] } });
  tp.push({ x: D.t, y: D.cmd.map(r => r[f]), name: names[f] + " command", yaxis: "y4", line: { color: colours[f], dash: "dash", width: 1 }, showlegend: false });
}
for (const tr of tp) { tr.type = "scatter"; tr.mode = "lines"; tr.xaxis = "x"; tr.hovertemplate = "%{y:.3f}"; }
const cursor = (yref) => ({ type: "line", xref: "x", yref: yref, x0: 0, x1: 0, y0: 0, y1: 1, line: { color: "#e377c2", width: 2 } });
const plotsLayout = {
  margin: { l: 56, r: 170, t: 8, b: 34 }, showlegend: true, legend: { x: 1.01, y: 1, font: { size: 10 } },
  hovermode: "x unified", uirevision: "keep",
  xaxis: { title: { text: "time [s]" }, domain: [0, 1], anchor: "y4", range: [D.t[0], D.t[D.t.length - 1]] },
  yaxis: { domain: [0.78, 1], title: { text: "distance [m]", font: { size: 10 } }, type: "log" },
  yaxis2: { domain: [0.53, 0.74], title: { text: "rel. speed [m/s]", font: { size: 10 } }, rangemode: "tozero" },
  yaxis3: { domain: [0.28, 0.49], title: { text: "tension [kN]", font: { size: 10 } }, rangemode: "tozero" },
  yaxis4: { domain: [0, 0.24], title: { text: "flaps [deg]", font: { size: 10 } }, range: [-M.flap_limit_deg * 1.1, M.flap_limit_deg * 1.1] },
  shapes: [cursor("paper")],
};
const config = { displaylogo: false, responsive: true };
const slider = document.getElementById("slider"), play = document.getElementById("play");
const clock = document.getElementById("clock"), readout = document.getElementById("readout");
slider.max = String(F.length - 1);
const seeds = Object.entries(M.seeds).map(([k, v]) => k + " " + v).join(", ");
document.getElementById("summary").textContent =
  `outcome: ${M.outcome}${M.captured_at !== null ? " at " + M.captured_at.toFixed(1) + " s" : ""}` +
  (M.divergence ? ` (${M.divergence})` : "") +
  ` · closest approach ${M.min_distance.toFixed(3)} m at ${M.time_of_min_distance.toFixed(1)} s` +
  ` · ${M.steps} agent steps of ${M.agent_step} s · seeds: ${seeds}` +
  (M.decimation > 1 ? ` · 3D shows every ${M.decimation}th sample` : "") + ` · accd-gym ${M.version}`;
let current = 0, timer = null, busy = false, pending = null;
const fmt = (v, d) => (v === null || v === undefined) ? "-" : v.toFixed(d);
function show(j) {
  j = Math.max(0, Math.min(F.length - 1, Math.round(j)));
  current = j; slider.value = String(j);
  if (busy) { pending = j; return Promise.resolve(); }
  busy = true;
  const k = F[j], w = wholeTraces(j), c = closeTraces(j), r = closeRanges(k);
  const pick = (traces) => ({ x: traces.map(t => t.x), y: traces.map(t => t.y), z: traces.map(t => t.z) });
  const wu = pick(w);
  const cu = pick(c);
  clock.textContent = `t = ${D.t[k].toFixed(2)} s / ${M.duration.toFixed(1)} s`;
  const s = Math.max(0, Math.min(D.reward.length - 1, k - 1)), q = D.quat[k];
  readout.textContent =
    `distance ${fmt(D.dist[k], 3)} m   relative speed ${fmt(D.vrel[k], 3)} m/s   attachment tension ${fmt(D.tension[k], 3)} kN   ` +
    `alpha ${fmt(D.alpha[k], 2)} deg   beta ${fmt(D.beta[k], 2)} deg\n` +
    `flaps (R, L, T, B) ${D.defl[k].map(v => fmt(v, 1)).join(", ")} deg   commands ${D.cmd[k].map(v => fmt(v, 1)).join(", ")} deg   ` +
    `reward of last step ${k > 0 ? fmt(D.reward[s], 3) : "-"}   attitude q = (${q.map(v => v.toFixed(4)).join(", ")})`;
  return Promise.all([
    Plotly.restyle("whole", { x: wu.x, y: wu.y, z: wu.z }, w.map((_, i) => i)).then(() => Plotly.restyle("whole", { "line.color": [w[0].line.color] }, [0])),
    Plotly.restyle("close", { x: cu.x, y: cu.y, z: cu.z }, c.map((_, i) => i)).then(() => Plotly.relayout("close", {
      "scene.xaxis.range": r[0], "scene.yaxis.range": r[1], "scene.zaxis.range": r[2] })),
    Plotly.relayout("plots", { "shapes[0].x0": D.t[k], "shapes[0].x1": D.t[k] }),
  ]).then(() => { busy = false; if (pending !== null) { const p = pending; pending = null; return show(p); } });
}
function frameAt(t) {                             // the frame closest to time t
  let best = 0;
  for (let j = 0; j < F.length; j++) if (Math.abs(D.t[F[j]] - t) < Math.abs(D.t[F[best]] - t)) best = j;
  return best;
}
function stop() { if (timer !== null) { clearInterval(timer); timer = null; } play.textContent = "Play"; }
function start() {
  if (current >= F.length - 1) show(0);
  const speed = parseFloat(document.getElementById("speed").value);
  const dt = (F.length > 1 ? (D.t[F[1]] - D.t[F[0]]) : M.agent_step) * 1000 / speed;
  play.textContent = "Pause";
  timer = setInterval(() => { if (busy) return; if (current >= F.length - 1) { stop(); return; } show(current + 1); }, dt);
}
play.addEventListener("click", () => { if (timer === null) start(); else stop(); });
document.getElementById("speed").addEventListener("change", () => { if (timer !== null) { stop(); start(); } });
slider.addEventListener("input", () => { stop(); show(parseInt(slider.value, 10)); });
document.addEventListener("keydown", (e) => {
  if (e.key === " ") { e.preventDefault(); play.click(); }
  else if (e.key === "ArrowRight") { stop(); show(current + 1); }
  else if (e.key === "ArrowLeft") { stop(); show(current - 1); }
});
const ready = Promise.all([
  Plotly.newPlot("whole", wholeTraces(0), wholeLayout, config),
  Plotly.newPlot("close", closeTraces(0), closeLayout, config),
  Plotly.newPlot("plots", tp, plotsLayout, config),
]).then(() => {
  document.getElementById("plots").on("plotly_click", (ev) => { if (ev.points.length) { stop(); show(frameAt(ev.points[0].x)); } });
  const m = /t=([0-9.]+)/.exec(location.hash);
  return show(m ? frameAt(parseFloat(m[1])) : 0);
}).then(() => { window.accdReplay.ready = true; });
window.accdReplay = {
  ready: false, meta: M, frames: F.length, data: D,
  setFrame: (j) => { stop(); return show(j); },
  setTime: (t) => { stop(); return show(frameAt(t)); },
  frame: () => current, time: () => D.t[F[current]],
  bodyPoint: bodyPoint, flapLocal: flapLocal, play: start, pause: stop, whenReady: ready,
  idle: () => new Promise((resolve) => { const f = () => (busy || pending !== null) ? setTimeout(f, 20) : resolve(true); f(); }),
};
})();
"""


def pick_episodes(episodes: Any, count: int) -> list[tuple[str, int]]:
    """``count`` evaluated episodes spread over the ranking best to worst, as ``(label, index)``.

    Ranking: captured episodes first, sooner captures better; then the others by their miss
    distance (minimum distance to the boom tip), smaller better. ``count`` = 1 gives the median,
    2 the best and the worst, 3 best, median and worst; more add evenly spaced ranks
    (``rank<r>``, 1 = best). ``episodes`` are :class:`accd_gym.evals.evaluation.Episode` objects.
    """
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ConfigError(f"invalid config: `replay` = {count!r} is outside the allowed range: an int >= 1")
    ranked = sorted(episodes, key=lambda e: (0, e.capture_time, e.index) if e.captured else (1, e.min_distance, e.index))
    m = len(ranked)
    if count == 1 or m == 1:
        positions = [(m - 1) // 2]
    else:
        c = min(count, m)
        positions = sorted({(m - 1) // 2 if 2 * j == c - 1 else round(j * (m - 1) / (c - 1)) for j in range(c)})
    out = []
    for p in positions:
        label = "best" if p == 0 else "worst" if p == m - 1 else "median" if p == (m - 1) // 2 else f"rank{p + 1}"
        out.append((label, int(ranked[p].index)))
    return out


def evaluation_replays(count: int) -> ReplayWriter:
    """The ``replay_writer`` of :func:`accd_gym.evals.evaluation.evaluate` for ``accd-gym evaluate
    --replay K``: :func:`write_evaluation_replays` of ``count`` episodes per policy."""

    def write(spec: str, label: str, episodes: list[Episode], context: dict[str, Any]) -> list[dict[str, Any]]:
        ctx = dict(context)
        folder = ctx.pop("folder")
        return write_evaluation_replays(spec, label, episodes, count, folder, **ctx)

    return write


def write_evaluation_replays(spec: str, label: str, episodes: Any, count: int, out: str | Path, *, seed: int,
                             wake_seeds: Any, num_envs: int, num_threads: int, config: Optional[dict[str, Any]],
                             allow_unnormalized: bool = False) -> list[dict[str, Any]]:
    """For ``accd-gym evaluate --replay K``: re-runs policy ``spec`` on the evaluation's episodes
    (the same seeds, batch and policy calls, :func:`accd_gym.replays.recording.record_episodes`),
    records the :func:`pick_episodes` ones and writes ``out/<label>/<pick>_ep<k>.html`` and
    ``.npz``. Checks that each recording reproduces the evaluation's outcome and steps. Returns
    one entry per page (pick, episode, outcome, miss distance, files)."""

    picks = pick_episodes(episodes, count)
    policy = load_policy(spec, allow_unnormalized=allow_unnormalized, config=config)
    recs = record_episodes(policy, len(episodes), config=config, seed=seed, wake_seeds=wake_seeds,
                           num_envs=num_envs, num_threads=num_threads, keep={k for _, k in picks})
    by_index = {int(r.meta["episode"]): r for r in recs}
    folder = Path(out) / "".join(c if c.isalnum() or c in "-_." else "_" for c in label)
    written = []
    for pick, k in picks:
        rec, ep = by_index[k], episodes[k]
        rec.meta["policy"] = label
        if rec.outcome != ep.outcome or rec.steps != ep.steps:
            raise RuntimeError(f"the replay of {label} episode {k} ended {rec.outcome} after {rec.steps} steps, the "
                               f"evaluation's {ep.outcome} after {ep.steps}: the policy is not reproducible")
        html = write_replay(rec, folder / f"{pick}_ep{k}.html", title=f"{label} · {pick} · episode {k} · {rec.outcome}"
                            f" · miss {rec.min_distance:.2f} m")
        npz = rec.save(folder / f"{pick}_ep{k}.npz")
        written.append({"pick": pick, "episode": k, "outcome": rec.outcome, "min_distance": rec.min_distance,
                        "html": str(html), "npz": str(npz)})
    return written


def run_replay(policy: str, episodes: int, out: str | Path, *, seed: Optional[int] = None,
               wake_seeds: Optional[list[int]] = None, config: Optional[dict[str, Any]] = None, num_envs: int = 16,
               num_threads: int = 0, video: bool = False, screenshot: bool = False, max_frames: int = MAX_FRAMES,
               allow_unnormalized: bool = False, progress: bool = False,
               only: Optional[list[int]] = None) -> list[dict[str, Any]]:
    """``accd-gym replay``: records ``episodes`` episodes of ``policy`` (the evaluation's episodes
    with the same ``episodes`` and ``num_envs``; ``only``: just these indices of them, the others
    run unrecorded) and writes per episode ``episode_<k>.npz``,
    ``episode_<k>.html`` and, on request, ``episode_<k>.mp4`` and ``episode_<k>.png`` (a screenshot
    of the page at the capture or the closest approach, by headless Chromium). Returns one entry per episode."""

    loaded = load_policy(policy, seed=0, allow_unnormalized=allow_unnormalized, config=config)
    if getattr(loaded, "note", None):
        import sys

        print(f"note: {loaded.note}", file=sys.stderr)
    # before the episodes: a read-only folder or a special file among the outputs is refused at once
    kinds = ("npz", "html") + (("mp4",) if video else ()) + (("png",) if screenshot else ())
    # (the counts themselves are checked where the episodes start)
    wanted = (sorted({k for k in only if isinstance(k, int)}) if only is not None
              else range(episodes if isinstance(episodes, int) else 0))
    folder = files.writable_folder(out, "--out", [f"episode_{k:04d}.{ext}" for k in wanted for ext in kinds])
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=episodes if only is None else len(set(only)), desc=policy, unit="ep")
    written = []
    for rec in iter_recordings(loaded, episodes, config=config, seed=seed, wake_seeds=wake_seeds, num_envs=num_envs,
                               num_threads=num_threads, keep=only):
        k = int(rec.meta["episode"])
        rec.meta["policy"] = policy
        stem = folder / f"episode_{k:04d}"
        entry: dict[str, Any] = {"episode": k, "outcome": rec.outcome, "steps": rec.steps,
                                 "min_distance": rec.min_distance, "npz": str(rec.save(stem.with_suffix(".npz")))}
        entry["html"] = str(write_replay(rec, stem.with_suffix(".html"), max_frames=max_frames))
        if video:
            entry["mp4"] = str(write_video(rec, stem.with_suffix(".mp4")))
        if screenshot:
            errors = screenshot_replay(entry["html"], stem.with_suffix(".png"))
            if errors:
                raise RuntimeError(f"the replay page {entry['html']} reported JavaScript errors: {errors}")
            entry["png"] = str(stem.with_suffix(".png"))
        written.append(entry)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return sorted(written, key=lambda e: e["episode"])


__all__ = ["MAX_FRAMES", "frame_indices", "page_data", "pick_episodes", "plotly_js", "replay_html", "run_replay",
           "screenshot_replay", "write_evaluation_replays", "write_replay", "write_video"]
