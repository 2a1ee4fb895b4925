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
update_threads     PPO: threads PyTorch uses in the gradient updates, when the envs are idle
                   (0, the default: ``torch_threads``). 2 on an idle 2-core machine: 5-8 % faster
                   end to end; with another process on one of the cores, 2.5x slower updates
                   (PyTorch's threads wait for each other), so only for dedicated machines. A
                   fixed number, never "per core": the trained policy can depend on it (on an
                   AMD EPYC, 1 and 2 give the same bits, 3 and 4 others; BENCHMARKS.md)
seed               seed of the env (training wake seeds only) and of the algorithm (default 0)
env                environment config overrides (see :mod:`accd_gym.config`) and the env options
                   ``residual`` and ``history`` (:mod:`accd_gym.agent_io`)
vec_normalize      ``VecNormalize`` options: ``norm_obs``, ``norm_reward`` (PPO; false for SAC),
                   ``clip_obs``, ``clip_reward``
algo_kwargs        keyword arguments of ``PPO``/``SAC`` (``learning_rate``, ``n_steps``, ``gamma``...)
policy_kwargs      ``net_arch`` (list of ints, or dict ``pi``/``vf``/``qf``), ``activation_fn``
                   (``"tanh"``/``"relu"``), ``log_std_init``
zero_action_init   true: the policy's last action layer starts at zero
                   (:class:`accd_gym.callbacks.ZeroActionInit`; PPO: ``action_net``, SAC: the
                   actor's mean, and its log-std layer constant at ``policy_kwargs.log_std_init``
                   when given), so that the deterministic policy starts with zero actions: with
                   ``env.residual`` it starts as the base controller, bit for bit (default false)
checkpoint_every   environment steps between checkpoints (model + VecNormalize statistics)
device             PyTorch device (default ``"cpu"``: the networks are small)
================== ================================================================================

Outputs in ``out``: ``final_model.zip``, ``vecnormalize.pkl``, ``run.json`` (the full config,
timing and steps per second, ``status``), ``checkpoints/`` and ``tb/`` (TensorBoard: SB3's
losses, episode returns, and ``accd/capture_rate`` etc. over the episodes that ended in each
rollout).

Interruption: SIGINT (Ctrl+C) or SIGTERM writes a checkpoint (model, VecNormalize statistics,
the envs' exact state, SAC's replay buffer) to ``checkpoints/`` and marks ``run.json``
``"status": "interrupted"``; ``accd-gym train --resume OUT`` (:func:`resume`) continues from the
latest checkpoint to the same total with the same config. ``accd-gym evaluate OUT`` of an
unfinished run evaluates its latest checkpoint and says so.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import signal
import threading
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
    "update_threads": 0,
    "seed": 0,
    "env": {},
    "vec_normalize": {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0, "clip_reward": 10.0},
    "algo_kwargs": {},
    "policy_kwargs": {},
    "checkpoint_every": 100_000,
    "device": "cpu",
    "zero_action_init": False,
}
_ALGOS = ("ppo", "sac")
_ACTIVATIONS = ("tanh", "relu", "elu")


