"""Recorded episodes: a recording equals the env's own outputs step for step,
reading it leaves the episode unchanged, its geometry is consistent, and the .npz loads without
accd-gym."""

import json
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import accd_gym
from accd_gym import ENV_ID, ConfigError
from accd_gym.control.registry import make_controller
from accd_gym.evals.evaluation import run_episodes
from accd_gym.replays.recording import SAMPLE_FIELDS, STEP_FIELDS, Recording, RecordEpisode, record_episodes
from accd_gym.envs.render import render_frame
from accd_gym.envs.task import INFO_NAMES, OBSERVATION_SCALE

SHORT = dict(capture_window=12.0, initial={"settle_time": 20.0})
FAST = {"wake": {"sampling": "per_step"}, "turbulence": {"normal_sampler": "ziggurat", "lane_streams": "per_lane"}}
BASE = 77


def rotation(q):
    """Rotation matrix of a unit quaternion (w, x, y, z) (body to TA frame)."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


@pytest.mark.parametrize("extra", [{}, FAST], ids=["exact-air", "fast-air"])
def test_recording_equals_a_single_envs_own_outputs_step_for_step(extra):
    config = dict(SHORT, **extra)
    wake = [1_000_000_003, 1_000_000_004]
    recs = record_episodes(make_controller("random", 5), 2, config=config, seed=BASE, wake_seeds=wake, num_envs=2)
    assert [r.meta["episode"] for r in recs] == [0, 1]
    for i, rec in enumerate(recs):
        # The same episode in a plain env that nobody reads anything from but its outputs:
        # recording (BatchEnv.record_data every step) must not change it.
        env = accd_gym.InAirCaptureEnv(**config)
        obs, info = env.reset(seed=BASE + i, options={"wake_seed": wake[i]})
        assert info["wake_seed"] == wake[i] == rec.meta["seeds"]["wake"]
        assert env.episode_seeds() == rec.meta["seeds"]
        np.testing.assert_array_equal(obs, rec["observation"][0])
        # A second copy whose state is read with render_data at every step, for the positions.
        seen = accd_gym.InAirCaptureEnv(render_mode="rgb_array", **config)
        seen.reset(seed=BASE + i, options={"wake_seed": wake[i]})
        for k, action in enumerate(rec["action"]):
            obs, reward, terminated, truncated, info = env.step(action)
            seen.step(action)
            assert np.array_equal(obs, rec["observation"][k + 1]), f"episode {i} step {k}: observation"
            assert reward == rec["reward"][k]
            assert (terminated, truncated) == (rec["terminated"][k], rec["truncated"][k])
            for name in INFO_NAMES:
                assert info[name] == rec[f"info_{name}"][k], f"episode {i} step {k}: info {name}"
            data = seen._core.render_data(0)
            for ours, theirs in (("joints", "joints"), ("position", "accd_position"), ("capture_point", "capture_point"),
                                 ("boom_tip", "boom_tip"), ("attitude", "attitude"),
                                 ("flap_deflection_deg", "deflection_deg"), ("attachment_tension", "tension"),
                                 ("distance", "distance"), ("time", "time")):
                np.testing.assert_array_equal(rec[ours][k + 1], data[theirs], err_msg=f"step {k}: {ours}")
            if k in (0, len(rec["action"]) - 1):
                np.testing.assert_array_equal(render_frame(rec.frame_data(k + 1)), seen.render())
        assert terminated or truncated
        assert rec.outcome == next((e for e in ("captured", "overload", "envelope_exit", "diverged") if info[e]),
                                   "truncated")


@pytest.mark.parametrize("policy", ["random", "guidance"])
def test_recorded_episodes_are_the_evaluations_episodes(policy):
    """Same batch, seeds and policy calls as run_episodes, so a stateful or random policy's
    episode k is the evaluation's episode k (evaluate --replay relies on it)."""
    kw = dict(seed=BASE, wake_seeds=list(accd_gym.HELD_OUT_WAKE_SEEDS[:5]), num_envs=2, config=SHORT)
    evaluated = run_episodes(make_controller(policy, 0), 5, **kw)
    recs = record_episodes(make_controller(policy, 0), 5, **kw)
    for e, rec in zip(evaluated, recs):
        assert rec.meta["episode"] == e.index
        assert rec.outcome == e.outcome and rec.steps == e.steps
        assert rec.meta["seeds"]["wake"] == e.wake_seed
        assert rec["info_time"][-1] == e.time and rec["info_distance"][-1] == e.final_distance
        assert float(np.sum(rec["reward"].astype(np.float32), dtype=np.float64)) == pytest.approx(e.episode_return, abs=1e-9)
        # The evaluation's trajectory is the true capture point minus boom tip (float32), the
        # recording's the same state's snapshot; the observation shows it scaled (no sensors here).
        np.testing.assert_allclose(rec["capture_point"] - rec["boom_tip"], e.trajectory, rtol=0, atol=1e-5)
        np.testing.assert_allclose(-rec["observation"][:, 0:3] / OBSERVATION_SCALE["boom_rel_x"], e.trajectory, rtol=0, atol=1e-5)
    # keep= records only the chosen episodes, and they are the same.
    (again,) = record_episodes(make_controller(policy, 0), 5, keep=[3], **kw)
    for name in recs[3].arrays:
        np.testing.assert_array_equal(again[name], recs[3][name])


