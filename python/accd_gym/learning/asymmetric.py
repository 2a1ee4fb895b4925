"""Asymmetric actor-critic for PPO (the training config's ``"asymmetric_critic": true``): the
critic also reads the true observation (what perfect sensors would give, the env option
``true_observation``), the actor only what the tier's sensors give, so that the policy still
runs on the sensors alone while its advantages come from a critic that is not misled by their
noise and delays.

* :class:`CriticObservation`: a VecEnv wrapper appending each env's true observation (25 values,
  scaled like the observation) to its observation, at reset, at every step and in the
  ``terminal_observation`` of an ended episode (the ended episode's last true observation).
* :class:`AsymmetricActorCriticPolicy`: stable-baselines3's actor-critic policy whose actor sees the
  first ``actor_dim`` inputs (the agent's observation) and whose critic sees all of them; the
  parameter names are those of the standard policy, so that a distilled student's actor loads
  into it (``init_from``) and its actor is exported like any other.
* :class:`PartlyFrozenStatistics`: observation statistics whose first ``frozen_dims`` entries stay
  those of the policy the run starts from while the rest (the critic's extra inputs) are updated.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, FlattenExtractor, MlpExtractor
from stable_baselines3.common.vec_env import VecEnvWrapper

from accd_gym.envs.task import OBS_DIM

__all__ = ["ActorInputs", "AsymmetricActorCriticPolicy", "CriticObservation", "PartlyFrozenStatistics", "TRUE_DIM"]

#: The critic's extra inputs: the true observation.
TRUE_DIM = OBS_DIM


class CriticObservation(VecEnvWrapper):
    """Appends each env's true observation to its observation (the wrapped env must be built with
    ``true_observation=True``). The observation space grows by :data:`TRUE_DIM` entries in
    [-10, 10], the bounds of the observation's own scaled entries."""

    def __init__(self, venv: Any) -> None:
        base = venv.observation_space
        low = np.concatenate([base.low, np.full(TRUE_DIM, -10.0, dtype=base.dtype)])
        high = np.concatenate([base.high, np.full(TRUE_DIM, 10.0, dtype=base.dtype)])
        super().__init__(venv, observation_space=spaces.Box(low, high, dtype=base.dtype))
        self.actor_dim = int(base.shape[0])

    def _true(self, infos: Any, rows: range) -> np.ndarray:
        try:
            return np.stack([np.asarray(infos[i]["true_obs"], dtype=np.float32) for i in rows])
        except KeyError:
            raise RuntimeError("CriticObservation needs the env option true_observation=True") from None

    def reset(self) -> np.ndarray:
        """The wrapped env's first observations with their true observations appended."""
        obs = self.venv.reset()
        return np.concatenate([obs, self._true(self.venv.unwrapped.reset_infos, range(self.num_envs))], axis=1)

    def step_wait(self) -> Any:
        """The wrapped env's step with the true observations appended: a row whose episode ended
        gets the new episode's first one, and its ``terminal_observation`` the ended episode's
        last one."""
        obs, rewards, dones, infos = self.venv.step_wait()
        true = self._true(infos, range(self.num_envs))  # an ended episode's: its last
        now = true.copy()
        for i in np.flatnonzero(dones):
            now[i] = np.asarray(self.venv.unwrapped.reset_infos[i]["true_obs"], dtype=np.float32)
            if "terminal_observation" in infos[i]:
                infos[i]["terminal_observation"] = np.concatenate([infos[i]["terminal_observation"], true[i]])
        return np.concatenate([obs, now], axis=1), rewards, dones, infos


class ActorInputs(BaseFeaturesExtractor):
    """The actor's inputs: the first ``actor_dim`` entries of a flat observation."""

    def __init__(self, observation_space: spaces.Box, actor_dim: int) -> None:
        super().__init__(observation_space, actor_dim)
        self.actor_dim = actor_dim

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        """The actor's slice of the (flat) observations."""
        return observations[..., : self.actor_dim]


class AsymmetricActorCriticPolicy(ActorCriticPolicy):
    """stable-baselines3's ``MlpPolicy`` with the actor reading the first ``actor_dim`` entries of
    the observation and the critic reading all of them (its own features extractor and first
    layer); everything else, parameter names included, as the standard policy."""

    def __init__(self, observation_space: spaces.Box, action_space: spaces.Space, lr_schedule: Any,
                 actor_dim: int, **kwargs: Any) -> None:
        if not 0 < int(actor_dim) < observation_space.shape[0]:
            raise ValueError(f"actor_dim {actor_dim} outside (0, {observation_space.shape[0]})")
        self.actor_dim = int(actor_dim)
        self._actor_extractor_made = False
        kwargs["share_features_extractor"] = False
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)

    def make_features_extractor(self) -> BaseFeaturesExtractor:
        """The actor's extractor (the first call, stable-baselines3's ``features_extractor``), then
        the critic's (the whole observation)."""
        if not self._actor_extractor_made:
            self._actor_extractor_made = True
            return ActorInputs(self.observation_space, self.actor_dim)
        return FlattenExtractor(self.observation_space)

    def _build_mlp_extractor(self) -> None:
        super()._build_mlp_extractor()  # the actor's layers on actor_dim inputs
        critic = MlpExtractor(self.vf_features_extractor.features_dim, net_arch=self.net_arch,
                              activation_fn=self.activation_fn, device=self.device)
        self.mlp_extractor.value_net = critic.value_net

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), "actor_dim": self.actor_dim}


class PartlyFrozenStatistics(RunningMeanStd):
    """Observation statistics whose first ``frozen_dims`` entries keep the mean and variance they
    start with (a policy started from another's weights keeps its input scaling) while the others
    are updated like VecNormalize's own."""

    def __init__(self, frozen: RunningMeanStd, total_dims: int) -> None:
        super().__init__(shape=(total_dims,))
        k = int(np.shape(frozen.mean)[0])
        self.frozen_dims = k
        self.mean[:k] = frozen.mean
        self.var[:k] = frozen.var
        self._rest = RunningMeanStd(shape=(total_dims - k,))
        self.count = self._rest.count

    def update(self, arr: np.ndarray) -> None:
        """Updates the statistics of the entries after ``frozen_dims``."""
        k = self.frozen_dims
        self._rest.update(np.asarray(arr)[:, k:])
        self.mean[k:] = self._rest.mean
        self.var[k:] = self._rest.var
        self.count = self._rest.count
