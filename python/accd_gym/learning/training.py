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
                   (0, the default: ``torch_threads``). Faster on a dedicated machine, much
                   slower when another process shares the cores (PyTorch's threads wait for each
                   other; BENCHMARKS.md). A fixed number, never "per core": the trained policy's
                   last bits can depend on it.
seed               seed of the env (training wake seeds only) and of the algorithm (default 0)
env                environment config overrides (see :mod:`accd_gym.envs.config`) and the env options
                   ``residual`` and ``history`` (:mod:`accd_gym.envs.agent_io`)
vec_normalize      ``VecNormalize`` options: ``norm_obs``, ``norm_reward`` (PPO; false for SAC),
                   ``clip_obs``, ``clip_reward``
algo_kwargs        keyword arguments of ``PPO``/``SAC`` (``learning_rate``, ``n_steps``, ``gamma``...)
policy_kwargs      ``net_arch`` (list of ints, or dict ``pi``/``vf``/``qf``), ``activation_fn``
                   (``"tanh"``/``"relu"``), ``log_std_init``
zero_action_init   true: the policy's last action layer starts at zero
                   (:class:`accd_gym.learning.callbacks.ZeroActionInit`; PPO: ``action_net``, SAC: the
                   actor's mean, and its log-std layer constant at ``policy_kwargs.log_std_init``
                   when given), so that the deterministic policy starts with zero actions: with
                   ``env.residual`` it starts as the base controller, bit for bit (default false)
