"""Every shipped recipe in training/ is valid for the command that reads it: the stable-baselines3
training configs (``accd-gym train``), the distillation recipes (``accd-gym distill``), the sweep
configs (``accd-gym sweep``) with the training configs they start from, and the benchmark config
(``accd-gym benchmark``, full and ``--quick``)."""

from __future__ import annotations

import json
import pathlib

import pytest

from accd_gym.evals import benchmark, sweep
from accd_gym.learning import distill, training

ROOT = pathlib.Path(__file__).resolve().parent.parent
RECIPES = sorted((ROOT / "training").glob("*.json"))


def _kind(raw: dict) -> str:
    if "learners" in raw:
        return "benchmark"
    if "train_config" in raw and ("grid" in raw or "seeds" in raw):
        return "sweep"
    if distill.is_recipe(raw):
        return "distill"
    if raw.get("algo") in ("ppo", "sac") and "trainer" not in raw:
        return "training"
    return "other"


@pytest.mark.parametrize("path", RECIPES, ids=[p.name for p in RECIPES])
def test_every_recipe_is_valid_for_its_command(path, monkeypatch, tmp_path):
    monkeypatch.chdir(ROOT)  # recipes name each other relative to the repository
    raw = json.loads(path.read_text())
    kind = _kind(raw)
    if kind == "training":
        if "init_from" in raw:
            # The run a fine-tuning starts from exists once that run is trained; validate_config
            # checks its files, which a stand-in folder provides.
            for name in ("final_model.zip", "vecnormalize.pkl"):
                (tmp_path / name).write_bytes(b"")
            raw["init_from"] = str(tmp_path)
        training.validate_config(raw)
    elif kind == "distill":
        distill.validate_recipe(raw)
    elif kind == "sweep":
        sweep.load_config(path)
        training.validate_config(json.loads((ROOT / raw["train_config"]).read_text()))
    elif kind == "benchmark":
        for quick in (False, True):
            benchmark.load_config(path, quick=quick)


def test_the_plain_learners_tuning_recipes_run_at_the_zoo_budgets():
    """rl-zoo3's budgets for continuous control: PPO at least 3M steps, SAC at least 500k."""
    for tier in ("precision", "hard"):
        ppo = sweep.load_config(ROOT / "training" / f"ppo_tuning_{tier}.json")
        sac = sweep.load_config(ROOT / "training" / f"sac_tuning_{tier}.json")
        assert ppo["timesteps"] >= 3_000_000 and sac["timesteps"] >= 500_000
        assert ppo["eval_split"] == sac["eval_split"] == "validation"
