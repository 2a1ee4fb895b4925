"""Replay pages, videos and the replay commands.

The browser tests open a page in Debian's headless ``chromium`` (driven by Selenium through
Debian's ``chromium-driver``) from a ``file://`` URL with the
network offline, and check: no JavaScript error, no request beyond the file itself, the 3D views
drawn (not blank, and the data traces visible in them), the slider moving the scene (a second
screenshot differs), play advancing time, and the page's body transform agreeing with the
recording. ``scripts/test.sh`` installs chromium and chromium-driver when they are missing under
``CI=true``; without them, locally, they are skipped with the reason.
"""

import io
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from accd_gym.replays.recording import Recording, record_episodes

pytest.importorskip("plotly", reason="replay pages need plotly (the replay and test extras install it)")

from accd_gym.replays.replay import (  # noqa: E402
    MAX_FRAMES,
    frame_indices,
    pick_episodes,
    replay_html,
    write_replay,
    write_video,
)

SHORT = dict(capture_window=6.0, initial={"settle_time": 20.0})
TEN_MB = 10 * 1024 * 1024


@pytest.fixture(scope="module")
def full_episode() -> Recording:
    """A failed 70 s episode (neutral flaps on the first held-out wake seed: truncated)."""
    (rec,) = record_episodes("zero", 1, num_envs=1)
    assert rec.outcome == "truncated" and rec.steps == 700
    return rec


def test_a_70_s_episodes_page_is_self_contained_and_under_10_mb(full_episode, tmp_path):
    path = write_replay(full_episode, tmp_path / "page.html")
    size = path.stat().st_size
    assert size <= TEN_MB, f"{size / 1e6:.2f} MB"
    text = path.read_text()
    # No external script, stylesheet, image or frame: everything is inline.
    for needle in ("<script src", "<link", "<img", "<iframe", "@import"):
        assert needle not in text.lower(), needle
    assert "default-src 'none'" in text  # the page's CSP forbids loading anything
    data = json.loads(text.split('<script type="application/json" id="accd-data">')[1].split("</script>")[0])
    assert len(data["frames"]) == full_episode.steps + 1 and len(data["t"]) == 701
    assert data["meta"]["outcome"] == "truncated"


def test_long_recordings_are_decimated_in_3d_and_stay_under_10_mb(full_episode):
    idx = frame_indices(3001, MAX_FRAMES)
    assert len(idx) == 751 and idx[0] == 0 and idx[-1] == 3000 and (np.diff(idx) == 4).all()
    idx = frame_indices(3003, MAX_FRAMES)
    assert idx[-1] == 3002 and (np.diff(idx)[:-1] == 4).all()  # the last sample is always shown
    # A 280 s recording (the 70 s one four times over): 3D decimated, time plots complete.
    a = full_episode.arrays
    long = Recording({k: (np.concatenate([v] * 4) if v.ndim and v.shape[0] in (700, 701) else v) for k, v in a.items()},
                     dict(full_episode.meta))
    text = replay_html(long)
    assert len(text.encode()) <= TEN_MB, f"{len(text.encode()) / 1e6:.2f} MB"
    data = json.loads(text.split('id="accd-data">')[1].split("</script>")[0])
    assert len(data["t"]) == 4 * 701 and len(data["frames"]) <= MAX_FRAMES + 1
    assert data["meta"]["decimation"] == 3 and data["frames"][-1] == 4 * 701 - 1


def test_pick_episodes_orders_captures_first_then_miss_distance():
    from accd_gym.evals.evaluation import Episode

    def ep(i, captured, t, miss):
        return Episode(i, 0, "captured" if captured else "truncated", captured, 10, t, t if captured else None,
                       miss, miss, 0.0, 0.0, 0.0, 0.0, np.zeros((1, 3)))

    eps = [ep(0, False, 70, 3.0), ep(1, True, 30, 0.2), ep(2, True, 20, 0.4), ep(3, False, 70, 1.0), ep(4, False, 70, 9.0)]
    assert pick_episodes(eps, 3) == [("best", 2), ("median", 3), ("worst", 4)]
    assert pick_episodes(eps, 1) == [("median", 3)]
    assert pick_episodes(eps, 2) == [("best", 2), ("worst", 4)]
    assert [k for _, k in pick_episodes(eps, 9)] == [2, 1, 3, 0, 4]


def test_video_has_one_frame_per_sample(tmp_path):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    from accd_gym.envs.render import render_frame

    (rec,) = record_episodes("guidance", 1, config=dict(SHORT, capture_window=3.0), num_envs=1)
    path = write_video(rec, tmp_path / "episode.mp4")
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = reader.__next__()
    assert tuple(meta["size"]) == (640, 480) and meta["fps"] == pytest.approx(10.0)
    frames = [np.frombuffer(f, np.uint8).reshape(480, 640, 3) for f in reader]
    assert len(frames) == len(rec["time"]) == 31
    for k in (0, 30):  # lossy H.264, but the same picture
        assert np.abs(frames[k].astype(int) - render_frame(rec.frame_data(k)).astype(int)).mean() < 6.0
    assert np.abs(frames[0].astype(int) - frames[30].astype(int)).mean() > 0.05


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "accd_gym", *args], capture_output=True, text=True, cwd=cwd)


