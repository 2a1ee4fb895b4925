"""Training with stable-baselines3 (PPO by default, or SAC) on :class:`accd_gym.AccdVecEnv`.

``accd-gym train --config training/ppo.json --out runs/NAME [--timesteps N]`` calls
:func:`train`. A training config is a JSON object (see ``training/*.json``); every key is optional:

================== ================================================================================
key                meaning
================== ================================================================================
algo               ``"ppo"`` (default) or ``"sac"``
total_timesteps    environment steps (all envs together); ``--timesteps`` overrides it
num_envs           parallel episodes in the AccdVecEnv (default 16)
num_threads        threads stepping the envs (0: one per core)
torch_threads      threads PyTorch uses (default 1: leaves the cores to the physics)
seed               seed of the env (training wake seeds only) and of the algorithm (default 0)
env                environment config overrides (see :mod:`accd_gym.config`)
vec_normalize      ``VecNormalize`` options: ``norm_obs``, ``norm_reward`` (PPO; false for SAC),
                   ``clip_obs``, ``clip_reward``
algo_kwargs        keyword arguments of ``PPO``/``SAC`` (``learning_rate``, ``n_steps``, ``gamma``...)
policy_kwargs      ``net_arch`` (list of ints, or dict ``pi``/``vf``/``qf``), ``activation_fn``
                   (``"tanh"``/``"relu"``), ``log_std_init``
checkpoint_every   environment steps between checkpoints (model + VecNormalize statistics)
device             PyTorch device (default ``"cpu"``: the networks are small)
================== ================================================================================

Outputs in ``out``: ``final_model.zip``, ``vecnormalize.pkl``, ``run.json`` (the full config,
timing and steps per second), ``checkpoints/`` and ``tb/`` (TensorBoard: SB3's losses, episode
returns, and ``accd/capture_rate`` etc. over the episodes that ended in each rollout).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Optional

import numpy as np

from accd_gym.errors import ConfigError

#: Defaults of a training config (``algo_kwargs`` are per algorithm).
DEFAULTS: dict[str, Any] = {
    "algo": "ppo",
    "total_timesteps": 1_000_000,
    "num_envs": 16,
    "num_threads": 0,
    "torch_threads": 1,
    "seed": 0,
    "env": {},
    "vec_normalize": {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0, "clip_reward": 10.0},
    "algo_kwargs": {},
    "policy_kwargs": {},
    "checkpoint_every": 100_000,
    "device": "cpu",
}
_ALGOS = ("ppo", "sac")
_ACTIVATIONS = ("tanh", "relu", "elu")


def load_config(path: str | Path, **overrides: Any) -> dict[str, Any]:
    """A complete, validated training config from a JSON file plus overrides (None values ignored)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"invalid config: training config file {str(path)!r} does not exist")
    try:
        raw = json.loads(p.read_text())
    except json.JSONDecodeError as e:
        raise ConfigError(f"invalid config: {str(path)!r} is not valid JSON ({e})") from None
    raw.update({k: v for k, v in overrides.items() if v is not None})
    return validate_config(raw)


def validate_config(raw: dict[str, Any]) -> dict[str, Any]:
    """Fills in defaults and checks every field; ConfigError names the field, value and allowed range."""
    if not isinstance(raw, dict):
        raise ConfigError(f"invalid config: a training config must be a JSON object, got {type(raw).__name__}")
    unknown = set(raw) - set(DEFAULTS) - {"description"}
    if unknown:
        raise ConfigError(f"invalid config: training config key(s) {sorted(unknown)} outside the allowed set {sorted(DEFAULTS)}")
    cfg = json.loads(json.dumps(DEFAULTS))
    cfg.update(raw)
    if cfg["algo"] not in _ALGOS:
        raise ConfigError(f"invalid config: `algo` = {cfg['algo']!r} is outside the allowed range {list(_ALGOS)}")
    for key, low in (("total_timesteps", 1), ("num_envs", 1), ("num_threads", 0), ("torch_threads", 1), ("checkpoint_every", 1)):
        v = cfg[key]
        if not isinstance(v, int) or isinstance(v, bool) or v < low:
            raise ConfigError(f"invalid config: `{key}` = {v!r} is outside the allowed range: an integer >= {low}")
    if not isinstance(cfg["seed"], int) or cfg["seed"] < 0:
        raise ConfigError(f"invalid config: `seed` = {cfg['seed']!r} is outside the allowed range: an integer >= 0")
    vn = dict(DEFAULTS["vec_normalize"], **cfg["vec_normalize"])
    bad = set(vn) - set(DEFAULTS["vec_normalize"])
    if bad:
        raise ConfigError(f"invalid config: vec_normalize key(s) {sorted(bad)} outside the allowed set {sorted(DEFAULTS['vec_normalize'])}")
    if cfg["algo"] == "sac" and "norm_reward" not in cfg["vec_normalize"]:
        vn["norm_reward"] = False
    cfg["vec_normalize"] = vn
    act = cfg["policy_kwargs"].get("activation_fn")
    if act is not None and act not in _ACTIVATIONS:
        raise ConfigError(f"invalid config: `policy_kwargs.activation_fn` = {act!r} is outside the allowed range {list(_ACTIVATIONS)}")
    from accd_gym.config import env_config

    full = env_config(cfg["env"])  # raises ConfigError naming the bad env field
    from accd_gym.task import HELD_OUT_WAKE_SEEDS

    fixed = ([full["wake_seed"]] if full["wake_seed"] is not None else []) + list(full["wake_seeds"] or [])
    leaked = sorted({s for s in fixed if s in HELD_OUT_WAKE_SEEDS})
    if leaked:
        raise ConfigError(
            f"invalid config: `env.wake_seed(s)` = {leaked[:5]} is outside the allowed range: training may not use "
            f"held-out wake seeds [{HELD_OUT_WAKE_SEEDS.start}, {HELD_OUT_WAKE_SEEDS.stop})"
        )
    return cfg


