"""Hyperparameters of the project's training recipes for `rl-zoo3 <https://github.com/DLR-RM/rl-baselines3-zoo>`_,
for every registered id of accd-gym::

    python -m rl_zoo3.train --algo ppo --env accd_gym/InAirCapture-v0 --gym-packages accd_gym \\
        --conf-file accd_gym.zoo.ppo
    python -m rl_zoo3.train --algo sac --env accd_gym/InAirCapture-v0 --gym-packages accd_gym \\
        --conf-file accd_gym.zoo.sac

``--conf-file`` takes the module name (rl-zoo3 imports it and reads its ``hyperparams``). The
values are those of ``training/ppo.json`` and ``training/sac.json`` (the recipes of
``accd-gym train``; ``tests/test_ecosystem.py`` keeps them equal): the envs, the observation and
reward normalisation (``VecNormalize``), the algorithm's arguments and the network.
"""

from __future__ import annotations

from typing import Any

from accd_gym.envs.tiers import TIERS

#: ``accd-gym train``'s recipes, as (algo -> training config fields) for rl-zoo3.
RECIPES: dict[str, dict[str, Any]] = {
    "ppo": {
        "total_timesteps": 3_000_000,
        "num_envs": 16,
        "vec_normalize": {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0, "clip_reward": 10.0},
        "algo_kwargs": {
            "learning_rate": 0.0003,
            "n_steps": 256,
            "batch_size": 1024,
            "n_epochs": 5,
            "gamma": 0.995,
            "gae_lambda": 0.95,
            "clip_range": 0.2,
            "ent_coef": 0.0,
            "max_grad_norm": 0.5,
        },
        "policy_kwargs": {"net_arch": {"pi": [128, 128], "vf": [128, 128]}, "activation_fn": "tanh", "log_std_init": -1.0},
    },
    "sac": {
        "total_timesteps": 1_000_000,
        "num_envs": 8,
        "vec_normalize": {"norm_obs": True, "norm_reward": False, "clip_obs": 10.0},
        "algo_kwargs": {
            "learning_rate": 0.0003,
            "buffer_size": 300000,
            "batch_size": 256,
            "learning_starts": 5000,
            "train_freq": 1,
            "gradient_steps": 2,
            "gamma": 0.995,
            "tau": 0.005,
        },
        "policy_kwargs": {"net_arch": [256, 256], "activation_fn": "relu"},
    },
}


def zoo_hyperparams(algo: str) -> dict[str, dict[str, Any]]:
    """rl-zoo3's ``hyperparams`` of ``algo`` (``"ppo"``, ``"sac"``): one entry per registered id.

    ``policy_kwargs`` is given as the text rl-zoo3 evaluates (with ``nn`` = ``torch.nn``), so
    this module imports no torch.
    """
    recipe = RECIPES[algo]
    kwargs = dict(recipe["policy_kwargs"])
    activation = {"tanh": "nn.Tanh", "relu": "nn.ReLU", "elu": "nn.ELU"}[kwargs.pop("activation_fn")]
    policy_kwargs = "dict(" + ", ".join([f"{k}={v!r}" for k, v in kwargs.items()] + [f"activation_fn={activation}"]) + ")"
    entry = {
        "n_envs": recipe["num_envs"],
        "n_timesteps": float(recipe["total_timesteps"]),
        "policy": "MlpPolicy",
        "normalize": repr(recipe["vec_normalize"]),
        **recipe["algo_kwargs"],
        "policy_kwargs": policy_kwargs,
    }
    return {t.id: dict(entry) for t in TIERS.values()}


__all__ = ["RECIPES", "zoo_hyperparams"]