def load_config(path: str | Path, **overrides: Any) -> dict[str, Any]:
    """A complete, validated training config from a JSON file plus overrides (None values ignored)."""
    from accd_gym.config import read_json_object

    raw = read_json_object(path, "training config")
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
    for key, low, high in (("total_timesteps", 1, 10**12), ("num_envs", 1, 65_536), ("num_threads", 0, 1024),
                           ("torch_threads", 1, 1024), ("update_threads", 0, 1024), ("checkpoint_every", 1, 10**12), ("seed", 0, 2**64 - 1)):
        v = cfg[key]
        if not isinstance(v, int) or isinstance(v, bool) or not low <= v <= high:
            raise ConfigError(f"invalid config: `{key}` = {v!r} is outside the allowed range: an integer in [{low}, {high}]")
    if cfg["algo"] != "ppo" and cfg["update_threads"] != 0:
        raise ConfigError(f"invalid config: `update_threads` = {cfg['update_threads']} is outside the allowed range "
                          f"for algo {cfg['algo']!r}: 0 (it applies to PPO's gradient updates only)")
    for key in ("env", "vec_normalize", "algo_kwargs", "policy_kwargs"):
        if not isinstance(cfg[key], dict):
            raise ConfigError(f"invalid config: `{key}` = {cfg[key]!r} is outside the allowed range: a JSON object")
    if not isinstance(cfg["zero_action_init"], bool):
        raise ConfigError(f"invalid config: `zero_action_init` = {cfg['zero_action_init']!r} is outside the allowed "
                          "range: true or false")
    if not isinstance(cfg["device"], str):
        raise ConfigError(f"invalid config: `device` = {cfg['device']!r} is outside the allowed range: a device name such as 'cpu'")
    _check_algo_kwargs(cfg["algo"], cfg["algo_kwargs"])
    bad_policy = set(cfg["policy_kwargs"]) - {"net_arch", "activation_fn", "log_std_init"}
    if bad_policy:
        raise ConfigError(f"invalid config: policy_kwargs key(s) {sorted(bad_policy)} outside the allowed set "
                          "['activation_fn', 'log_std_init', 'net_arch']")
    vn = dict(DEFAULTS["vec_normalize"], **cfg["vec_normalize"])
    bad = set(vn) - set(DEFAULTS["vec_normalize"])
    if bad:
        raise ConfigError(f"invalid config: vec_normalize key(s) {sorted(bad)} outside the allowed set {sorted(DEFAULTS['vec_normalize'])}")
    if cfg["algo"] == "sac" and "norm_reward" not in cfg["vec_normalize"]:
        vn["norm_reward"] = False
    cfg["vec_normalize"] = vn
    _check_net_arch(cfg["policy_kwargs"])
    act = cfg["policy_kwargs"].get("activation_fn")
    if act is not None and act not in _ACTIVATIONS:
        raise ConfigError(f"invalid config: `policy_kwargs.activation_fn` = {act!r} is outside the allowed range {list(_ACTIVATIONS)}")
    check_training_env(cfg["env"])
    return cfg


def _check_net_arch(policy_kwargs: dict[str, Any]) -> None:
    """ConfigError for a ``net_arch`` that is not a list of layer widths (or a dict of such lists
    under ``pi``/``vf``/``qf``), or a ``log_std_init`` that is not a finite number."""

    def widths(value: Any) -> bool:
        return isinstance(value, list) and all(isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= 65_536
                                               for w in value)

    arch = policy_kwargs.get("net_arch")
    if arch is not None and not widths(arch) and not (
            isinstance(arch, dict) and arch and set(arch) <= {"pi", "vf", "qf"} and all(widths(v) for v in arch.values())):
        raise ConfigError(f"invalid config: `policy_kwargs.net_arch` = {arch!r} is outside the allowed range: a list of "
                          "layer widths (integers in [1, 65536]) or a dict of such lists under 'pi', 'vf', 'qf'")
    std = policy_kwargs.get("log_std_init")
    if std is not None and (not isinstance(std, (int, float)) or isinstance(std, bool) or not math.isfinite(std)):
        raise ConfigError(f"invalid config: `policy_kwargs.log_std_init` = {std!r} is outside the allowed range: a finite number")


def check_training_env(env: dict[str, Any]) -> None:
    """ConfigError for a bad env override (or env option, :mod:`accd_gym.agent_io`) or one that
    fixes a held-out wake seed (training may only draw training wake seeds); shared by every
    trainer."""
    from accd_gym.agent_io import split_agent_options
    from accd_gym.config import env_config

    _, physics = split_agent_options(env)  # raises ConfigError naming a bad residual/history option
    full = env_config(physics)  # raises ConfigError naming the bad env field
    from accd_gym.task import HELD_OUT_WAKE_SEEDS

    fixed = ([full["wake_seed"]] if full["wake_seed"] is not None else []) + list(full["wake_seeds"] or [])
    leaked = sorted({s for s in fixed if s in HELD_OUT_WAKE_SEEDS})
    if leaked:
        raise ConfigError(
            f"invalid config: `env.wake_seed(s)` = {leaked[:5]} is outside the allowed range: training may not use "
            f"held-out wake seeds [{HELD_OUT_WAKE_SEEDS.start}, {HELD_OUT_WAKE_SEEDS.stop})"
        )


