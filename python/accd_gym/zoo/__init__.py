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

Residual recipes (:mod:`accd_gym.envs.residual`: the agent learns a correction of at most 0.3 flap
units on top of the LQR, starting at zero, ``accd_gym.learning.callbacks.ZeroActionInit``; with the
observation history of 4 steps on the tiers with sensors)::

    python -m rl_zoo3.train --algo ppo --env accd_gym/InAirCaptureHard-v0 --gym-packages accd_gym \
        --conf-file accd_gym.zoo.residual_ppo
    python -m rl_zoo3.train --algo sac --env accd_gym/InAirCaptureHard-v0 --gym-packages accd_gym \
        --conf-file accd_gym.zoo.residual_sac

Their values are those of ``training/residual_{ppo,sac}_{precision,hard}.json`` (the env options
per tier: :func:`agent_env`).
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
    # Residual PPO on the LQR: 64 envs, small steps (learning rate 1e-4, clip 0.1) from zero
    # corrections with a small initial spread (log std -2: 0.04 flap units at scale 0.3).
    "residual_ppo": {
        "algo": "ppo",
        "total_timesteps": 3_000_000,
        "num_envs": 64,
        "vec_normalize": {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0, "clip_reward": 10.0},
        "algo_kwargs": {
            "learning_rate": 0.0001,
            "n_steps": 128,
            "batch_size": 2048,
            "n_epochs": 5,
            "gamma": 0.995,
            "gae_lambda": 0.95,
            "clip_range": 0.1,
            "ent_coef": 0.0,
            "max_grad_norm": 0.5,
        },
        "policy_kwargs": {"net_arch": {"pi": [128, 128], "vf": [128, 128]}, "activation_fn": "tanh", "log_std_init": -2.0},
        "zero_action_init": True,
    },
    # Residual SAC on the LQR: the recipe of training/sac.json from zero corrections (the actor's
    # mean layer zero, its log std constant at -2 until learned), on 16 envs (tuned:
    # training/residual_sac_tuning.json).
    "residual_sac": {
        "algo": "sac",
        "total_timesteps": 500_000,
        "num_envs": 16,
        "vec_normalize": {"norm_obs": True, "norm_reward": False, "clip_obs": 10.0},
        "algo_kwargs": {
            "learning_rate": 0.0003,
            "buffer_size": 300000,
            "batch_size": 256,
            "learning_starts": 2000,
            "train_freq": 1,
            "gradient_steps": 2,
            "gamma": 0.995,
            "tau": 0.005,
        },
        "policy_kwargs": {"net_arch": [256, 256], "activation_fn": "relu", "log_std_init": -2.0},
        "zero_action_init": True,
    },
}

#: The residual control of the residual recipes (:mod:`accd_gym.envs.residual`).
RESIDUAL: dict[str, Any] = {"base": "lqr", "scale": 0.3, "observe_base": True}
#: The observation history of the residual recipes on tiers with sensors (:mod:`accd_gym.envs.history`).
SENSOR_HISTORY = 4


def agent_env(tier: str) -> dict[str, Any]:
    """The env options of the residual recipes on ``tier``: residual control on the LQR, and the
    history of :data:`SENSOR_HISTORY` steps where the tier has sensors (delayed, held and
    dropped measurements: the past says what one observation cannot)."""
    has_sensors = bool(TIERS[tier].overrides.get("sensors", {}).get("enabled", False))
    return {"residual": dict(RESIDUAL), **({"history": SENSOR_HISTORY} if has_sensors else {})}


def zoo_hyperparams(algo: str) -> dict[str, dict[str, Any]]:
    """rl-zoo3's ``hyperparams`` of recipe ``algo`` (``"ppo"``, ``"sac"``, ``"residual_ppo"``,
    ``"residual_sac"``): one entry per registered id (the residual ones with the tier's
    ``env_kwargs``, :func:`agent_env`, and the callback zeroing the initial correction).

    ``policy_kwargs`` is given as the text rl-zoo3 evaluates (with ``nn`` = ``torch.nn``), so
    this module imports no torch.
    """
    recipe = RECIPES[algo]
    residual = recipe.get("zero_action_init", False)
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
    if not residual:
        return {t.id: dict(entry) for t in TIERS.values()}
    entry["callback"] = "accd_gym.learning.callbacks.ZeroActionInit"
    return {t.id: dict(entry, env_kwargs=agent_env(t.name)) for t in TIERS.values()}


__all__ = ["RECIPES", "RESIDUAL", "SENSOR_HISTORY", "agent_env", "zoo_hyperparams"]
