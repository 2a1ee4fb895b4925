"""Training with RLlib (new API stack) on the native vector env (``pip install 'accd-gym[ray]'``).

``accd-gym train --config training/rllib_ppo.json --out runs/NAME`` calls :func:`train` for a
config with ``"trainer": "rllib"``. Tested with Ray 2.60 (the ``ray`` extra pins
``ray[rllib,tune]>=2.60,<2.61``: RLlib's new API stack changes between minor versions).

**Env**: ``tune.register_env`` with a vector creator and ``gym_env_vectorize_mode=
"vector_entry_point"``: each env runner builds one :class:`accd_gym.InAirCaptureVectorEnv` of
``num_envs_per_env_runner`` envs (stepped by the Rust core on ``num_threads`` threads), with
RLlib's next-step autoreset. **Seeds**: RLlib resets a runner's vector env with ``seed +
worker_index``, which a vector env would spread to ``seed + worker_index + i``, so neighbouring
runners would share all but one env's episode streams. Instead runner ``w`` (1, 2, ...; 0 is
the local runner used when ``num_env_runners`` is 0) seeds env ``i`` with ``seed + (max(w, 1) - 1)
* num_envs_per_env_runner + i``, set from the runner's worker index when its env is created:
the runners' envs together are the envs ``0 .. num_env_runners * num_envs_per_env_runner - 1``
of one vector env seeded ``seed``, so no two runners share an episode stream, and every wake
seed is a training draw (an ``env`` override fixing a held-out wake seed is refused).

================== ================================================================================
key                meaning
================== ================================================================================
trainer            ``"rllib"`` (required: selects this module)
algo               ``"ppo"`` (the only one wired here)
total_timesteps    environment steps (all runners together); ``--timesteps`` overrides it
num_env_runners    RLlib env runner actors (0: sample in the driver)
num_envs_per_env_runner  envs of each runner's native vector env
num_threads        threads stepping each runner's envs (default 1)
torch_threads      threads PyTorch uses in the driver (learner) (default 1)
seed               base seed (see above) and RLlib's ``debugging(seed=...)``
env                environment config overrides (see :mod:`accd_gym.envs.config`)
algo_kwargs        keyword arguments of ``PPOConfig.training`` (``lr``, ``gamma``, ``lambda_``,
                   ``clip_param``, ``entropy_coeff``, ``train_batch_size_per_learner``,
                   ``minibatch_size``, ``num_epochs``, ``vf_loss_coeff``, ``grad_clip``...)
model              ``DefaultModelConfig`` fields (``fcnet_hiddens``, ``fcnet_activation``,
                   ``vf_share_layers``)
rollout_fragment_length  steps per env per sample (default ``"auto"``)
checkpoint_every   environment steps between checkpoints
ray_address        ``"local"`` (a Ray instance on this machine), ``"auto"`` or ``HOST:PORT``
================== ================================================================================

Outputs in ``out`` (the layout of a stable-baselines3 run): ``final_model/`` (an RLlib
checkpoint, :meth:`ray.rllib.algorithms.Algorithm.from_checkpoint` restores it), ``run.json``
(config, steps, wall time, steps per second, ``status``, the Ray and RLlib version),
``checkpoints/ckpt_<steps>_steps/`` and ``tb/`` (TensorBoard: episode return and length,
``accd/capture_rate``, the learner's losses, steps per second). Observations are not normalised
(the env's observations are already scaled to order one; see ``docs/environment.md``).
``accd-gym evaluate --policy RUN`` evaluates the final model (or the latest checkpoint of an
unfinished run) with :class:`RLlibPolicy`.
"""

from __future__ import annotations

import io
import json
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Any, Optional, Mapping

import numpy as np

from accd_gym import files
from accd_gym.errors import ConfigError
from accd_gym.learning import ray_cluster
from accd_gym.envs.config import read_json_object
from accd_gym.learning.training import check_training_env
from accd_gym.envs.vector import InAirCaptureVectorEnv
from accd_gym.files import read_user_json