#: Keyword arguments of the algorithms that the training pipeline sets itself.
_RESERVED_ALGO_KWARGS = ("policy", "env", "seed", "device", "tensorboard_log", "policy_kwargs", "verbose", "_init_setup_model")


def _check_algo_kwargs(algo: str, kwargs: dict[str, Any]) -> None:
    """ConfigError for a key of ``algo_kwargs`` that PPO/SAC does not take (or that is set by the
    pipeline), naming the allowed keys."""
    import inspect

    try:
        from stable_baselines3 import PPO, SAC
    except ImportError:  # without the sb3 extra the keys cannot be checked here; training needs it anyway
        return
    params = inspect.signature({"ppo": PPO, "sac": SAC}[algo].__init__).parameters
    allowed = sorted(set(params) - {"self", *_RESERVED_ALGO_KWARGS})
    bad = sorted(set(kwargs) - set(allowed))
    if bad:
        raise ConfigError(f"invalid config: algo_kwargs key(s) {bad} outside the allowed set for {algo.upper()}: {allowed}")


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


def _thread_split(collection: int, updates: int):
    """A callback giving PyTorch ``updates`` threads for PPO's gradient updates and ``collection``
    threads while the envs step (the env pool then has the cores; an idle PyTorch worker thread
    spinning beside it halves the env's speed); None when ``updates`` is 0 or ``collection``
    (one count throughout)."""
    if updates in (0, collection):
        return None
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    class ThreadSplit(BaseCallback):
        """Sets PyTorch's thread count at each rollout's start and end."""

        def _on_rollout_start(self) -> None:
            torch.set_num_threads(collection)

        def _on_rollout_end(self) -> None:
            torch.set_num_threads(updates)

        def _on_training_end(self) -> None:
            torch.set_num_threads(collection)

        def _on_step(self) -> bool:
            return True

    return ThreadSplit()


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


class _StopRequest:
    """SIGINT and SIGTERM during training, turned into a request to stop at the next env step.

    Raising ``KeyboardInterrupt`` from the handler could cut an optimizer step in half (Adam's
    state half initialised: a checkpoint written then cannot be resumed), so the first signal only
    sets :attr:`signal_name`; :meth:`callback` makes ``learn`` return at the next env step, after
    the gradient update under way. A second signal raises ``KeyboardInterrupt`` at once (no new
    checkpoint: the run keeps its periodic ones).
    """

    def __init__(self) -> None:
        self.signal_name: Optional[str] = None

    def handler(self, signum: int, frame: Any) -> None:
        """The signal handler: remember the first signal, raise on the second."""
        name = signal.Signals(signum).name
        if self.signal_name is not None:
            raise KeyboardInterrupt(f"signal {name} (second)")
        self.signal_name = f"signal {name}"

    def installed(self):
        """While active (main thread only), SIGINT and SIGTERM request the stop."""
        return _signal_handlers(self.handler)

    def callback(self):
        """An SB3 callback that stops ``learn`` once a stop was requested."""
        from stable_baselines3.common.callbacks import BaseCallback

        request = self

        class StopOnSignal(BaseCallback):
            """Returns False from ``_on_step`` after SIGINT or SIGTERM."""

            def _on_step(self) -> bool:
                return request.signal_name is None

        return StopOnSignal()