def test_replay_and_evaluate_replay_commands(tmp_path):
    env = json.dumps({"capture_window": 4.0, "initial": {"settle_time": 20.0}})
    done = _cli("replay", "--policy", "guidance", "--episodes", "2", "--out", "rep", "--env", env, "--video", "--quiet",
                cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    for k in (0, 1):
        for ext in ("html", "npz", "mp4"):
            assert (tmp_path / "rep" / f"episode_{k:04d}.{ext}").stat().st_size > 0
    rec = Recording.load(tmp_path / "rep" / "episode_0001.npz")
    assert rec.meta["policy"] == "guidance" and rec.meta["episode"] == 1
    done = _cli("evaluate", "--policy", "random", "--episodes", "5", "--num-envs", "2", "--replay", "3", "--out", "ev",
                "--env", env, "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    results = json.loads((tmp_path / "ev" / "results.json").read_text())
    pages = results["replays"]["random"]
    assert [p["pick"] for p in pages] == ["best", "median", "worst"]
    for p in pages:
        ep = results["policies"]["random"]["episodes"][p["episode"]]
        assert p["outcome"] == ep["outcome"]
        assert p["min_distance"] == pytest.approx(ep["min_distance"], abs=1e-5)  # float32 observation at t = 0
        assert os.path.isfile(tmp_path / p["html"]) and os.path.isfile(tmp_path / p["npz"])
    bad = _cli("replay", "--policy", "guidance", "--episodes", "0", cwd=tmp_path)
    assert bad.returncode == 2 and "--episodes = 0 is outside the allowed range" in bad.stderr


# --- in a real browser -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def browser():
    from accd_gym.replays.browser import Browser, available

    why = available()
    if why is not None:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI=true but no browser ({why}): scripts/test.sh installs Debian's chromium and chromium-driver")
        pytest.skip(f"{why}; scripts/test.sh installs them under CI=true")
    with Browser(1400, 900) as b:
        yield b


def _png(data: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).astype(int)


def _region(page, element: str, image: np.ndarray) -> np.ndarray:
    r = page.evaluate(f"(() => {{ const r = document.getElementById('{element}').getBoundingClientRect(); "
                      "return [r.left, r.top, r.right, r.bottom]; })()")
    left, top, right, bottom = (int(round(v)) for v in r)
    return image[top:bottom, left:right]


def _settled(page) -> None:
    page.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => setTimeout(r, 50))))")


def test_page_in_headless_chromium_offline(browser, tmp_path):
    (rec,) = record_episodes("guidance", 1, config=dict(SHORT, capture_window=20.0), num_envs=1)
    path = write_replay(rec, tmp_path / "replay.html")
    url = path.resolve().as_uri()
    page = browser.open(url, ready="window.accdReplay && window.accdReplay.ready", timeout=120)
    assert page.errors() == []
    assert page.evaluate("navigator.onLine") is False  # the network is off for the page
    assert page.evaluate("accdReplay.frames") == len(rec["time"])

    # The 3D views are drawn: many non-background pixels and colours, and the data traces are
    # what makes them (hiding the traces changes the picture).
    _settled(page)
    first = _png(page.screenshot())
    for view in ("whole", "close"):
        region = _region(page, view, first)
        ink = (np.abs(region - 255).sum(axis=-1) > 60).mean()
        colours = len(np.unique(region.reshape(-1, 3) // 16, axis=0))
        assert ink > 0.02 and colours > 20, f"{view}: {ink:.3f} ink, {colours} colours"
    page.evaluate("Plotly.restyle('close', {visible: false}).then(() => null)")
    _settled(page)
    hidden = _region(page, "close", _png(page.screenshot()))
    shown = _region(page, "close", first)
    assert (np.abs(hidden - shown).sum(axis=-1) > 60).mean() > 0.002, "the ACCD, boom and trails are drawn"
    page.evaluate("Plotly.restyle('close', {visible: true}).then(() => null)")
    if os.environ.get("ACCD_REPLAY_SHOTS"):  # to look at them: ACCD_REPLAY_SHOTS=folder
        from PIL import Image

        Image.fromarray(first.astype(np.uint8)).save(os.path.join(os.environ["ACCD_REPLAY_SHOTS"], "first.png"))

    # Moving the slider as a user does (input event) moves the scene, the cursor and the clock.
    clock0 = page.evaluate("document.getElementById('clock').textContent")
    last = len(rec["time"]) - 1
    page.evaluate(f"(() => {{ const s = document.getElementById('slider'); s.value = '{last}'; "
                  "s.dispatchEvent(new Event('input')); })()")
    page.wait_for(f"accdReplay.frame() === {last}")
    page.evaluate("accdReplay.idle()")
    _settled(page)
    second = _png(page.screenshot())
    assert page.evaluate("document.getElementById('clock').textContent") != clock0
    for view in ("whole", "close", "plots"):
        changed = (np.abs(_region(page, view, second) - _region(page, view, first)).sum(axis=-1) > 60).mean()
        assert changed > 0.001, f"{view}: {changed:.4f} of the pixels changed"

    # Play advances time; pause stops it.
    page.evaluate("accdReplay.setFrame(0).then(() => null)")
    page.evaluate("document.getElementById('play').click()")
    page.evaluate("new Promise(r => setTimeout(r, 1500))")
    page.evaluate("document.getElementById('play').click()")
    assert page.evaluate("accdReplay.frame()") > 0

    # The page draws the body with the recording's attitude: its capture point (the tail)
    # is the recorded one, to the page's rounding (1 mm, 1e-6).
    back = -rec.meta["accd_geometry"]["capture_offset"]
    for k in (0, last // 2, last):
        drawn = page.evaluate(f"accdReplay.bodyPoint({k}, [{back}, 0, 0])")
        np.testing.assert_allclose(drawn, rec["capture_point"][k], atol=3e-3)

    assert page.errors() == []
    requests = page.requests()
    assert requests and all(u == url for u in requests), requests