#: Defaults of an RLlib training config.
DEFAULTS: dict[str, Any] = {
    "trainer": "rllib",
    "algo": "ppo",
    "total_timesteps": 1_000_000,
    "num_env_runners": 1,
    "num_envs_per_env_runner": 16,
    "num_threads": 1,
    "torch_threads": 1,
    "seed": 0,
    "env": {},
    "algo_kwargs": {},
    "model": {"fcnet_hiddens": [128, 128], "fcnet_activation": "tanh", "vf_share_layers": False},
    "rollout_fragment_length": "auto",
    "checkpoint_every": 200_000,
    "ray_address": "local",
}
#: The env name this module registers with Tune.
ENV_NAME = "accd-gym-vector"
#: Where a checkpoint keeps the policy's RLModule.
MODULE_PATH = Path("learner_group") / "learner" / "rl_module" / "default_policy"
_MODEL_KEYS = ("fcnet_hiddens", "fcnet_activation", "vf_share_layers", "head_fcnet_hiddens", "head_fcnet_activation")


def is_rllib_config(raw: Any) -> bool:
    """Whether a parsed training config asks for this trainer (``"trainer": "rllib"``)."""
    return isinstance(raw, dict) and raw.get("trainer") == "rllib"


def load_config(path: str | Path, **overrides: Any) -> dict[str, Any]:
    """A complete, validated RLlib training config from a JSON file plus overrides (None ignored)."""
    raw = read_json_object(path, "training config")
    raw.update({k: v for k, v in overrides.items() if v is not None})
    return validate_config(raw)


def validate_config(raw: dict[str, Any]) -> dict[str, Any]:
    """Fills in defaults and checks every field; ConfigError names the field, value and allowed range."""
    unknown = set(raw) - set(DEFAULTS) - {"description"}
    if unknown:
        raise ConfigError(f"invalid config: RLlib training config key(s) {sorted(unknown)} outside the allowed set {sorted(DEFAULTS)}")
    cfg = json.loads(json.dumps(DEFAULTS))
    cfg.update(raw)
    if cfg["trainer"] != "rllib":
        raise ConfigError(f"invalid config: `trainer` = {cfg['trainer']!r} is outside the allowed range ['rllib']")
    if cfg["algo"] != "ppo":
        raise ConfigError(f"invalid config: `algo` = {cfg['algo']!r} is outside the allowed range ['ppo'] for the RLlib trainer")
    for key, low, high in (("total_timesteps", 1, 10**12), ("num_env_runners", 0, 4096), ("num_envs_per_env_runner", 1, 65_536),
                           ("num_threads", 0, 1024), ("torch_threads", 1, 1024), ("checkpoint_every", 1, 10**12),
                           ("seed", 0, 2**32 - 1)):
        v = cfg[key]
        if not isinstance(v, int) or isinstance(v, bool) or not low <= v <= high:
            raise ConfigError(f"invalid config: `{key}` = {v!r} is outside the allowed range: an integer in [{low}, {high}]")
    for key in ("env", "algo_kwargs", "model"):
        if not isinstance(cfg[key], dict):
            raise ConfigError(f"invalid config: `{key}` = {cfg[key]!r} is outside the allowed range: a JSON object")
    cfg["model"] = dict(DEFAULTS["model"], **cfg["model"])
    bad = sorted(set(cfg["model"]) - set(_MODEL_KEYS))
    if bad:
        raise ConfigError(f"invalid config: model key(s) {bad} outside the allowed set {sorted(_MODEL_KEYS)}")
    rfl = cfg["rollout_fragment_length"]
    if rfl != "auto" and (not isinstance(rfl, int) or isinstance(rfl, bool) or rfl < 1):
        raise ConfigError(f"invalid config: `rollout_fragment_length` = {rfl!r} is outside the allowed range: 'auto' or an integer >= 1")
    if not isinstance(cfg["ray_address"], str):
        raise ConfigError(f"invalid config: `ray_address` = {cfg['ray_address']!r} is outside the allowed range: 'local', 'auto' or 'HOST:PORT'")
    _check_algo_kwargs(cfg["algo_kwargs"])

    check_training_env(cfg["env"])
    return cfg


