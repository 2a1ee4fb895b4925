"""Trained policies shipped with the package, by name, like rl-baselines3-zoo's trained agents.

Each is a stable-baselines3 model with its VecNormalize statistics and the env options it was
trained with (residual control, observation history), copied from a training run by
``scripts/ship_policies.py`` with its recorded held-out result (docs/trained-policies.md), and
its actor network exported as plain arrays (``network.npz``, :mod:`accd_gym.evals.network`),
which is what evaluates it: in fixed-order arithmetic, the same actions on every CPU, with
neither PyTorch nor stable-baselines3 installed::

    from accd_gym import trained
    trained.available()        # ['residual_ppo_hard', 'residual_ppo_precision', 'residual_sac_hard', ...]
    trained.info("residual_sac_hard")["tier"]          # 'hard'
    policy = trained.load_policy("residual_sac_hard")  # predict(obs) -> flap commands
    episodes = trained.held_out_episodes("residual_sac_hard", 20)

On the command line: ``accd-gym evaluate --policy residual_sac_hard`` (its tier unless
``--tier`` says otherwise); ``rollout`` and ``replay`` take the name too. The
stable-baselines3 model itself (``backend="torch"``, e.g. to fine-tune it) needs
``pip install 'accd-gym[sb3]'``.
"""

from __future__ import annotations

from typing import Any, Optional

from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS, check_count
from accd_gym.errors import ConfigError
from accd_gym.evals.episodes import Episode, run_episodes
from accd_gym.evals.network import NetworkPolicy
from accd_gym.evals.policies import SB3Policy
from accd_gym.evals.shipped import TRAINED_DIR, available, info, is_trained, policy_dir

__all__ = ["TRAINED_DIR", "available", "info", "is_trained", "load_policy", "held_out_episodes", "policy_dir"]


def _tier_config(name: str, config: Optional[dict[str, Any]]) -> dict[str, Any]:
    """``config`` (env overrides) over the shipped policy's tier."""
    return {"tier": info(name)["tier"], **(config or {})}


def load_policy(name: str, config: Optional[dict[str, Any]] = None, device: str = "cpu",
                backend: str = "network") -> Any:
    """Shipped policy ``name`` (deterministic, ``predict(obs) -> flap commands``) for the env
    configuration ``config`` (overrides over the policy's tier; its base controller is designed
    for it). ``backend="network"``: its exported network
    (:class:`accd_gym.evals.network.NetworkPolicy`, no PyTorch); ``"torch"``: the
    stable-baselines3 model on PyTorch device ``device``
    (:class:`accd_gym.evals.policies.SB3Policy`), whose actions agree with the network's to
    float32 rounding (docs/trained-policies.md)."""
    if backend == "network":
        return NetworkPolicy(policy_dir(name), config=_tier_config(name, config))
    if backend != "torch":
        raise ConfigError(f"invalid config: backend {backend!r} is outside the allowed range ['network', 'torch']")
    return SB3Policy(policy_dir(name), device=device, config=_tier_config(name, config))


def held_out_episodes(name: str, n: int, num_envs: int = 50, num_threads: int = 0, backend: str = "network") -> list[Episode]:
    """The first ``n`` of the benchmark's held-out episodes of shipped policy ``name`` on its
    tier (episode k: seed ``EVAL_BASE_SEED + k``, held-out wake seed k, as ``accd-gym evaluate``),
    as :class:`accd_gym.evals.episodes.Episode` s in index order; ``backend`` as
    :func:`load_policy`'s."""
    n = check_count(n, "n", 1, len(HELD_OUT_WAKE_SEEDS))
    config = _tier_config(name, None)
    policy = load_policy(name, config, backend=backend)
    return run_episodes(policy, n, wake_seeds=list(HELD_OUT_WAKE_SEEDS[:n]), num_envs=num_envs,
                        num_threads=num_threads, config=config)