@contextlib.contextmanager
def _signal_handlers(handler: Any):
    """While active (main thread only; elsewhere Python delivers no signals), ``handler`` takes
    SIGINT and SIGTERM; the previous handlers come back on exit."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def _signals_deferred():
    """While active, SIGINT and SIGTERM are held back, so that a checkpoint being written is not
    cut short; a signal that arrived meanwhile is ignored."""
    return _signal_handlers(signal.SIG_IGN)


def _prefix(cfg: dict[str, Any]) -> str:
    """File-name prefix of a run's checkpoints (as CheckpointCallback names them)."""
    return f"{cfg['algo']}_accd"


def _base_env(env: Any) -> Any:
    """The AccdVecEnv under the VecMonitor and VecNormalize wrappers."""
    while hasattr(env, "venv"):
        env = env.venv
    return env


def latest_checkpoint(run: str | Path) -> Optional[dict[str, Any]]:
    """The newest checkpoint of a run folder: ``{"steps", "model", "vecnormalize", "env_state",
    "replay_buffer"}`` (paths; the last two None when absent), or None without checkpoints."""
    folder = Path(run) / "checkpoints"
    best: Optional[tuple[int, Path]] = None
    for p in folder.glob("*_steps.zip"):
        m = re.fullmatch(r"(.+)_(\d+)_steps", p.stem)
        if m and (best is None or int(m.group(2)) > best[0]):
            best = (int(m.group(2)), p)
    if best is None:
        return None
    steps, model = best
    prefix = model.stem[: -len(f"_{steps}_steps")]

    def beside(kind: str, ext: str) -> Optional[Path]:
        q = folder / f"{prefix}_{kind}_{steps}_steps.{ext}"
        return q if q.is_file() else None

    return {
        "steps": steps,
        "model": model,
        "vecnormalize": beside("vecnormalize", "pkl"),
        "env_state": beside("envstate", "bin"),
        "replay_buffer": beside("replay_buffer", "pkl"),
    }


def _save_checkpoint(model: Any, env: Any, cfg: dict[str, Any], out: Path) -> dict[str, Any]:
    """Writes the model, the VecNormalize statistics, the envs' exact state and (SAC) the replay
    buffer as a checkpoint named like CheckpointCallback's; returns :func:`latest_checkpoint`'s
    record of it."""
    folder = out / "checkpoints"
    folder.mkdir(parents=True, exist_ok=True)
    steps = int(model.num_timesteps)
    stem = f"{_prefix(cfg)}_{{}}{steps}_steps"
    model.save(str(folder / (stem.format("") + ".zip")))
    env.save(str(folder / (stem.format("vecnormalize_") + ".pkl")))
    (folder / (stem.format("envstate_") + ".bin")).write_bytes(_base_env(env).get_state())
    if hasattr(model, "save_replay_buffer") and cfg["algo"] == "sac":
        model.save_replay_buffer(str(folder / (stem.format("replay_buffer_") + ".pkl")))
    record = latest_checkpoint(out)
    assert record is not None and record["steps"] == steps
    return record


def _write_meta(out: Path, meta: dict[str, Any]) -> None:
    """Writes run.json atomically (a crash never leaves half a file)."""
    tmp = out / "run.json.tmp"
    tmp.write_text(json.dumps(meta, indent=1, default=str))
    os.replace(tmp, out / "run.json")