def _check_algo_kwargs(kwargs: dict[str, Any]) -> None:
    """ConfigError for a key ``PPOConfig.training`` does not take (when RLlib is installed)."""
    try:
        from ray.rllib.algorithms.ppo import PPOConfig
    except ModuleNotFoundError:
        return
    import inspect

    allowed = set(inspect.signature(PPOConfig.training).parameters) - {"self", "kwargs"}
    allowed |= set(inspect.signature(PPOConfig.__mro__[1].training).parameters) - {"self", "kwargs"}
    bad = sorted(set(kwargs) - allowed)
    if bad:
        raise ConfigError(f"invalid config: algo_kwargs key(s) {bad} outside the allowed set for RLlib PPO: {sorted(allowed)}")


def runner_seed_base(seed: int, worker_index: int, num_envs: int) -> int:
    """The seed of env 0 of runner ``worker_index``: ``seed + (max(w, 1) - 1) * num_envs``."""
    return int(seed) + (max(int(worker_index), 1) - 1) * int(num_envs)


def _runner_env_class() -> type:
    """The vector env RLlib's runners build: an :class:`InAirCaptureVectorEnv` whose int-seeded
    reset uses the runner's own seeds (``runner_base + i``) once its worker index is known."""
    class RunnerVectorEnv(InAirCaptureVectorEnv):
        """InAirCaptureVectorEnv of one RLlib env runner (see the module docstring for its seeds)."""

        runner_base: Optional[int] = None

        def reset(self, *, seed: Any = None, options: Optional[dict[str, Any]] = None) -> Any:
            """Resets as the parent does; an int seed becomes ``[runner_base + i]`` once set."""
            if self.runner_base is not None and isinstance(seed, (int, np.integer)):
                seed = [self.runner_base + i for i in range(self.num_envs)]
            return super().reset(seed=seed, options=options)

    return RunnerVectorEnv


def make_runner_env(ctx: Any) -> Any:
    """RLlib's vector creator: ``ctx`` holds ``num_envs`` (added by RLlib), ``env``,
    ``num_threads`` and ``seed`` (from the config's ``env_config``)."""
    cls = _runner_env_class()
    return cls(int(ctx["num_envs"]), num_threads=int(ctx.get("num_threads", 1)), **dict(ctx.get("env", {})))


def _on_environment_created(env: Any, env_context: Any, **_: Any) -> None:
    """Sets a runner's env seeds from its worker index (RLlib passes the ``EnvContext`` here only)."""
    base = runner_seed_base(env_context.get("seed", 0), env_context.worker_index, env.num_envs)
    env.runner_base = base


def _on_episode_end(episode: Any, metrics_logger: Any, **_: Any) -> None:
    """Logs the ended episode's capture (``accd/capture_rate``) and final distance."""
    info = episode.get_infos(-1) or {}
    metrics_logger.log_value("accd/capture_rate", float(bool(info.get("captured", False))), window=200)
    if "distance" in info:
        metrics_logger.log_value("accd/final_distance_m", float(info["distance"]), window=200)


def build_config(cfg: dict[str, Any]) -> Any:
    """The ``PPOConfig`` of a validated config (registers the env with Tune)."""
    from ray import tune
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    tune.register_env(ENV_NAME, make_runner_env)
    env_config = {"env": cfg["env"], "num_threads": cfg["num_threads"], "seed": cfg["seed"]}
    return (
        PPOConfig()
        .environment(ENV_NAME, env_config=env_config)
        .env_runners(num_env_runners=cfg["num_env_runners"], num_envs_per_env_runner=cfg["num_envs_per_env_runner"],
                     gym_env_vectorize_mode="vector_entry_point", rollout_fragment_length=cfg["rollout_fragment_length"],
                     num_cpus_per_env_runner=max(1, cfg["num_threads"]))
        .training(**cfg["algo_kwargs"])
        .rl_module(model_config=DefaultModelConfig(**cfg["model"]))
        .callbacks(on_environment_created=_on_environment_created, on_episode_end=_on_episode_end)
        .debugging(seed=cfg["seed"])
    )


def _versions() -> dict[str, str]:
    import ray

    return {"ray": ray.__version__}


