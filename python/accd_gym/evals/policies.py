"""Policies by name or path: :func:`load_policy`, the one resolver of the registered controllers
(:mod:`accd_gym.control.registry`), the shipped trained policies (:mod:`accd_gym.evals.shipped`; their exported networks,
:class:`accd_gym.evals.network.NetworkPolicy`),
tuning files of the guidance controller and the LQR, trained stable-baselines3 models
(:class:`SB3Policy`) and RLlib runs (:class:`accd_gym.learning.rllib.RLlibPolicy`), each as an
:class:`accd_gym.control.registry.Policy`.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Optional

import numpy as np

from accd_gym.control.baselines import guidance_from_tuning
from accd_gym.control.lqr import is_lqr_tuning, lqr_from_tuning
from accd_gym.control.registry import CONTROLLERS, Policy, make_controller
from accd_gym.envs.agent_io import AgentOptions, AgentSideMethods, PolicyAgentIO, physics_config, split_agent_options
from accd_gym.envs.task import OBS_DIM
from accd_gym.errors import ConfigError
from accd_gym.evals.network import NetworkPolicy
from accd_gym.evals.shipped import available, is_trained, policy_dir
from accd_gym.files import read_user_json
from accd_gym.learning.rllib import RLlibPolicy, is_rllib_run
from accd_gym.learning.training import latest_checkpoint, load_model, load_statistics, model_algo


class SB3Policy(AgentSideMethods):
    """A trained stable-baselines3 model (PPO or SAC) with its VecNormalize statistics, deterministic.

    ``path``: a run folder (``final_model.zip`` and ``vecnormalize.pkl`` in it; for a run that was
    interrupted or is still training, its latest checkpoint, which :attr:`note` and a warning
    say), or a model ``.zip`` (its statistics: ``vecnormalize.pkl`` beside it, or for a
    checkpoint ``<prefix>_vecnormalize_<steps>_steps.pkl``). The algorithm is read from the run's
    ``run.json`` when there is one, else from the zip's stored policy class.

    A model trained with VecNormalize acts on normalised observations: without its statistics it
    would see raw ones and act wrongly, so a missing statistics file is a ConfigError unless
    ``allow_unnormalized=True`` (then observations are passed raw, with a warning).

    A model trained with the env options ``residual``/``history`` (:mod:`accd_gym.envs.agent_io`, read
    from the run's ``run.json``) gets the observations it was trained on and its actions are
    turned into flap commands as in training: the policy keeps the base controller (designed
    for ``config``, the env configuration it runs on) and the history per env, restarted by
    :meth:`reset`, so it runs on the plain env. :attr:`agent_options` holds them.
    """

    def __init__(self, path: str | Path, device: str = "cpu", *, allow_unnormalized: bool = False,
                 config: Optional[Any] = None) -> None:
        p = Path(path)
        #: How the model was found, e.g. that a run's latest checkpoint stands in for its final model.
        self.note: Optional[str] = None
        if p.is_dir():
            model_path, stats_path = p / "final_model.zip", p / "vecnormalize.pkl"
            if not model_path.is_file():
                ckpt = latest_checkpoint(p)
                status = _run_status(p)
                if ckpt is None:
                    raise ConfigError(
                        f"invalid config: policy path {str(path)!r}: no final model and no checkpoint in "
                        f"{str(p / 'checkpoints')!r} (run status: {status})"
                    )
                model_path = ckpt["model"]
                stats_path = ckpt["vecnormalize"] or model_path.with_name("vecnormalize.pkl")
                self.note = (f"run {str(path)!r} has no final model (status: {status}); evaluating its latest "
                             f"checkpoint {model_path.name} ({ckpt['steps']} steps)")
                warnings.warn(self.note, stacklevel=2)
        else:
            model_path = p
            stats_path = p.with_name("vecnormalize.pkl")
            if "_steps" in p.stem:  # CheckpointCallback: <prefix>_<steps>_steps.zip
                prefix, steps = p.stem.rsplit("_", 2)[0], p.stem.rsplit("_", 2)[1]
                stats_path = p.with_name(f"{prefix}_vecnormalize_{steps}_steps.pkl")
        if not model_path.is_file():
            raise ConfigError(f"invalid config: policy path {str(path)!r}: no model file {str(model_path)!r}")
        if not stats_path.is_file() and not allow_unnormalized:
            raise ConfigError(
                f"invalid config: policy {str(path)!r}: its VecNormalize statistics {str(stats_path)!r} are missing; "
                "the model would see unnormalised observations (pass allow_unnormalized=True, or "
                "--allow-unnormalized on the command line, if it was trained without VecNormalize)"
            )
        self.name = str(path)
        try:
            # The optional dependency, imported here so that the package imports without it.
            from stable_baselines3 import PPO, SAC  # noqa: F401
        except ModuleNotFoundError as e:
            raise ModuleNotFoundError(
                f"loading the trained model {str(path)!r} needs stable-baselines3 ({e}): pip install 'accd-gym[sb3]'",
                name=e.name,
            ) from e
        self._device = device
        self.agent_options = _agent_options_of(model_path)
        #: Inputs the model reads beyond the actor's observation (an asymmetric critic's true
        #: observation): zeros here, which the actor never reads.
        self.critic_inputs = _critic_inputs_of(model_path)
        self._config = physics_config(config)
        self._agent = PolicyAgentIO(self.agent_options, self._config)
        self._model_path = str(model_path)
        self._stats_path = str(stats_path)
        self._model_bytes = model_path.read_bytes()
        self._stats_bytes = stats_path.read_bytes() if stats_path.is_file() else None
        #: What run.json beside or above the model says (checked against the zip when loading).
        self._run_algo = _run_algo(model_path)
        self.algo = self._run_algo or model_algo(self._model_bytes, self._model_path)
        self._load()
        expected = (self.agent_options.observation_space().shape[0] + self.critic_inputs,)
        if self.model.observation_space.shape != expected:
            raise ConfigError(
                f"invalid config: policy {str(path)!r} observes shape {self.model.observation_space.shape}, the env "
                f"options {self.agent_options.to_dict() or 'none'} give {expected}; a model trained with residual/history "
                "options is evaluated from its run folder (run.json holds them)"
            )
        if self._stats_bytes is None:
            warnings.warn(f"policy {str(path)!r}: no VecNormalize statistics; observations are passed unnormalised",
                          stacklevel=2)

    def _load(self) -> None:
        """Builds the model and the normalizer from the files' bytes (kept for pickling);
        ConfigError naming the file that is damaged or of another env or algorithm."""
        obs_dim = self.agent_options.observation_space().shape[0] + self.critic_inputs
        self.model = load_model(self._model_bytes, self._model_path, self._run_algo, obs_dim, device=self._device)
        self.normalizer = None
        if self._stats_bytes is not None:
            self.normalizer = load_statistics(self._stats_bytes, self._stats_path, obs_dim=obs_dim)
            self.normalizer.training = False

    def __getstate__(self) -> dict[str, Any]:
        """Pickles as the model's and statistics' file contents (for Ray tasks): a copy acts bit for bit alike."""
        return {k: v for k, v in self.__dict__.items() if k not in ("model", "normalizer")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._load()

    def predict(self, obs: Any) -> np.ndarray:
        """Deterministic flap commands (N, 4) for raw observations (N, 25), normalised as in
        training (with residual/history options: augmented, and the actions made commands, as
        the env did in training)."""
        o = np.asarray(obs, dtype=np.float32)
        if self.agent_options.enabled:
            o = self._agent.observation(o)
        if self.critic_inputs:
            o = np.concatenate([o, np.zeros((o.shape[0], self.critic_inputs), dtype=np.float32)], axis=1)
        if self.normalizer is not None and self.normalizer.norm_obs:
            o = self.normalizer.normalize_obs(o)
        actions, _ = self.model.predict(o, deterministic=True)
        actions = np.clip(np.asarray(actions, dtype=np.float32), -1.0, 1.0)
        return self._agent.command(actions)


def _run_status(run: Path) -> str:
    """The ``status`` of a run folder's run.json ("unknown" without one or with a damaged one)."""
    if not (run / "run.json").exists():
        return "unknown"
    try:
        return str(read_user_json(run / "run.json", "run summary").get("status", "unknown"))
    except (ConfigError, AttributeError):
        return "unknown"


def _run_algo(model_path: Path) -> Optional[str]:
    """'ppo' or 'sac' as the run.json beside or above a saved model says, None without one;
    ConfigError naming the run.json when it is damaged or names another algorithm."""
    for folder in (model_path.parent, model_path.parent.parent):
        meta = folder / "run.json"
        if meta.exists():
            doc = read_user_json(meta, "run summary")
            algo = doc.get("algo") if isinstance(doc, dict) else None
            if algo not in ("ppo", "sac"):
                raise ConfigError(f"invalid config: {str(meta)!r} is not a run summary of a stable-baselines3 run: "
                                  f"`algo` = {algo!r} is outside the allowed range ['ppo', 'sac']")
            return algo
    return None


def _critic_inputs_of(model_path: Path) -> int:
    """How many inputs the model's critic reads beyond the actor's observation: the true
    observation's size for a run trained with ``asymmetric_critic``, else 0 (from its run.json)."""
    for folder in (model_path.parent, model_path.parent.parent):
        meta = folder / "run.json"
        if meta.exists():
            doc = read_user_json(meta, "run summary")
            cfg = doc.get("config", {}) if isinstance(doc, dict) else {}
            return OBS_DIM if isinstance(cfg, dict) and cfg.get("asymmetric_critic") is True else 0
    return 0


def _agent_options_of(model_path: Path) -> Any:
    """The env options (residual, history) the model was trained with, from its run.json."""
    for folder in (model_path.parent, model_path.parent.parent):
        meta = folder / "run.json"
        if meta.exists():
            doc = read_user_json(meta, "run summary")
            env = doc.get("config", {}).get("env", {}) if isinstance(doc, dict) else {}
            return split_agent_options(env)[0] if isinstance(env, dict) else AgentOptions()
    return AgentOptions()


def load_policy(spec: str, seed: int = 0, *, allow_unnormalized: bool = False, config: Optional[Any] = None) -> Policy:
    """The one resolver of policy specs: every policy the package runs comes from here.

    ``spec``, tried in this order:

    1. the name of a shipped trained policy (:mod:`accd_gym.trained`; a file or folder of that
       name in the working folder wins): its :class:`SB3Policy`;
    2. the name of a registered controller (:data:`accd_gym.control.registry.CONTROLLERS`:
       ``zero``, ``random``, ``guidance``, ``lqr``, ...): the controller built for ``config``
       with ``seed``;
    3. a tuning file (``training/guidance_tuning*.json``: the guidance controller with its
       winning gains; ``training/lqr_tuning.json``: the LQR with its winning tuning);
    4. a model path: an RLlib run or checkpoint folder (:class:`accd_gym.learning.rllib.RLlibPolicy`)
       or a stable-baselines3 run folder or model zip (:class:`SB3Policy`; see it for
       ``allow_unnormalized``).

    ``config``: the env configuration (overrides) the policy will run on; a model-based
    controller (the LQR, a residual base) is designed for it. Anything else is a ConfigError
    naming the registered controllers."""
    config = physics_config(config)
    if is_trained(spec):
        return NetworkPolicy(policy_dir(spec), config=config)
    if spec in CONTROLLERS:
        return make_controller(spec, seed, config)
    if spec.endswith(".json") and Path(spec).is_file():
        if is_lqr_tuning(spec):
            return lqr_from_tuning(spec, config)
        return guidance_from_tuning(spec)
    if Path(spec).exists():
        if is_rllib_run(spec):
            return RLlibPolicy(spec)
        return SB3Policy(spec, allow_unnormalized=allow_unnormalized, config=config)
    raise ConfigError(f"invalid config: policy {spec!r} is neither a registered controller {list(CONTROLLERS)}, "
                      f"a shipped policy {available()} nor a model path")


__all__ = ["SB3Policy", "load_policy"]