def test_recorded_geometry_is_consistent():
    (rec,) = record_episodes("guidance", 1, config=SHORT, seed=BASE, num_envs=1)
    cfg = rec.meta["config"]
    geometry = rec.meta["accd_geometry"]
    steps = rec.steps
    t = rec["time"]
    np.testing.assert_allclose(t, np.arange(steps + 1) * cfg["agent_step"], rtol=0, atol=1e-9)
    joints = rec["joints"]
    assert joints.shape == (steps + 1, cfg["tether"]["segments"] + 1, 3)
    # Rigid segments of length L/n between consecutive joints; the last joint is the ACCD.
    seg = np.linalg.norm(np.diff(joints, axis=1), axis=2)
    np.testing.assert_allclose(seg, cfg["tether"]["length"] / cfg["tether"]["segments"], rtol=1e-9)
    np.testing.assert_allclose(joints[:, -1], rec["position"], rtol=0, atol=1e-9)
    # Tension entry 0 is the attachment's k s + c s'; all entries pull (towed tether).
    np.testing.assert_allclose(rec["tensions"][:, 0], rec["attachment_tension"], rtol=1e-9)
    assert (rec["tensions"] > 0).all()
    # The capture point is capture_offset behind the centre of gravity along body -x: this pins
    # the quaternion convention (w, x, y, z; body to TA) that the replay page draws the body with.
    for k in range(0, steps + 1, 7):
        expected = rec["position"][k] + rotation(rec["attitude"][k]) @ np.array([-geometry["capture_offset"], 0, 0])
        np.testing.assert_allclose(rec["capture_point"][k], expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(rec["attitude"], axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(rec["distance"], np.linalg.norm(rec["boom_tip"] - rec["capture_point"], axis=1), rtol=1e-12)
    np.testing.assert_array_equal(rec["distance"][1:], rec["info_distance"])
    np.testing.assert_allclose(rec["flap_command_deg"][1:], rec["action"] * cfg["accd"]["flap_limit_deg"], rtol=1e-6)
    # The observation's boom-relative position is the recorded one (float32, clipped at +-10).
    rel = (rec["boom_tip"] - rec["capture_point"]) * OBSERVATION_SCALE["boom_rel_x"]
    np.testing.assert_allclose(rec["observation"][:, 0:3], np.clip(rel, -10, 10), rtol=0, atol=1e-5)


def test_npz_loads_without_accd_gym(tmp_path):
    (rec,) = record_episodes("zero", 1, config=dict(SHORT, capture_window=3.0), seed=BASE, num_envs=1)
    path = rec.save(tmp_path / "episode.npz")
    script = f"""
import json, sys
import numpy as np
z = np.load({str(path)!r}, allow_pickle=False)
assert str(z["format"]) == "accd-gym-recording" and int(z["version"]) == 1
meta = json.loads(str(z["meta_json"]))
out = {{k: list(z[k].shape) for k in z.files}}
assert "accd_gym" not in sys.modules
print(json.dumps({{"shapes": out, "outcome": meta["outcome"], "segments": meta["config"]["tether"]["segments"]}}))
"""
    # A fresh interpreter (-I: no cwd or user site on sys.path) that imports numpy and json only.
    done = subprocess.run([sys.executable, "-I", "-c", script], capture_output=True, text=True, check=True)
    doc = json.loads(done.stdout)
    assert doc["outcome"] == rec.outcome == "truncated"
    assert doc["shapes"]["joints"] == [31, 31, 3] and doc["shapes"]["action"] == [30, 4]
    for name in (*SAMPLE_FIELDS, *STEP_FIELDS, "observation", "equilibrium"):
        assert name in doc["shapes"], name
    back = Recording.load(path)
    assert back.meta == json.loads(json.dumps(rec.meta))
    for name, value in rec.arrays.items():
        np.testing.assert_array_equal(back[name], value)
        assert back[name].dtype == value.dtype
    (tmp_path / "other.npz").write_bytes(b"")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ConfigError, match="not an accd-gym recording"):
        Recording.load(tmp_path / "other.npz")


def test_wrapper_records_what_drives_the_env(tmp_path):
    wake = 1_000_000_009
    env = RecordEpisode(gym.make(ENV_ID, **SHORT), folder=tmp_path)
    policy = make_controller("guidance", 0)
    obs, _ = env.reset(seed=BASE, options={"wake_seed": wake})
    policy.reset(None)
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(policy.predict(obs[None])[0])
        done = terminated or truncated
    (rec,) = env.recordings
    assert (tmp_path / "episode_0000.npz").is_file()
    (ref,) = record_episodes("guidance", 1, config=SHORT, seed=BASE, wake_seeds=[wake], num_envs=1)
    for name in ref.arrays:
        np.testing.assert_array_equal(rec[name], ref[name], err_msg=name)
    assert rec.outcome == ref.outcome


def test_bad_arguments_name_the_field():
    with pytest.raises(ConfigError, match="`episodes` = 0"):
        record_episodes("zero", 0)
    with pytest.raises(ConfigError, match="`keep` has episode 4"):
        record_episodes("zero", 2, keep=[4], config=SHORT)
    with pytest.raises(ConfigError, match="1 wake seeds for 2 episodes"):
        record_episodes("zero", 2, wake_seeds=[5], config=SHORT)
    with pytest.raises(ConfigError, match="RecordEpisode wraps"):
        RecordEpisode(gym.make("CartPole-v1"))


def test_every_public_name_of_the_replay_modules_has_a_docstring():
    import inspect

    from accd_gym.replays import browser, recording, replay

    for module in (recording, replay, browser):
        assert inspect.getdoc(module)
        for name in module.__all__:
            obj = getattr(module, name)
            if inspect.isclass(obj) or inspect.isfunction(obj):
                assert inspect.getdoc(obj), f"{module.__name__}.{name}"
                for attr, member in vars(obj).items() if inspect.isclass(obj) else ():
                    if not attr.startswith("_") and callable(member) or isinstance(member, property):
                        assert inspect.getdoc(member), f"{module.__name__}.{name}.{attr}"


def test_format_doc_lists_every_array_as_recorded():
    from pathlib import Path

    from accd_gym.replays.recording import fields_markdown

    doc = (Path(__file__).parents[1] / "docs" / "recording-format.md").read_text()
    table = fields_markdown()
    assert table in doc, "docs/recording-format.md: regenerate the table with accd_gym.replays.recording.fields_markdown()"
    (rec,) = record_episodes("zero", 1, config=dict(SHORT, capture_window=1.0), seed=BASE, num_envs=1)
    rows = [r.split("|")[1:4] for r in table.splitlines()[2:]]
    assert {name.strip(" `") for name, _, _ in rows} == set(rec.arrays)
    for name, shape, dtype in rows:
        assert str(rec[name.strip(" `")].dtype) == dtype.strip(), name
        assert rec[name.strip(" `")].ndim == shape.count(",") + (0 if shape.strip().endswith(",)") else 1), name