def _scalars(result: dict[str, Any]) -> dict[str, float]:
    """The TensorBoard scalars of one training iteration's result."""
    out: dict[str, float] = {}
    runners = result.get("env_runners", {})
    for key in ("episode_return_mean", "episode_len_mean", "accd/capture_rate", "accd/final_distance_m"):
        v = runners.get(key)
        if isinstance(v, (int, float, np.floating, np.integer)) and np.isfinite(v):
            out[key if key.startswith("accd/") else f"rollout/{key}"] = float(v)
    learner = result.get("learners", {}).get("default_policy", {})
    for key in ("policy_loss", "vf_loss", "entropy", "mean_kl_loss", "curr_kl_coeff"):
        v = learner.get(key)
        if isinstance(v, (int, float, np.floating, np.integer)) and np.isfinite(v):
            out[f"train/{key}"] = float(v)
    return out


def _writer(path: Path) -> Any:
    """A TensorBoard SummaryWriter (tensorboardX, which Ray Tune brings, or PyTorch's)."""
    try:
        from tensorboardX import SummaryWriter
    except ModuleNotFoundError:
        from torch.utils.tensorboard import SummaryWriter
    return SummaryWriter(str(path))


def _write_meta(out: Path, meta: dict[str, Any]) -> None:
    """Writes run.json atomically (:mod:`accd_gym.files`)."""
    files.write_text(out / "run.json", json.dumps(meta, indent=1))


def train(cfg: dict[str, Any], out: str | Path, *, timesteps: Optional[int] = None, progress: bool = True,
          connect: bool = True) -> dict[str, Any]:
    """Trains RLlib PPO per the validated config ``cfg`` into the run folder ``out``; returns the
    run summary (also ``out/run.json``). Ctrl+C writes a checkpoint, marks the run
    ``"interrupted"`` and returns. ``connect=False``: use the Ray connection already made
    (inside a Tune trial)."""
    import torch

    if timesteps is not None:
        cfg = dict(cfg, total_timesteps=int(timesteps))
    out = files.writable_folder(out, "--out", ("run.json",))  # before Ray starts
    (out / "checkpoints").mkdir(exist_ok=True)
    if connect:
        ray_cluster.connect(cfg["ray_address"])
    torch.set_num_threads(cfg["torch_threads"])
    meta: dict[str, Any] = {"trainer": "rllib", "algo": "ppo", "config": cfg, "status": "running", "timesteps": 0,
                            "versions": _versions()}
    _write_meta(out, meta)
    algo = build_config(cfg).build_algo()
    writer = _writer(out / "tb")
    total = cfg["total_timesteps"]
    steps = 0
    next_ckpt = cfg["checkpoint_every"]
    t0 = time.perf_counter()
    sample_time = 0.0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, desc="rllib ppo", unit="step")
    status, interrupted_by = "finished", None
    try:
        while steps < total:
            result = algo.train()
            new = int(result["env_runners"]["num_env_steps_sampled_lifetime"])
            if bar is not None:
                bar.update(new - steps)
            steps = new
            sample_time += float(result["env_runners"].get("sample", 0.0))
            elapsed = time.perf_counter() - t0
            for k, v in _scalars(result).items():
                writer.add_scalar(k, v, steps)
            writer.add_scalar("time/steps_per_s", steps / elapsed, steps)
            if steps >= next_ckpt and steps < total:
                algo.save_to_path(str((out / "checkpoints" / f"ckpt_{steps}_steps").resolve()))
                next_ckpt += cfg["checkpoint_every"]
            meta.update(timesteps=steps, wall_time_s=round(elapsed, 2))
            _write_meta(out, meta)
    except KeyboardInterrupt:
        status, interrupted_by = "interrupted", "SIGINT"
    finally:
        if bar is not None:
            bar.close()
        writer.close()
    wall = time.perf_counter() - t0
    if status == "finished":
        algo.save_to_path(str((out / "final_model").resolve()))
        meta["checkpoint"] = str(out / "final_model")
    else:
        ckpt = out / "checkpoints" / f"ckpt_{steps}_steps"
        algo.save_to_path(str(ckpt.resolve()))
        meta.update(checkpoint=str(ckpt), interrupted_by=interrupted_by)
    algo.stop()
    meta.update(status=status, timesteps=steps, wall_time_s=round(wall, 2),
                steps_per_s=round(steps / wall, 1) if wall > 0 else None,
                iterations=int(result["training_iteration"]) if steps else 0)
    _write_meta(out, meta)
    return meta


