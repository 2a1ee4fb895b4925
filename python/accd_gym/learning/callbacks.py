"""stable-baselines3 callbacks of the training recipes (imports stable-baselines3 and torch).

:class:`ZeroActionInit` starts a policy at zero actions: with residual control
(:mod:`accd_gym.envs.residual`) the agent then starts as its base controller, bit for bit, and
learns a correction from there. ``accd-gym train`` adds it for ``"zero_action_init": true``;
rl-zoo3 takes it as ``callback: accd_gym.learning.callbacks.ZeroActionInit`` (the residual recipes of
:mod:`accd_gym.zoo` do).
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.running_mean_std import RunningMeanStd


class FrozenStatistics(RunningMeanStd):
    """Observation statistics that stepping does not update: a policy started from another's
    weights (``init_from``) keeps the input scaling it was trained with. A feature that hardly
    varied in the teacher's episodes has a tiny variance there; updated by the fine-tuning's
    exploratory episodes, its scaling would change by orders of magnitude and the inherited
    policy would see other inputs than it learned on."""

    def update(self, arr: np.ndarray) -> None:
        """Leaves the statistics as they are."""

    @classmethod
    def of(cls, stats: RunningMeanStd) -> "FrozenStatistics":
        """A frozen copy of ``stats``."""
        out = cls(shape=np.shape(stats.mean))
        out.mean = np.array(stats.mean, copy=True)
        out.var = np.array(stats.var, copy=True)
        out.count = float(stats.count)
        return out


class CriticWarmup(BaseCallback):
    """Trains only the critic for the first ``steps`` environment steps of a PPO run started from
    another policy's weights (``init_from`` with ``critic_warmup``): the actor (hidden layers,
    action layer, log std) is frozen, so that the advantages of its first updates come from a
    critic that has learned the inherited policy's values, not from a random one."""

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.steps = int(steps)

    def _actor(self) -> list:
        policy = self.model.policy
        return [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters(), policy.log_std]

    def _freeze(self, frozen: bool) -> None:
        for param in self._actor():
            param.requires_grad_(not frozen)

    def _on_training_start(self) -> None:
        self._freeze(self.model.num_timesteps < self.steps)

    def _on_rollout_start(self) -> None:
        if self.model.num_timesteps >= self.steps:
            self._freeze(False)

    def _on_step(self) -> bool:
        return True


def zero_action_init(model, log_std: Optional[float] = None) -> None:
    """Zeroes the last layer of ``model``'s action mean (PPO, A2C: ``policy.action_net``; SAC,
    TQC: ``actor.mu``), so that its deterministic action is exactly zero for every observation.
    For SAC/TQC without gSDE the log-std layer is made constant at ``log_std`` (weights zero,
    bias ``log_std``) when given (PPO's initial std is ``policy_kwargs.log_std_init``).
    TypeError for a model with neither layer."""
    policy = model.policy
    with torch.no_grad():
        if hasattr(policy, "action_net"):
            layer = policy.action_net
        elif hasattr(policy, "actor") and hasattr(policy.actor, "mu"):
            layer = policy.actor.mu
            std = getattr(policy.actor, "log_std", None)
            if log_std is not None and isinstance(std, torch.nn.Linear):
                std.weight.zero_()
                std.bias.fill_(float(log_std))
        else:
            raise TypeError(f"zero_action_init: {type(policy).__name__} has no action_net or actor.mu")
        if isinstance(layer, torch.nn.Sequential):  # SAC's mu with gSDE: Linear (+ Hardtanh)
            layer = layer[0]
        layer.weight.zero_()
        layer.bias.zero_()


class ZeroActionInit(BaseCallback):
    """At the start of a fresh training (no steps yet), :func:`zero_action_init` on the model,
    with ``log_std`` from the model's ``policy_kwargs.log_std_init`` (SAC/TQC)."""

    def _on_training_start(self) -> None:
        if self.model.num_timesteps == 0:
            zero_action_init(self.model, self.model.policy_kwargs.get("log_std_init"))

    def _on_step(self) -> bool:
        return True


__all__ = ["ZeroActionInit", "zero_action_init"]
