"""scripts/ship_policies.py reads a benchmark folder as its recorded results: the run's held-out
outcomes and the LQR's on the same episodes, keyed by the tier the run was trained on."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from accd_gym.errors import ConfigError
from accd_gym.evals.episodes import EVAL_BASE_SEED

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("ship_policies", ROOT / "scripts" / "ship_policies.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_benchmark_folder_gives_the_runs_and_the_lqrs_outcomes(tmp_path):
    run = tmp_path / "runs" / "hard_residual_sac_seed3"
    run.mkdir(parents=True)
    (run / "result.json").write_text(json.dumps({
        "key": {"job": {"tier": "hard", "algo": "residual_sac", "seed": 3}},
        "result": {"episodes": {"captured": [True, False, True]}}}))
    (tmp_path / "baselines").mkdir()
    (tmp_path / "baselines" / "hard_lqr.json").write_text(json.dumps({"record": {"captured": [True, True, False]}}))
    got = _script().benchmark_results(tmp_path, "hard_residual_sac_seed3")
    assert got == {"hard": {"base_seed": EVAL_BASE_SEED, "hard_residual_sac_seed3": {"captured": "101"},
                            "lqr": {"captured": "110"}}}
    with pytest.raises(ConfigError, match=r"--key 'hard_sac_seed0' has no result .*allowed: \['hard_residual_sac_seed3'\]"):
        _script().benchmark_results(tmp_path, "hard_sac_seed0")


def test_the_shipped_run_is_recomputed_from_the_benchmark_folder_on_validation_episodes(tmp_path):
    """chosen_run (what ship_policies ships) takes the highest validation rate; the run best on
    the held-out episodes is not chosen for it."""
    from accd_gym.evals.benchmark import chosen_run

    for seed, held_out, validation in ((0, [True] * 4, [True, False, False, False]),
                                       (1, [True, False, False, False], [True, True, True, False])):
        run = tmp_path / "runs" / f"hard_residual_sac_seed{seed}"
        run.mkdir(parents=True)
        (run / "result.json").write_text(json.dumps({"key": {}, "result": {
            "name": run.name, "job": {"tier": "hard", "algo": "residual_sac", "seed": seed},
            "episodes": {"captured": held_out}, "validation": {"captured": validation}}}))
    got = chosen_run(tmp_path, "hard", "residual_sac")
    assert got["name"] == "hard_residual_sac_seed1" and got["validation_rate"] == 0.75
    assert got["candidates"] == {"hard_residual_sac_seed0": 0.25, "hard_residual_sac_seed1": 0.75}
    with pytest.raises(ConfigError, match="no finished ppo run on hard with a validation record"):
        chosen_run(tmp_path, "hard", "ppo")
    with pytest.raises(ConfigError, match="is not the run chosen on the validation episodes"):
        _script().main(["--name", "x", "--results", str(tmp_path), "--tier", "hard", "--method", "residual_sac",
                        "--key", "hard_residual_sac_seed0"])
