"""Expert datasets (accd_gym.evals.datasets, ``accd-gym dataset``): a dataset round-trips through
Minari (``minari.load_dataset``) and its episodes are those of an evaluation of the same policy on
the same seeds; only training wake seeds outside the validation ones are used."""

from __future__ import annotations

import numpy as np
import pytest

from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS, TRAINING_WAKE_SEEDS, VALIDATION_WAKE_SEEDS
from accd_gym.errors import ConfigError
from accd_gym.evals.datasets import DATASET_WAKE_SEEDS, dataset_id, record_dataset
from accd_gym.evals.episodes import run_episodes
from accd_gym.evals.policies import load_policy

minari = pytest.importorskip("minari", reason="the dataset extra (minari) is not installed")


def test_dataset_wake_seeds_are_training_seeds_never_validation_or_held_out_ones():
    # (ranges of step 1, compared by their ends: the training range is large)
    d = DATASET_WAKE_SEEDS
    assert TRAINING_WAKE_SEEDS.start <= d.start < d.stop <= TRAINING_WAKE_SEEDS.stop and len(d) > 0
    for other in (VALIDATION_WAKE_SEEDS, HELD_OUT_WAKE_SEEDS):
        assert d.stop <= other.start or other.stop <= d.start
    assert dataset_id("hard", "lqr") == "accd/hard/lqr-v0"
    assert dataset_id("hard", "runs/x/final_model.zip") == "accd/hard/final_model-v0"


@pytest.mark.parametrize("tier", ["sensors"])
def test_a_dataset_round_trips_through_minari_and_equals_the_evaluation(tier, tmp_path, monkeypatch):
    episodes, seed = 3, 4
    done = record_dataset("lqr", tier, episodes, tmp_path, seed=seed, true_observation=True, num_envs=2,
                          num_threads=1)
    assert done["id"] == f"accd/{tier}/lqr-v0"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    ds = minari.load_dataset(done["id"])
    assert ds.total_episodes == episodes and ds.total_steps == done["steps"]
    evaluated = run_episodes(load_policy("lqr", seed, config={"tier": tier}), episodes, seed=seed,
                             wake_seeds=list(DATASET_WAKE_SEEDS[:episodes]), num_envs=2, num_threads=1,
                             config={"tier": tier})
    for ep, ev in zip(ds.iterate_episodes(), evaluated):
        steps = len(ep.actions)
        assert ep.observations.shape == (steps + 1, 25) and ep.actions.shape == (steps, 4)
        assert steps == ev.steps
        assert bool(ep.terminations[-1]) == (ev.outcome != "truncated") and bool(ep.truncations[-1]) == (ev.outcome == "truncated")
        assert not ep.terminations[:-1].any() and not ep.truncations[:-1].any()
        assert sum(float(np.float32(r)) for r in ep.rewards) == pytest.approx(ev.episode_return, abs=1e-9)
        assert float(np.abs(ep.actions).mean()) == pytest.approx(ev.mean_abs_action, rel=1e-6)
        true_obs = ep.infos["true_obs"]
        assert true_obs.shape == ep.observations.shape
        assert not np.array_equal(true_obs, ep.observations)  # a sensor tier: the sensors show other values
    # the same id in the same folder is refused before any episode runs
    with pytest.raises(ConfigError, match="already holds the dataset"):
        record_dataset("lqr", tier, 1, tmp_path)


def test_bad_arguments_are_refused_before_any_work(tmp_path):
    with pytest.raises(ConfigError, match="--tier 'nope'"):
        record_dataset("lqr", "nope", 1, tmp_path)
    with pytest.raises(ConfigError, match="episodes"):
        record_dataset("lqr", "nominal", 0, tmp_path)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(ConfigError, match="--out"):
        record_dataset("lqr", "nominal", 1, blocker)


def test_the_command_writes_a_dataset_minari_loads(tmp_path, monkeypatch, capsys):
    from accd_gym.cli import main

    assert main(["dataset", "--policy", "zero", "--tier", "nominal", "--episodes", "2", "--out", str(tmp_path),
                 "--num-envs", "2"]) == 0
    assert "accd/nominal/zero-v0" in capsys.readouterr().out
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    ds = minari.load_dataset("accd/nominal/zero-v0")
    assert ds.total_episodes == 2 and not ds.iterate_episodes().__next__().infos
    from accd_gym.envs.tiers import TIERS

    assert ds.spec.env_spec.id == TIERS["nominal"].id