checkpoint_every   environment steps between checkpoints (model + VecNormalize statistics)
init_from          a run folder (``final_model.zip`` and ``vecnormalize.pkl``) of a PPO policy with
                   the same observation, e.g. a distilled student (:mod:`accd_gym.learning.distill`):
                   PPO starts from its policy's weights (but ``log_std``, which
                   ``policy_kwargs.log_std_init`` sets) and its observation statistics, which
                   then stay fixed (:class:`accd_gym.learning.callbacks.FrozenStatistics`; the
                   rewards are still normalised as configured): RL fine-tuning (default null:
                   a fresh policy). The run records a digest of that policy
                   (``run.json``'s ``init_from_digest``, :func:`start_digest`)
critic_warmup      with ``init_from``: environment steps at the start during which only the
                   critic learns, the actor frozen (:class:`accd_gym.learning.callbacks.CriticWarmup`;
                   default 0)
asymmetric_critic  PPO, true: the critic also reads the true observation (perfect sensors' 25
                   values), the actor only the agent's observation
                   (:mod:`accd_gym.learning.asymmetric`); the run is evaluated and exported on
                   the agent's observation like any other; with ``init_from`` the actor starts
                   from the saved policy and keeps its input scaling, the critic starts afresh
                   and learns the scaling of its extra inputs (default false)
device             PyTorch device (default ``"cpu"``: the networks are small)
================== ================================================================================

Outputs in ``out``: ``final_model.zip``, ``vecnormalize.pkl``, ``run.json`` (the full config,
timing and steps per second, ``status``), ``checkpoints/`` and ``tb/`` (TensorBoard: SB3's
losses, episode returns, and ``accd/capture_rate`` etc. over the episodes that ended in each
rollout).

Interruption: SIGINT (Ctrl+C) or SIGTERM writes a checkpoint (model, VecNormalize statistics,
the envs' exact state, SAC's replay buffer) to ``checkpoints/`` and marks ``run.json``
``"status": "interrupted"``; ``accd-gym train --resume OUT`` (:func:`resume`) continues from the
newest checkpoint that loads (saying which damaged ones it skipped) to the same total with the
same config. ``accd-gym evaluate OUT`` of an unfinished run evaluates its latest checkpoint and
says so.

Nothing saved is lost: every file is written atomically (:mod:`accd_gym.files`; a checkpoint's
model zip last, after its companions), so a crash or a full disk leaves the earlier checkpoints
and the previous run.json intact; a write that fails stops the training with an
:class:`~accd_gym.errors.OutputError` saying which checkpoint the run keeps. A full disk costs at
most one checkpoint interval: run.json is written after every checkpoint, naming it
(``checkpoint``, ``checkpoint_steps``), and the run folder keeps a small reserve file
(:func:`accd_gym.files.reserve_space`) that is freed so that run.json can still say
``"interrupted"`` when the disk is full; ``--resume`` continues from that checkpoint (a run
stopped before its first one starts over).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import math
import re
import signal
import threading
import time
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from accd_gym import files
from accd_gym.envs.task import SEED_END
from accd_gym.errors import ConfigError, OutputError, StateError
from accd_gym.envs.config import env_config, read_json_object
from accd_gym.envs.agent_io import split_agent_options
from accd_gym.envs.task import ACT_DIM, HELD_OUT_WAKE_SEEDS, OBS_DIM

#: The files a run folder gets beside ``checkpoints/`` and ``tb/`` (checked before a training starts).
RUN_FILES = ("run.json", "final_model.zip", "vecnormalize.pkl")

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
#: Optional keys of a training config that have no default value (absent: off), so that the
#: configs of runs made before them validate to the same dict.
OPTIONAL_KEYS = ("init_from", "critic_warmup", "asymmetric_critic")
_ALGOS = ("ppo", "sac")
_ACTIVATIONS = ("tanh", "relu", "elu")


def load_config(path: str | Path, **overrides: Any) -> dict[str, Any]:
    """A complete, validated training config from a JSON file plus overrides (None values ignored)."""
    raw = read_json_object(path, "training config")
    raw.update({k: v for k, v in overrides.items() if v is not None})
    return validate_config(raw)


def validate_config(raw: dict[str, Any]) -> dict[str, Any]:
    """Fills in defaults and checks every field; ConfigError names the field, value and allowed range."""
    if not isinstance(raw, dict):
        raise ConfigError(f"invalid config: a training config must be a JSON object, got {type(raw).__name__}")
    unknown = set(raw) - set(DEFAULTS) - set(OPTIONAL_KEYS) - {"description"}
    if unknown:
        raise ConfigError(f"invalid config: training config key(s) {sorted(unknown)} outside the allowed set "
                          f"{sorted([*DEFAULTS, *OPTIONAL_KEYS])}")
    cfg = json.loads(json.dumps(DEFAULTS))
    cfg.update(raw)
    if cfg["algo"] not in _ALGOS:
        raise ConfigError(f"invalid config: `algo` = {cfg['algo']!r} is outside the allowed range {list(_ALGOS)}")
    for key, low, high in (("total_timesteps", 1, 10**12), ("num_envs", 1, 65_536), ("num_threads", 0, 1024),
                           ("torch_threads", 1, 1024), ("update_threads", 0, 1024), ("checkpoint_every", 1, 10**12), ("seed", 0, SEED_END - 1)):
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
    _check_asymmetric(cfg)
    _check_init_from(cfg)
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


def _check_asymmetric(cfg: dict[str, Any]) -> None:
    """ConfigError for an ``asymmetric_critic`` that is not a bool, or true with another algorithm
    than PPO or with the env option ``true_observation`` set by hand; a false one is dropped (the
    config then validates to the same dict as before the key existed)."""
    value = cfg.get("asymmetric_critic")
    if value is None or value is False:
        cfg.pop("asymmetric_critic", None)
        return
    if value is not True:
        raise ConfigError(f"invalid config: `asymmetric_critic` = {value!r} is outside the allowed range: true or false")
    if cfg["algo"] != "ppo":
        raise ConfigError(f"invalid config: `asymmetric_critic` = true is outside the allowed range for algo "
                          f"{cfg['algo']!r}: PPO only")
    if isinstance(cfg["env"], dict) and "true_observation" in cfg["env"]:
        raise ConfigError("invalid config: `env.true_observation` is set by `asymmetric_critic` (the critic's input); "
                          "drop it from env")


def _check_init_from(cfg: dict[str, Any]) -> None:
    """ConfigError for an ``init_from`` that is not a PPO run folder with its final model and
    statistics, or that is combined with SAC or ``zero_action_init``."""
    warmup = cfg.get("critic_warmup")
    if warmup is not None and (not isinstance(warmup, int) or isinstance(warmup, bool) or not 0 <= warmup <= 10**12
                               or (warmup > 0 and cfg.get("init_from") is None)):
        raise ConfigError(f"invalid config: `critic_warmup` = {warmup!r} is outside the allowed range: an integer in "
                          "[0, 10^12], above 0 only with `init_from` (the critic of a policy started from another's "
                          "weights)")
    if not warmup:
        cfg.pop("critic_warmup", None)
    src = cfg.get("init_from")
    if src is None:
        cfg.pop("init_from", None)
        return
    if not isinstance(src, str) or not src:
        raise ConfigError(f"invalid config: `init_from` = {src!r} is outside the allowed range: null or a run folder")
    if cfg["algo"] != "ppo" or cfg["zero_action_init"]:
        raise ConfigError(f"invalid config: `init_from` = {src!r} is outside the allowed range for algo {cfg['algo']!r} "
                          f"with zero_action_init {cfg['zero_action_init']}: it starts PPO (without zero_action_init) "
                          "from a PPO policy")
    folder = Path(src)
    for name in ("final_model.zip", "vecnormalize.pkl"):
        if not (folder / name).is_file():
            raise ConfigError(f"invalid config: `init_from` = {src!r} is not a finished run folder: no {name} in it")


def actor_dim(cfg: dict[str, Any]) -> int:
    """The size of the observation the policy acts on (the env's with the config's agent options:
    history, the residual base's command); with ``asymmetric_critic`` the critic reads
    :data:`accd_gym.learning.asymmetric.TRUE_DIM` more."""
    options, _ = split_agent_options(cfg["env"])
    return int(options.observation_space().shape[0])


def start_digest(folder: str | Path) -> Optional[str]:
    """SHA-256 of the policy a fine-tuning starts from (``init_from``): its ``final_model.zip`` and
    ``vecnormalize.pkl``, or None where either is missing. A fine-tuned run records it
    (``run.json``'s ``init_from_digest``), so that a run started from a student that has since
    been trained again is told apart from one started from the student there now."""
    digest = hashlib.sha256()
    for name in ("final_model.zip", "vecnormalize.pkl"):
        try:
            data = (Path(folder) / name).read_bytes()
        except OSError:
            return None
        digest.update(name.encode() + b"\0" + len(data).to_bytes(8, "little") + data)
    return digest.hexdigest()


def _init_from(model: Any, env: Any, cfg: dict[str, Any]) -> None:
    """Starts ``model`` (PPO) from the policy and the observation statistics of the run folder
    ``init_from``; its ``log_std`` stays the config's. ConfigError when the shapes differ (a
    policy of another observation or network). With ``asymmetric_critic`` the actor starts from
    the saved policy's and the critic afresh (it reads other inputs), and the statistics of the
    critic's extra inputs are learned while the actor's stay the saved policy's."""
    src = Path(cfg["init_from"])
    obs_dim = actor_dim(cfg)
    asymmetric = bool(cfg.get("asymmetric_critic"))
    stats = load_statistics((src / "vecnormalize.pkl").read_bytes(), str(src / "vecnormalize.pkl"), obs_dim=obs_dim)
    saved = load_model((src / "final_model.zip").read_bytes(), str(src / "final_model.zip"), "ppo", obs_dim,
                       device=cfg["device"])
    own = model.policy.state_dict()
    critic = ("mlp_extractor.value_net.", "value_net.") if asymmetric else ()
    theirs = {k: v for k, v in saved.policy.state_dict().items() if k != "log_std" and not k.startswith(critic)}
    bad = sorted(k for k, v in theirs.items() if k not in own or own[k].shape != v.shape)
    if bad:
        raise ConfigError(f"invalid config: `init_from` = {str(src)!r} holds a policy of another network: its "
                          f"parameters {bad[:4]} do not fit the config's policy_kwargs {cfg['policy_kwargs']!r}")
    own.update(theirs)
    model.policy.load_state_dict(own)
    # deferred: stable-baselines3, an optional dependency (accd_gym.learning.callbacks imports it)
    from accd_gym.learning.callbacks import FrozenStatistics

    if asymmetric:
        # deferred: stable-baselines3 and torch, optional dependencies (accd_gym.learning.asymmetric imports them)
        from accd_gym.learning.asymmetric import PartlyFrozenStatistics

        env.obs_rms = PartlyFrozenStatistics(stats.obs_rms, env.observation_space.shape[0])
    else:
        env.obs_rms = FrozenStatistics.of(stats.obs_rms)


def check_training_env(env: dict[str, Any]) -> None:
    """ConfigError for a bad env override (or env option, :mod:`accd_gym.envs.agent_io`) or one that
    fixes a held-out wake seed (training may only draw training wake seeds); shared by every
    trainer."""

    _, physics = split_agent_options(env)  # raises ConfigError naming a bad residual/history option
    full = env_config(physics)  # raises ConfigError naming the bad env field

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


def _unnormalized_env(cfg: dict[str, Any]) -> tuple[Any, Any]:
    """The AccdVecEnv of the config (training wake seeds) and the same wrapped as VecNormalize
    will wrap it: in VecMonitor and, with ``asymmetric_critic``, in the wrapper appending the
    critic's true observation (:class:`accd_gym.learning.asymmetric.CriticObservation`)."""
    from stable_baselines3.common.vec_env import VecMonitor

    # deferred: stable-baselines3, an optional dependency (accd_gym.envs.sb3 imports it)
    from accd_gym.envs.sb3 import AccdVecEnv

    options = dict(cfg["env"], true_observation=True) if cfg.get("asymmetric_critic") else cfg["env"]
    base = AccdVecEnv(num_envs=cfg["num_envs"], seed=cfg["seed"], num_threads=cfg["num_threads"], **options)
    env = VecMonitor(base, info_keywords=("captured",))
    if cfg.get("asymmetric_critic"):
        # deferred: stable-baselines3 and torch, optional dependencies (accd_gym.learning.asymmetric imports them)
        from accd_gym.learning.asymmetric import CriticObservation

        env = CriticObservation(env)
    return base, env


def make_training_env(cfg: dict[str, Any]):
    """The AccdVecEnv (training wake seeds) wrapped in VecMonitor (and the asymmetric critic's
    wrapper) and VecNormalize per the config."""
    from stable_baselines3.common.vec_env import VecNormalize

    _, env = _unnormalized_env(cfg)
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


def checkpoints(run: str | Path) -> list[dict[str, Any]]:
    """Every checkpoint of a run folder, newest first: ``{"steps", "model", "vecnormalize",
    "env_state", "replay_buffer"}`` (paths; the last three None when absent). Whether each one
    loads is not checked here (:func:`resume` tries them in this order)."""
    folder = Path(run) / "checkpoints"
    found: list[tuple[int, Path]] = []
    for p in folder.glob("*_steps.zip"):
        m = re.fullmatch(r"(.+)_(\d+)_steps", p.stem)
        if m and not p.name.startswith(".") and p.is_file():
            found.append((int(m.group(2)), p))
    records = []
    for steps, model in sorted(found, key=lambda f: (f[0], f[1].name), reverse=True):
        prefix = model.stem[: -len(f"_{steps}_steps")]

        def beside(kind: str, ext: str) -> Optional[Path]:
            q = folder / f"{prefix}_{kind}_{steps}_steps.{ext}"
            return q if q.is_file() else None

        records.append({
            "steps": steps,
            "model": model,
            "vecnormalize": beside("vecnormalize", "pkl"),
            "env_state": beside("envstate", "bin"),
            "replay_buffer": beside("replay_buffer", "pkl"),
        })
    return records


def latest_checkpoint(run: str | Path) -> Optional[dict[str, Any]]:
    """The newest checkpoint of a run folder (the first of :func:`checkpoints`), or None without
    checkpoints."""
    found = checkpoints(run)
    return found[0] if found else None


def _reason(e: BaseException) -> str:
    """An exception as a short one-line reason (type and the start of its message)."""
    text = " ".join(str(e).split())
    return f"{type(e).__name__}: {text[:200]}{'...' if len(text) > 200 else ''}" if text else type(e).__name__


def model_algo(data: bytes, name: str) -> Optional[str]:
    """``"ppo"`` or ``"sac"`` for the bytes of a saved stable-baselines3 model (from its stored
    policy class), None when the class is neither; ConfigError naming ``name`` when the bytes are
    not a readable model zip (truncated, corrupted, another file)."""
    import io
    import zipfile

    try:
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            text = z.read("data").decode()
    except Exception as e:  # a damaged zip raises BadZipFile, zlib.error, EOFError, KeyError, ...
        raise ConfigError(f"invalid config: {name!r} is not a readable stable-baselines3 model (truncated or "
                          f"corrupted: {_reason(e)})") from None
    if "sac.policies" in text:
        return "sac"
    if "policies.ActorCriticPolicy" in text or "ActorCriticPolicy" in text:
        return "ppo"
    return None


def load_model(data: bytes, name: str, algo: Optional[str], obs_dim: Optional[int] = None, **kwargs: Any) -> Any:
    """The PPO or SAC model in the bytes of a saved model zip (``name``: its file, for the
    messages), loaded with ``kwargs`` (``env``, ``device``, ...). ``algo``: what the run's
    run.json says (None: what the zip holds). ConfigError naming the file when it is damaged,
    holds another algorithm than ``algo``, does not load, or is a model of another environment
    (observation or action shape other than accd-gym's: ``obs_dim`` observations, the plain env's
    by default; more with the env options ``residual`` and ``history``)."""
    from stable_baselines3 import PPO, SAC

    stored = model_algo(data, name)
    if algo is not None and stored is not None and algo != stored:
        raise ConfigError(f"invalid config: {name!r} holds a {stored.upper()} model, but its run.json says "
                          f"\"algo\": {algo!r}")
    algo = algo or stored
    if algo not in _ALGOS:
        raise ConfigError(f"invalid config: cannot tell the algorithm of {name!r} (allowed: PPO, SAC)")
    import io

    try:
        model = {"ppo": PPO, "sac": SAC}[algo].load(io.BytesIO(data), **kwargs)
    except Exception as e:  # a damaged or foreign model fails anywhere in torch or SB3
        raise ConfigError(f"invalid config: {name!r} does not load as a {algo.upper()} model of accd-gym "
                          f"({_reason(e)})") from None
    obs = getattr(model.observation_space, "shape", None)
    act = getattr(model.action_space, "shape", None)
    obs_dim = OBS_DIM if obs_dim is None else obs_dim
    if obs != (obs_dim,) or act != (ACT_DIM,):
        raise ConfigError(f"invalid config: {name!r} is a model of another environment: observations of shape "
                          f"{obs}, actions {act}; this env's are ({obs_dim},) and ({ACT_DIM},) (a model trained with the "
                          "env options residual/history is evaluated from its run folder, whose run.json holds them)")
    return model


def load_statistics(data: bytes, name: str, venv: Any = None, obs_dim: Optional[int] = None) -> Any:
    """The ``VecNormalize`` statistics pickled in ``data`` (``name``: its file, for the messages),
    attached to ``venv`` when given. ConfigError naming the file when it is empty, truncated,
    holds something else, or holds statistics of another environment (``obs_dim`` observations,
    the plain env's by default)."""
    import pickle

    from stable_baselines3.common.vec_env import VecNormalize

    if not data:
        raise ConfigError(f"invalid config: VecNormalize statistics {name!r} are an empty file")
    try:
        stats = pickle.loads(data)
    except Exception as e:  # a truncated or foreign pickle can raise almost anything
        raise ConfigError(f"invalid config: VecNormalize statistics {name!r} cannot be read (truncated or "
                          f"corrupted: {_reason(e)})") from None
    if not isinstance(stats, VecNormalize):
        raise ConfigError(f"invalid config: {name!r} holds a {type(stats).__name__}, not VecNormalize statistics")
    shape = getattr(getattr(stats, "observation_space", None), "shape", None)
    mean = getattr(getattr(stats, "obs_rms", None), "mean", None)
    obs_dim = OBS_DIM if obs_dim is None else obs_dim
    if shape != (obs_dim,) or (stats.norm_obs and getattr(mean, "shape", None) != (obs_dim,)):
        raise ConfigError(f"invalid config: {name!r} holds VecNormalize statistics of another environment "
                          f"(observations of shape {shape}; this env's are ({obs_dim},))")
    if venv is not None:
        try:
            stats.set_venv(venv)
        except Exception as e:
            raise ConfigError(f"invalid config: VecNormalize statistics {name!r} do not fit the env ({_reason(e)})") from None
    return stats


def save_statistics(env: Any, path: Path) -> None:
    """Writes the VecNormalize statistics (as ``VecNormalize.save`` does) atomically."""
    import pickle

    with files.atomic_open(path, "wb") as f:
        pickle.dump(env, f)


def save_model(model: Any, path: Path) -> None:
    """Writes an SB3 model's zip (``model.save`` into the open temporary file of
    :func:`accd_gym.files.atomic_open`, so that the one writer decides where it goes)."""
    with files.atomic_open(path, "wb") as f:
        model.save(f)


def _save_checkpoint(model: Any, env: Any, cfg: dict[str, Any], out: Path, *, replay_buffer: bool = True) -> dict[str, Any]:
    """Writes the VecNormalize statistics, the envs' exact state, (SAC, with ``replay_buffer``)
    the replay buffer and the model as a checkpoint named like SB3's CheckpointCallback's; each
    file atomically (:mod:`accd_gym.files`), the model last, so that a checkpoint's zip exists
    only once its companions are complete. Returns :func:`checkpoints`' record of it;
    OutputError (nothing of an earlier checkpoint touched) when a file cannot be written."""
    folder = out / "checkpoints"
    folder.mkdir(parents=True, exist_ok=True)
    steps = int(model.num_timesteps)
    stem = f"{_prefix(cfg)}_{{}}{steps}_steps"
    save_statistics(env, folder / (stem.format("vecnormalize_") + ".pkl"))
    files.write_bytes(folder / (stem.format("envstate_") + ".bin"), _base_env(env).get_state())
    if replay_buffer and hasattr(model, "save_replay_buffer") and cfg["algo"] == "sac":
        with files.atomic_open(folder / (stem.format("replay_buffer_") + ".pkl"), "wb") as f:
            model.save_replay_buffer(f)
    save_model(model, folder / (stem.format("") + ".zip"))
    record = latest_checkpoint(out)
    assert record is not None and record["steps"] == steps
    return record


def _checkpoint_callback(cfg: dict[str, Any], out: Path, meta: dict[str, Any]):
    """An SB3 callback writing a checkpoint (:func:`_save_checkpoint`, no replay buffer) every
    ``checkpoint_every`` environment steps, named like SB3's CheckpointCallback's, then run.json
    naming it (:func:`_note_checkpoint`): whatever stops the run later, run.json already names
    the checkpoint ``--resume`` continues from."""
    from stable_baselines3.common.callbacks import BaseCallback

    every = max(1, cfg["checkpoint_every"] // cfg["num_envs"])

    class PeriodicCheckpoints(BaseCallback):
        """Writes a checkpoint every ``every`` calls (vectorised env steps)."""

        def _on_step(self) -> bool:
            if self.n_calls % every == 0:
                ckpt = _save_checkpoint(self.model, self.model.get_env(), cfg, out, replay_buffer=False)
                _note_checkpoint(meta, ckpt)
                _write_meta(out, meta)
            return True

    return PeriodicCheckpoints()


def _note_checkpoint(meta: dict[str, Any], ckpt: Optional[dict[str, Any]]) -> None:
    """Records in the run summary the newest checkpoint written (``checkpoint``, ``vecnormalize``,
    ``checkpoint_steps``: what ``--resume`` continues from), or removes the record without one."""
    if ckpt is None:
        for key in ("checkpoint", "vecnormalize", "checkpoint_steps"):
            meta.pop(key, None)
    else:
        meta.update(checkpoint=str(ckpt["model"]), vecnormalize=str(ckpt["vecnormalize"]), checkpoint_steps=ckpt["steps"])


def _write_meta(out: Path, meta: dict[str, Any]) -> None:
    """Writes run.json atomically (a crash or a full disk never leaves half a file). On a full
    disk the run folder's reserve (:func:`accd_gym.files.reserve_space`, made when the training
    starts) is freed and the write tried once more, so that a run stopped by a full disk still
    says where it stands."""
    text = json.dumps(meta, indent=1, default=str)
    try:
        files.write_text(out / "run.json", text)
    except OutputError as e:
        if e.errno != errno.ENOSPC or not files.release_space(out):
            raise
        files.write_text(out / "run.json", text)


def _kept(out: Path) -> str:
    """What a run folder keeps after a failed write, for the messages."""
    ckpt = latest_checkpoint(out)
    if ckpt is None:
        return (f"the run has no checkpoint yet (it lost less than one checkpoint interval); free space and start it "
                f"over with: accd-gym train --resume {out}")
    return (f"the run keeps its checkpoint at {ckpt['steps']} steps ({ckpt['model']}); free space and continue with: "
            f"accd-gym train --resume {out}")


def _read_meta(out: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """A run folder's run.json and its validated config; ConfigError naming the file when it is
    missing, not JSON, not a run summary or holds an invalid config."""
    meta_path = out / "run.json"
    if not meta_path.exists():
        raise ConfigError(f"invalid config: --resume {str(out)!r} is not a run folder (no run.json)")
    meta = files.read_user_json(meta_path, "run summary")
    if not isinstance(meta, dict) or not isinstance(meta.get("config"), dict):
        raise ConfigError(f"invalid config: {str(meta_path)!r} is not a run summary (a JSON object with a \"config\" object)")
    try:
        cfg = validate_config(meta["config"])
    except ConfigError as e:
        raise ConfigError(f"invalid config: {str(meta_path)!r} holds an invalid config: {e}") from None
    return meta, cfg


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

    cfg = validate_config(dict(config))
    if timesteps is not None:
        if timesteps < 1:
            raise ConfigError(f"invalid config: `timesteps` = {timesteps} is outside the allowed range >= 1")
        cfg["total_timesteps"] = int(timesteps)
    out = files.writable_folder(out, "--out", RUN_FILES)
    held = [name for name in RUN_FILES if (out / name).exists()] + (["checkpoints"] if checkpoints(out) else [])
    if held:
        # Training afresh here would overwrite that run's model and mix its checkpoints with these.
        raise ConfigError(f"invalid config: --out {str(out)!r} already holds a training run ({', '.join(held)}); "
                          f"continue it with `accd-gym train --resume {out}`, or choose another --out")
    torch.set_num_threads(cfg["torch_threads"])
    _one_blas_thread()
    env, model = _new_model(cfg, out)
    meta = {"algo": cfg["algo"], "config": cfg, "status": "training", "total_timesteps": cfg["total_timesteps"]}
    if cfg.get("init_from") is not None:
        meta["init_from_digest"] = start_digest(cfg["init_from"])
    _write_meta(out, meta)
    return _learn(model, env, cfg, out, meta, progress=progress, fresh=True)


def _new_model(cfg: dict[str, Any], out: Path) -> tuple[Any, Any]:
    """The training env and a new model of the validated config ``cfg`` (TensorBoard logs in
    ``out/tb``); ConfigError when stable-baselines3 or torch refuses the config's values."""
    from stable_baselines3 import PPO, SAC

    env = make_training_env(cfg)
    cls = {"ppo": PPO, "sac": SAC}[cfg["algo"]]
    policy: Any = "MlpPolicy"
    policy_kwargs = _policy_kwargs(cfg)
    if cfg.get("asymmetric_critic"):
        # deferred: stable-baselines3 and torch, optional dependencies (accd_gym.learning.asymmetric imports them)
        from accd_gym.learning.asymmetric import AsymmetricActorCriticPolicy

        policy = AsymmetricActorCriticPolicy
        policy_kwargs["actor_dim"] = actor_dim(cfg)
    try:
        model = cls(
            policy,
            env,
            seed=cfg["seed"],
            device=cfg["device"],
            tensorboard_log=str(out / "tb"),
            policy_kwargs=policy_kwargs,
            verbose=0,
            **cfg["algo_kwargs"],
        )
    except (TypeError, ValueError, AssertionError, RuntimeError) as e:
        # a value of the right key that stable-baselines3 or torch cannot use (a string learning
        # rate, a batch size the rollout cannot fill, an unknown device, ...)
        env.close()
        raise ConfigError(f"invalid config: {cfg['algo'].upper()} refused the config's algo_kwargs "
                          f"{cfg['algo_kwargs']!r} / policy_kwargs {cfg['policy_kwargs']!r} / device "
                          f"{cfg['device']!r}: {type(e).__name__}: {e}") from e
    if cfg.get("init_from") is not None:
        try:
            _init_from(model, env, cfg)
        except BaseException:
            env.close()
            raise
    return env, model


def _one_blas_thread() -> None:
    """numpy's BLAS on one thread for the training process (threadpoolctl, when installed): its
    only users are small products (VecNormalize, the algorithms' buffers), and its idle threads
    spin beside the env's stepping threads."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    threadpool_limits(1, user_api="blas")


def _zero_action_init(cfg: dict[str, Any]):
    """The callback zeroing the last action layer at the start (``zero_action_init``), or None."""
    if not cfg["zero_action_init"]:
        return None
    # deferred: stable-baselines3 and torch, optional dependencies (accd_gym.learning.callbacks imports them)
    from accd_gym.learning.callbacks import ZeroActionInit

    return ZeroActionInit()


def resume(run: str | Path, *, progress: bool = True, report: Optional[Callable[[str], None]] = None) -> dict[str, Any]:
    """Continues an interrupted run (or one killed while training) from its newest checkpoint
    that loads to the total of its config, with the same config and seeds (the envs continue
    from their saved state; SAC's replay buffer is restored when it was saved). Returns the run
    summary.

    A checkpoint whose files are damaged (a truncated zip or statistics file, statistics of
    another env, a model of another algorithm than run.json's) is skipped: ``report`` (default:
    a warning) gets one line per skipped checkpoint saying why, and the next older one is tried.

    A run stopped before its first checkpoint (by a full disk, say) has lost less than one
    checkpoint interval: it starts over from step 0 with its config and seeds, saying so.

    Raises ConfigError when ``run`` is not a run folder, its run.json is damaged, it has
    finished, or none of its checkpoints loads.
    """
    import torch

    out = Path(run)
    meta, cfg = _read_meta(out)
    if meta.get("status") == "done":
        raise ConfigError(f"invalid config: run {str(run)!r} is complete ({meta.get('timesteps')} steps); nothing to resume")
    files.writable_folder(out, "--resume", RUN_FILES)
    found = checkpoints(out)
    if report is None:
        import warnings

        def report(line: str) -> None:
            warnings.warn(line, stacklevel=3)

    torch.set_num_threads(cfg["torch_threads"])
    _one_blas_thread()
    if not found:
        report(f"run {str(run)!r} has no checkpoint in {str(out / 'checkpoints')!r}: it starts over from step 0")
        env, model = _new_model(cfg, out)
        meta.setdefault("resumed", []).append({"from_steps": 0, "checkpoint": None})
        _note_checkpoint(meta, None)
        meta.update(status="training", timesteps=0)
        if cfg.get("init_from") is not None:
            meta["init_from_digest"] = start_digest(cfg["init_from"])
        _write_meta(out, meta)
        return _learn(model, env, cfg, out, meta, progress=progress, fresh=True)
    skipped: list[str] = []
    loaded = None
    for ckpt in found:
        try:
            loaded = _load_checkpoint(ckpt, cfg, out)
            break
        except (ConfigError, StateError) as e:
            reason = " ".join(str(e).split()).removeprefix("invalid config: ")
            skipped.append(f"{ckpt['model'].name} ({reason})")
            report(f"skipped checkpoint {ckpt['model']} ({ckpt['steps']} steps): {reason}")
    if loaded is None:
        raise ConfigError(f"invalid config: run {str(run)!r}: none of its {len(found)} checkpoints loads; "
                          f"newest: {skipped[0]}")
    ckpt, env, model = loaded
    record = {"from_steps": ckpt["steps"], "checkpoint": str(ckpt["model"])}
    if skipped:
        record["skipped"] = skipped
    meta.setdefault("resumed", []).append(record)
    meta["status"] = "training"
    _note_checkpoint(meta, ckpt)
    _write_meta(out, meta)
    return _learn(model, env, cfg, out, meta, progress=progress, fresh=False)


def _load_checkpoint(ckpt: dict[str, Any], cfg: dict[str, Any], out: Path) -> tuple[dict[str, Any], Any, Any]:
    """The env (wrapped, statistics restored, envs at their saved state) and model of one
    checkpoint; ConfigError or StateError naming the file that does not load."""
    if ckpt["vecnormalize"] is None:
        raise ConfigError(f"invalid config: checkpoint {str(ckpt['model'])!r} has no VecNormalize statistics beside it")
    base, wrapped = _unnormalized_env(cfg)
    try:
        obs_dim = wrapped.observation_space.shape[0]
        env = load_statistics(ckpt["vecnormalize"].read_bytes(), str(ckpt["vecnormalize"]), wrapped, obs_dim=obs_dim)
        env.training = True
        model = load_model(ckpt["model"].read_bytes(), str(ckpt["model"]), cfg["algo"], obs_dim, env=env,
                           device=cfg["device"],
                           tensorboard_log=str(out / "tb"))
        if ckpt["replay_buffer"] is not None and hasattr(model, "load_replay_buffer"):
            try:
                model.load_replay_buffer(str(ckpt["replay_buffer"]))
            except Exception as e:  # a truncated pickle raises almost anything
                raise ConfigError(f"invalid config: replay buffer {str(ckpt['replay_buffer'])!r} cannot be read "
                                  f"(truncated or corrupted: {_reason(e)})") from None
        if ckpt["env_state"] is not None:
            try:
                base.set_state(ckpt["env_state"].read_bytes())
            except StateError as e:
                raise StateError(f"env state {str(ckpt['env_state'])!r} cannot be restored: {e}") from None
            base.drop_pending_seed()  # continue the saved episode sequence instead of reseeding
    except BaseException:
        base.close()
        raise
    return ckpt, env, model


def _learn(model: Any, env: Any, cfg: dict[str, Any], out: Path, meta: dict[str, Any], *, progress: bool,
           fresh: bool) -> dict[str, Any]:
    """Runs ``model.learn`` to the config's total with checkpoints; on SIGINT/SIGTERM writes a
    checkpoint and marks the run interrupted, else writes the final model. Returns ``meta``.
    While it runs, the run folder holds a reserve (:func:`accd_gym.files.reserve_space`) that
    :func:`_write_meta` frees on a full disk, so that run.json still names the last checkpoint."""
    files.reserve_space(out)
    try:
        return _learn_reserved(model, env, cfg, out, meta, progress=progress, fresh=fresh)
    finally:
        files.release_space(out)


def _learn_reserved(model: Any, env: Any, cfg: dict[str, Any], out: Path, meta: dict[str, Any], *, progress: bool,
                    fresh: bool) -> dict[str, Any]:
    """:func:`_learn` with the run folder's reserve made."""
    import torch
    from stable_baselines3.common.callbacks import CallbackList

    remaining = cfg["total_timesteps"] - (0 if fresh else int(model.num_timesteps))
    t0 = time.time()
    start_steps = 0 if fresh else int(model.num_timesteps)
    stop = _StopRequest()
    callbacks = [_checkpoint_callback(cfg, out, meta), _capture_callback(), stop.callback()]
    init = _zero_action_init(cfg) if fresh else None
    if init is not None:
        callbacks.insert(0, init)
    if cfg.get("critic_warmup"):
        # deferred: stable-baselines3 and torch, optional dependencies (accd_gym.learning.callbacks imports them)
        from accd_gym.learning.callbacks import CriticWarmup

        callbacks.insert(0, CriticWarmup(cfg["critic_warmup"]))
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
        with _signals_deferred(), contextlib.suppress(OutputError):
            meta.update(status="interrupted", interrupted_by=str(e) or "SIGINT", timesteps=int(model.num_timesteps))
            _write_meta(out, meta)
        env.close()
        raise
    except OutputError as e:
        # A periodic checkpoint could not be written (a full disk): the earlier ones are intact.
        env.close()
        raise _write_failed(out, meta, f"training stopped at {int(model.num_timesteps)} steps: {e}",
                            stop.signal_name) from None
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
        try:
            if interrupted is not None:
                ckpt = _save_checkpoint(model, env, cfg, out)
                meta.update(status="interrupted", interrupted_by=interrupted)
                _note_checkpoint(meta, ckpt)
            else:
                # the statistics first: a final model on the disk always has its statistics
                save_statistics(env, out / "vecnormalize.pkl")
                save_model(model, out / "final_model.zip")
                meta.update(status="done")
                _note_checkpoint(meta, None)
                meta.pop("interrupted_by", None)
            _write_meta(out, meta)
        except OutputError as e:
            env.close()
            what = (f"training interrupted ({interrupted}) at {done} steps, but its checkpoint could not be written"
                    if interrupted is not None else f"training finished {done} steps, but its results could not be written")
            raise _write_failed(out, meta, f"{what}: {e}", interrupted) from None
    env.close()
    return meta


def _write_failed(out: Path, meta: dict[str, Any], what: str, signal_name: Optional[str] = None) -> OutputError:
    """The OutputError for a run whose checkpoint or final model could not be written: run.json
    marked interrupted (by ``signal_name``, or by the failed write) at the steps its newest
    checkpoint holds and naming that checkpoint (:func:`_write_meta` frees the folder's reserve
    for it on a full disk); the message says what the run keeps and how to continue."""
    ckpt = latest_checkpoint(out)
    with contextlib.suppress(OutputError):
        meta.update(status="interrupted", interrupted_by=f"{signal_name}; then a failed write" if signal_name else "a failed write",
                    timesteps=ckpt["steps"] if ckpt else 0)
        _note_checkpoint(meta, ckpt)
        _write_meta(out, meta)
    return OutputError(f"{what}; {_kept(out)}")


__all__ = ["DEFAULTS", "checkpoints", "latest_checkpoint", "load_config", "load_model", "load_statistics", "make_training_env",
           "model_algo", "resume", "save_model", "save_statistics", "train", "validate_config"]
