"""scripts/bench_summary.py: the performance targets read from one bench.sh run's files."""

from __future__ import annotations

import importlib.util
import json
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _summary():
    spec = importlib.util.spec_from_file_location("bench_summary", ROOT / "scripts" / "bench_summary.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _criterion(root: pathlib.Path, n: int, threads: int, mean_ns: float) -> None:
    d = root / "batch_step" / "agent_steps" / f"default-n{n}-threads{threads}" / "new"
    d.mkdir(parents=True)
    (d / "estimates.json").write_text(json.dumps({"mean": {"point_estimate": mean_ns}}))


def test_targets_are_computed_from_the_files_and_missing_inputs_are_said(tmp_path):
    s = _summary()
    out, crit = tmp_path / "run", tmp_path / "criterion"
    out.mkdir()
    (out / "physics.json").write_text(json.dumps({"ratios": {
        "capture default / tether": 1.9, "mujoco / capture default": 16.0,
        "mujoco / tether": 31.0, "tether n=300 / n=30 (per step)": 9.0}}))
    rows = {r["target"]: r for r in s.targets(out, crit)}
    assert rows["capture-system step / tether step"]["met"] is True
    assert rows["MuJoCo bare chain / capture-system step"]["met"] is False
    assert rows["MuJoCo bare chain / tether step"]["value"] == 31.0
    # No env, criterion or training files: not measured, neither met nor failed.
    ppo = rows["PPO with training/ppo.json, end to end"]
    assert ppo["value"] is None and ppo["met"] is None
    assert "not measured" in s.markdown(list(rows.values()))

    env_rows = [{"env": e, "num_envs": n, "agent_steps_per_s": rate}
                for e, n, rate in [("native VectorEnv (gymnasium.make_vec)", 16, 26_000.0),
                                   ("native SB3 AccdVecEnv", 16, 24_000.0),
                                   ("native VectorEnv (gymnasium.make_vec)", 256, 30_000.0),
                                   ("native SB3 AccdVecEnv", 256, 27_000.0)]]
    (out / "envs_default.json").write_text(json.dumps({"substeps": 10, "rows": env_rows}))
    # 16 envs in 0.5 ms with 2 threads (32,000/s), 1.0 ms with one; 256 in 10 ms on 2 (25,600/s).
    # The thread counts come from the case names, whatever this machine's core count.
    _criterion(crit, 16, 2, 0.5e6)
    _criterion(crit, 16, 1, 1.0e6)
    _criterion(crit, 256, 2, 10e6)
    (out / "training_default.json").write_text(json.dumps({"accd env": {"agent_steps_per_s": 8100.0}}))
    rows = {r["target"]: r for r in s.targets(out, crit)}
    n16 = rows["vector envs, N = 16 (the slower of the two)"]
    assert n16["value"] == 24_000.0 and n16["met"] is False
    assert rows["vector envs, N = 256 (the slower of the two)"]["met"] is True
    share = rows["vector envs / Rust batch, N = 16"]
    assert abs(share["value"] - 0.75) < 1e-12 and share["met"] is False
    assert abs(rows["vector envs / Rust batch, N = 256"]["value"] - 27_000.0 / 25_600.0) < 1e-12
    assert abs(rows["Rust batch 1 -> 2 threads, N = 16"]["value"] - 2.0) < 1e-12
    assert rows["Rust batch 1 -> 2 threads, N = 256"]["met"] is None  # no one-thread estimate
    assert rows["PPO with training/ppo.json, end to end"]["met"] is True


def test_the_share_of_the_rust_batch_comes_from_the_side_by_side_rounds_when_there(tmp_path):
    s = _summary()
    out, crit = tmp_path / "run", tmp_path / "criterion"
    out.mkdir()
    env_rows = [{"env": "native VectorEnv (gymnasium.make_vec)", "num_envs": 16, "agent_steps_per_s": 10_000.0}]
    beside = {"16": {"rust batch": 16_000.0, "native VectorEnv": 15_200.0, "native SB3 AccdVecEnv": 14_000.0}}
    (out / "envs_default.json").write_text(json.dumps({"substeps": 10, "rows": env_rows, "side_by_side": beside}))
    _criterion(crit, 16, 2, 0.5e6)  # 32,000/s in another process: not what the share is taken from
    rows = {r["target"]: r for r in s.targets(out, crit)}
    share = rows["vector envs / Rust batch, N = 16"]
    assert abs(share["value"] - 14_000.0 / 16_000.0) < 1e-12 and share["met"] is False
    assert share["source"] == "envs_default.json, side by side"
    # N = 256 has no side-by-side rounds and no env rows: not measured.
    assert rows["vector envs / Rust batch, N = 256"]["value"] is None