def _policy_kwargs(cfg: dict[str, Any]) -> dict[str, Any]:
    """policy_kwargs with the activation name turned into the torch class."""
    import torch

    kw = dict(cfg["policy_kwargs"])
    if "activation_fn" in kw:
        kw["activation_fn"] = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU}[kw["activation_fn"]]
    return kw


def make_training_env(cfg: dict[str, Any]):
    """The AccdVecEnv (training wake seeds) wrapped in VecMonitor and VecNormalize per the config."""
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from accd_gym.sb3 import AccdVecEnv

    env = AccdVecEnv(num_envs=cfg["num_envs"], seed=cfg["seed"], num_threads=cfg["num_threads"], **cfg["env"])
    env = VecMonitor(env, info_keywords=("captured",))
    gamma = cfg["algo_kwargs"].get("gamma", 0.99)
    return VecNormalize(env, gamma=gamma, **cfg["vec_normalize"])


def _capture_callback():
    """A callback logging capture rate, miss distance and failure rate of ended episodes to TensorBoard."""
    from stable_baselines3.common.callbacks import BaseCallback

    class CaptureStats(BaseCallback):
        """Counts the outcomes of episodes that end; logs ``accd/*`` at each rollout end."""

        def _on_training_start(self) -> None:
            self._reset()

        def _reset(self) -> None:
            self.n = self.captured = self.failed = 0
            self.final_distance: list[float] = []

        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"]):
                if done:
                    self.n += 1
                    self.captured += bool(info.get("captured"))
                    self.failed += bool(info.get("overload") or info.get("envelope_exit") or info.get("diverged"))
                    self.final_distance.append(float(info.get("distance", np.nan)))
            return True

        def _on_rollout_end(self) -> None:
            if self.n:
                self.logger.record("accd/capture_rate", self.captured / self.n)
                self.logger.record("accd/failure_rate", self.failed / self.n)
                self.logger.record("accd/final_distance_m", float(np.nanmedian(self.final_distance)))
                self.logger.record("accd/episodes", self.n)
                self._reset()

    return CaptureStats()


def train(
    config: dict[str, Any],
    out: str | Path,
    *,
    timesteps: Optional[int] = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Trains per ``config`` (from :func:`load_config`); writes the model, statistics and logs to ``out``.

    Returns the run summary (also ``out/run.json``): config, steps, wall time, steps per second.
    """
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    cfg = validate_config(dict(config))
    if timesteps is not None:
        if timesteps < 1:
            raise ConfigError(f"invalid config: `timesteps` = {timesteps} is outside the allowed range >= 1")
        cfg["total_timesteps"] = int(timesteps)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(cfg["torch_threads"])
    env = make_training_env(cfg)
    cls = {"ppo": PPO, "sac": SAC}[cfg["algo"]]
    model = cls(
        "MlpPolicy",
        env,
        seed=cfg["seed"],
        device=cfg["device"],
        tensorboard_log=str(out / "tb"),
        policy_kwargs=_policy_kwargs(cfg),
        verbose=0,
        **cfg["algo_kwargs"],
    )
    meta = {"algo": cfg["algo"], "config": cfg, "status": "training"}
    (out / "run.json").write_text(json.dumps(meta, indent=1))
    checkpoints = CheckpointCallback(
        save_freq=max(1, cfg["checkpoint_every"] // cfg["num_envs"]),
        save_path=str(out / "checkpoints"),
        name_prefix=f"{cfg['algo']}_accd",
        save_vecnormalize=True,
    )
    t0 = time.time()
    model.learn(
        total_timesteps=cfg["total_timesteps"],
        callback=CallbackList([checkpoints, _capture_callback()]),
        progress_bar=progress,
        tb_log_name=cfg["algo"],
    )
    wall = time.time() - t0
    model.save(str(out / "final_model.zip"))
    env.save(str(out / "vecnormalize.pkl"))
    meta.update(
        status="done",
        timesteps=int(model.num_timesteps),
        wall_time_s=round(wall, 1),
        steps_per_s=round(model.num_timesteps / wall, 1),
        torch_version=torch.__version__,
    )
    (out / "run.json").write_text(json.dumps(meta, indent=1))
    env.close()
    return meta


__all__ = ["DEFAULTS", "load_config", "make_training_env", "train", "validate_config"]
