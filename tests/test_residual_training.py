"""Training with residual control and history: the recipes (training/residual_*.json equal to
accd_gym.zoo's), a zero-initialised policy that evaluates as its base controller bit for bit,
and a smoke training of each recipe through ``accd-gym train``."""

import json
import pathlib

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from accd_gym.cli import main  # noqa: E402
from accd_gym.evals.evaluation import SB3Policy, run_episodes  # noqa: E402
from accd_gym.control.lqr import LqrPolicy  # noqa: E402
from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS  # noqa: E402
from accd_gym.learning.training import load_config, train, validate_config  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
RECIPES = [(name, tier) for name in ("residual_ppo", "residual_sac") for tier in ("precision", "hard")]


@pytest.mark.parametrize("name, tier", RECIPES)
def test_residual_recipes_are_the_zoo_hyperparameters(name, tier):
    import importlib

    from accd_gym.envs.tiers import TIERS
    from accd_gym.zoo import RECIPES as ZOO
    from accd_gym.zoo import agent_env

    recipe = json.loads((ROOT / "training" / f"{name}_{tier}.json").read_text())
    for key, value in ZOO[name].items():
        assert recipe[key] == value, key
    assert recipe["env"] == {"tier": tier, **agent_env(tier)}
    assert recipe["env"]["residual"]["base"] == "lqr" and recipe["zero_action_init"] is True
    assert ("history" in recipe["env"]) == (tier == "hard")  # history where the tier has sensors
    assert recipe["total_timesteps"] >= (3_000_000 if recipe["algo"] == "ppo" else 500_000)
    validate_config(recipe)
    hyper = importlib.import_module(f"accd_gym.zoo.{name}").hyperparams
    entry = hyper[TIERS[tier].id]
    assert entry["env_kwargs"] == agent_env(tier) and entry["callback"] == "accd_gym.learning.callbacks.ZeroActionInit"
    assert entry["n_envs"] == recipe["num_envs"] and entry["n_timesteps"] == recipe["total_timesteps"]
    assert eval(entry["normalize"]) == recipe["vec_normalize"]
    assert all(entry[k] == v for k, v in recipe["algo_kwargs"].items())


def short(name: str, tier: str, **algo_kwargs) -> dict:
    """The recipe with few envs and short rollouts, for tests."""
    cfg = load_config(ROOT / "training" / f"{name}_{tier}.json")
    cfg["num_envs"] = 4
    if cfg["algo"] == "ppo":
        cfg["algo_kwargs"].update(n_steps=32, batch_size=64, n_epochs=1)
    else:
        cfg["algo_kwargs"].update(learning_starts=64, buffer_size=2000, batch_size=32)
    cfg["algo_kwargs"].update(algo_kwargs)
    return validate_config(cfg)


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_a_zero_initialised_residual_policy_evaluates_as_the_lqr_bit_for_bit(algo, tmp_path):
    """Learning rate 0: the model after training is the one training started from."""
    cfg = short(f"residual_{algo}", "hard", learning_rate=0.0)
    meta = train(cfg, tmp_path / "run", timesteps=256, progress=False)
    assert meta["status"] == "done"
    config = {"tier": "hard", "capture_window": 6.0}
    seeds = list(HELD_OUT_WAKE_SEEDS[:6])
    policy = SB3Policy(tmp_path / "run", config=config)
    assert policy.agent_options.to_dict() == {k: cfg["env"][k] for k in ("residual", "history")}
    ours = run_episodes(policy, 6, wake_seeds=seeds, num_envs=3, config=config)
    lqr = run_episodes(LqrPolicy.for_config(config), 6, wake_seeds=seeds, num_envs=3, config=config)
    assert any(e.steps > 1 for e in lqr)
    for a, b in zip(ours, lqr):
        assert a.metrics() == b.metrics()
        assert np.array_equal(a.trajectory, b.trajectory)


def test_zero_action_init_gives_exactly_zero_deterministic_actions():
    from stable_baselines3 import PPO, SAC

    from accd_gym.learning.callbacks import zero_action_init
    from accd_gym.envs.sb3 import AccdVecEnv

    env = AccdVecEnv(2, seed=0, residual={"base": "lqr"}, capture_window=2.0)
    obs = np.random.default_rng(0).uniform(-3, 3, (5,) + env.observation_space.shape).astype(np.float32)
    for cls, kw in ((PPO, {"log_std_init": -2.0}), (SAC, {"log_std_init": -2.0})):
        model = cls("MlpPolicy", env, policy_kwargs=kw, seed=0, device="cpu")
        before, _ = model.predict(obs, deterministic=True)
        assert np.abs(before).max() > 0  # not zero by itself
        zero_action_init(model, kw["log_std_init"])
        after, _ = model.predict(obs, deterministic=True)
        assert not after.any()
        if cls is SAC:
            import torch

            mean, log_std, _ = model.actor.get_action_dist_params(torch.as_tensor(obs))
            assert torch.all(log_std == -2.0)


@pytest.mark.parametrize("name, tier", RECIPES)
def test_accd_gym_train_runs_each_residual_recipe(name, tier, tmp_path, capsys):
    """A smoke training of a few thousand steps with the recipe as shipped, from the command line,
    then a held-out evaluation of the run."""
    out = tmp_path / "run"
    steps = 3000
    assert main(["train", "--config", str(ROOT / "training" / f"{name}_{tier}.json"), "--out", str(out),
                 "--timesteps", str(steps), "--quiet"]) == 0
    meta = json.loads((out / "run.json").read_text())
    assert meta["status"] == "done" and meta["timesteps"] >= steps and meta["config"]["env"]["tier"] == tier
    policy = SB3Policy(out, config={"tier": tier, "capture_window": 2.0})
    eps = run_episodes(policy, 2, wake_seeds=list(HELD_OUT_WAKE_SEEDS[:2]), num_envs=2,
                       config={"tier": tier, "capture_window": 2.0})
    assert len(eps) == 2 and all(np.isfinite(e.final_distance) for e in eps)


def test_a_residual_model_without_its_run_is_refused(tmp_path):
    from accd_gym.errors import ConfigError

    cfg = short("residual_ppo", "precision")
    train(cfg, tmp_path / "run", timesteps=128, progress=False)
    lone = tmp_path / "lone"
    lone.mkdir()
    for f in ("final_model.zip", "vecnormalize.pkl"):
        (lone / f).write_bytes((tmp_path / "run" / f).read_bytes())
    with pytest.raises(ConfigError, match="run folder"):
        SB3Policy(lone / "final_model.zip")


def test_bad_env_options_in_a_training_config_are_refused():
    from accd_gym.errors import ConfigError

    with pytest.raises(ConfigError, match=r"`residual.scale` = 3"):
        validate_config({"env": {"residual": {"scale": 3}}})
    with pytest.raises(ConfigError, match=r"`zero_action_init` = 'yes'"):
        validate_config({"zero_action_init": "yes"})