def train(
    config: dict[str, Any],
    out: str | Path,
    *,
    timesteps: Optional[int] = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Trains per ``config`` (from :func:`load_config`); writes the model, statistics and logs to ``out``.

    Returns the run summary (also ``out/run.json``): config, steps, wall time, steps per second,
    and ``status``: ``"done"``, or ``"interrupted"`` when SIGINT (Ctrl+C) or SIGTERM stopped the
    training. An interrupted run has written a checkpoint (model, VecNormalize statistics, the
    envs' state; SAC: the replay buffer) to ``out/checkpoints`` and continues with
    :func:`resume` (``accd-gym train --resume OUT``) to the same total.
    """
    import torch
    from stable_baselines3 import PPO, SAC

    cfg = validate_config(dict(config))
    if timesteps is not None:
        if timesteps < 1:
            raise ConfigError(f"invalid config: `timesteps` = {timesteps} is outside the allowed range >= 1")
        cfg["total_timesteps"] = int(timesteps)
    out = _writable_folder(out)
    torch.set_num_threads(cfg["torch_threads"])
    _one_blas_thread()
    env = make_training_env(cfg)
    cls = {"ppo": PPO, "sac": SAC}[cfg["algo"]]
    try:
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
    except (TypeError, ValueError, AssertionError, RuntimeError) as e:
        # a value of the right key that stable-baselines3 or torch cannot use (a string learning
        # rate, a batch size the rollout cannot fill, an unknown device, ...)
        raise ConfigError(f"invalid config: {cfg['algo'].upper()} refused the config's algo_kwargs "
                          f"{cfg['algo_kwargs']!r} / policy_kwargs {cfg['policy_kwargs']!r} / device "
                          f"{cfg['device']!r}: {type(e).__name__}: {e}") from e
    meta = {"algo": cfg["algo"], "config": cfg, "status": "training", "total_timesteps": cfg["total_timesteps"]}
    _write_meta(out, meta)
    return _learn(model, env, cfg, out, meta, progress=progress, fresh=True)


def _one_blas_thread() -> None:
    """numpy's BLAS on one thread for the training process (threadpoolctl, when installed): its
    only users are small products (the LQR base controller of residual control, VecNormalize),
    and its idle threads spin beside the env's stepping threads."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    threadpool_limits(1, user_api="blas")


def _zero_action_init(cfg: dict[str, Any]):
    """The callback zeroing the last action layer at the start (``zero_action_init``), or None."""
    if not cfg["zero_action_init"]:
        return None
    from accd_gym.callbacks import ZeroActionInit

    return ZeroActionInit()


def resume(run: str | Path, *, progress: bool = True) -> dict[str, Any]:
    """Continues an interrupted run (or one killed while training) from its latest checkpoint to
    the total of its config, with the same config and seeds (the envs continue from their saved
    state; SAC's replay buffer is restored when it was saved). Returns the run summary.

    Raises ConfigError when ``run`` is not a run folder, has finished, or has no checkpoint.
    """
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.vec_env import VecNormalize

    out = Path(run)
    meta_path = out / "run.json"
    if not meta_path.is_file():
        raise ConfigError(f"invalid config: --resume {str(run)!r} is not a run folder (no run.json)")
    try:
        meta = json.loads(meta_path.read_text())
        cfg = validate_config(meta["config"])
    except (json.JSONDecodeError, KeyError, TypeError) as e:
        raise ConfigError(f"invalid config: {str(meta_path)!r} is not a run summary ({e})") from None
    if meta.get("status") == "done":
        raise ConfigError(f"invalid config: run {str(run)!r} is complete ({meta.get('timesteps')} steps); nothing to resume")
    ckpt = latest_checkpoint(out)
    if ckpt is None:
        raise ConfigError(f"invalid config: run {str(run)!r} has no checkpoint in {str(out / 'checkpoints')!r} to resume from")
    if ckpt["vecnormalize"] is None:
        raise ConfigError(f"invalid config: checkpoint {str(ckpt['model'])!r} has no VecNormalize statistics beside it")
    torch.set_num_threads(cfg["torch_threads"])
    _one_blas_thread()
    from stable_baselines3.common.vec_env import VecMonitor

    from accd_gym.sb3 import AccdVecEnv

    base = AccdVecEnv(num_envs=cfg["num_envs"], seed=cfg["seed"], num_threads=cfg["num_threads"], **cfg["env"])
    if ckpt["env_state"] is not None:
        base.set_state(ckpt["env_state"].read_bytes())
        base._base_seed = None  # continue the saved episode sequence instead of reseeding
    env = VecNormalize.load(str(ckpt["vecnormalize"]), VecMonitor(base, info_keywords=("captured",)))
    env.training = True
    cls = {"ppo": PPO, "sac": SAC}[cfg["algo"]]
    model = cls.load(str(ckpt["model"]), env=env, device=cfg["device"], tensorboard_log=str(out / "tb"))
    if ckpt["replay_buffer"] is not None and hasattr(model, "load_replay_buffer"):
        model.load_replay_buffer(str(ckpt["replay_buffer"]))
    meta.setdefault("resumed", []).append({"from_steps": ckpt["steps"], "checkpoint": str(ckpt["model"])})
    meta["status"] = "training"
    _write_meta(out, meta)
    return _learn(model, env, cfg, out, meta, progress=progress, fresh=False)


def _learn(model: Any, env: Any, cfg: dict[str, Any], out: Path, meta: dict[str, Any], *, progress: bool,
           fresh: bool) -> dict[str, Any]:
    """Runs ``model.learn`` to the config's total with checkpoints; on SIGINT/SIGTERM writes a
    checkpoint and marks the run interrupted, else writes the final model. Returns ``meta``."""
    import torch
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    checkpoints = CheckpointCallback(
        save_freq=max(1, cfg["checkpoint_every"] // cfg["num_envs"]),
        save_path=str(out / "checkpoints"),
        name_prefix=_prefix(cfg),
        save_vecnormalize=True,
    )
    remaining = cfg["total_timesteps"] - (0 if fresh else int(model.num_timesteps))
    t0 = time.time()
    start_steps = 0 if fresh else int(model.num_timesteps)
    stop = _StopRequest()
    callbacks = [checkpoints, _capture_callback(), stop.callback()]
    init = _zero_action_init(cfg) if fresh else None
    if init is not None:
        callbacks.insert(0, init)
    split = _thread_split(cfg["torch_threads"], cfg["update_threads"])  # PPO only: validate_config
    if split is not None:
        callbacks.append(split)
    try:
        with stop.installed():
            if remaining > 0:
                model.learn(
                    total_timesteps=remaining,
                    callback=CallbackList(callbacks),
                    progress_bar=progress,
                    tb_log_name=cfg["algo"],
                    reset_num_timesteps=fresh,
                )
    except KeyboardInterrupt as e:
        # A second signal (or Ctrl+C outside the handler's reach): the model may be mid-update,
        # so no checkpoint of it is written; the run is marked and keeps its periodic ones.
        with _signals_deferred():
            meta.update(status="interrupted", interrupted_by=str(e) or "SIGINT", timesteps=int(model.num_timesteps))
            _write_meta(out, meta)
        env.close()
        raise
    interrupted = stop.signal_name
    wall = time.time() - t0
    with _signals_deferred():
        done = int(model.num_timesteps)
        meta.update(
            timesteps=done,
            wall_time_s=round(meta.get("wall_time_s", 0.0) + wall, 1),
            steps_per_s=round((done - start_steps) / wall, 1) if wall > 0 else None,
            torch_version=torch.__version__,
        )
        if interrupted is not None:
            ckpt = _save_checkpoint(model, env, cfg, out)
            meta.update(status="interrupted", interrupted_by=interrupted, checkpoint=str(ckpt["model"]),
                        vecnormalize=str(ckpt["vecnormalize"]))
        else:
            model.save(str(out / "final_model.zip"))
            env.save(str(out / "vecnormalize.pkl"))
            meta.update(status="done")
            for key in ("checkpoint", "vecnormalize", "interrupted_by"):
                meta.pop(key, None)
        _write_meta(out, meta)
    env.close()
    return meta


def _writable_folder(out: str | Path) -> Path:
    """``out`` created if needed; ConfigError naming it when it cannot be created or written."""
    p = Path(out)
    try:
        p.mkdir(parents=True, exist_ok=True)
        probe = p / ".accd-write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise ConfigError(f"invalid config: --out {str(out)!r} is not a writable folder ({e.strerror or e})") from None
    return p


__all__ = ["DEFAULTS", "latest_checkpoint", "load_config", "make_training_env", "resume", "train", "validate_config"]