def latest_checkpoint(run: str | Path) -> Optional[Path]:
    """The newest ``checkpoints/ckpt_<steps>_steps`` folder of an RLlib run, or None."""
    folder = Path(run) / "checkpoints"
    found = []
    for p in folder.glob("ckpt_*_steps") if folder.is_dir() else []:
        try:
            found.append((int(p.name.split("_")[1]), p))
        except ValueError:
            continue
    return max(found)[1] if found else None


def is_rllib_run(path: str | Path) -> bool:
    """Whether ``path`` is an RLlib run folder (run.json with ``"trainer": "rllib"``) or checkpoint."""
    p = Path(path)
    if (p / "rllib_checkpoint.json").is_file():
        return True

    if not (p / "run.json").exists():
        return False
    try:
        return read_user_json(p / "run.json", "run summary").get("trainer") == "rllib"
    except (ConfigError, AttributeError):
        return False


class RLlibPolicy:
    """A trained RLlib PPO policy (its RLModule), deterministic: the mean of the action
    distribution, clipped to [-1, 1].

    ``path``: a run folder (``final_model/``, or for an unfinished run its latest checkpoint,
    which :attr:`note` and a warning say) or an RLlib checkpoint folder. Needs the ``ray``
    extra. Pickles as the module's checkpoint files, so Ray tasks on other nodes can load it.
    """

    def __init__(self, path: str | Path) -> None:
        import warnings

        p = Path(path)
        #: How the model was found, e.g. that a run's latest checkpoint stands in for its final model.
        self.note: Optional[str] = None
        ckpt = p
        if not (p / "rllib_checkpoint.json").is_file():
            ckpt = p / "final_model"
            if not (ckpt / "rllib_checkpoint.json").is_file():
                latest = latest_checkpoint(p)
                if latest is None:
                    raise ConfigError(f"invalid config: policy path {str(path)!r}: no final model and no checkpoint in "
                                      f"{str(p / 'checkpoints')!r}")
                ckpt = latest
                self.note = f"run {str(path)!r} has no final model; evaluating its latest checkpoint {ckpt.name}"
                warnings.warn(self.note, stacklevel=2)
        module_dir = ckpt / MODULE_PATH
        if not module_dir.is_dir():
            raise ConfigError(f"invalid config: policy path {str(path)!r}: {str(module_dir)!r} is not an RLlib module checkpoint")
        self.name = str(path)
        self.algo = "ppo"
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w") as tar:
            tar.add(str(module_dir), arcname="module")
        self._module_tar = buf.getvalue()
        self._load()

    def _load(self) -> None:
        """Builds the RLModule from the kept checkpoint files."""
        try:
            from ray.rllib.core.rl_module.rl_module import RLModule
        except ModuleNotFoundError as e:
            raise ModuleNotFoundError(f"loading the RLlib model {self.name!r} needs Ray ({e}): pip install 'accd-gym[ray]'",
                                      name=e.name) from e
        with tempfile.TemporaryDirectory() as tmp:
            with tarfile.open(fileobj=io.BytesIO(self._module_tar)) as tar:
                tar.extractall(tmp, filter="data")
            self.module = RLModule.from_checkpoint(str(Path(tmp) / "module"))
        self.module.eval()

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k != "module"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._load()

    def predict(self, obs: Any) -> np.ndarray:
        """Deterministic actions (N, 4) for observations (N, 25): the Gaussian's mean, clipped."""
        import torch

        o = torch.as_tensor(np.asarray(obs, dtype=np.float32))
        with torch.no_grad():
            out = self.module.forward_inference({"obs": o})
        logits = out["action_dist_inputs"].numpy()
        mean = logits[:, : logits.shape[1] // 2]
        return np.clip(mean, -1.0, 1.0).astype(np.float32)

    def reset(self, mask: Optional[np.ndarray] = None) -> None:
        """Feed-forward policies keep no state."""

    def get_state(self) -> dict[str, np.ndarray]:
        """Feed-forward: no per-env state."""
        return {}

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Feed-forward: nothing to restore."""


__all__ = ["DEFAULTS", "ENV_NAME", "RLlibPolicy", "build_config", "is_rllib_config", "is_rllib_run", "latest_checkpoint",
           "load_config", "make_runner_env", "runner_seed_base", "train", "validate_config"]
