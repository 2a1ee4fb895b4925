"""Exports shipped policies' actor networks as plain arrays (``network.npz`` beside their
``final_model.zip``; the format is documented in docs/trained-policies.md), so that evaluating a
shipped policy needs neither PyTorch nor stable-baselines3
(:class:`accd_gym.evals.network.NetworkPolicy`). Training keeps both; this reads the
stable-baselines3 model and its VecNormalize statistics once, here.

    python scripts/export_networks.py                      # every shipped policy
    python scripts/export_networks.py --name residual_sac_hard [--folder DIR]

After writing, each export is checked against PyTorch on observations drawn around the
normalisation statistics: its float64 output against PyTorch's network run in float64 (must agree
within 1e-6; they agree to about 1e-15), and its float32 actions against stable-baselines3's
float32 ``predict``, printed (PyTorch's float32 sums are off by up to a few 1e-6 there).
``scripts/ship_policies.py`` exports the network of each policy it ships.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from accd_gym.errors import ConfigError
from accd_gym.files import write_bytes
from accd_gym.evals.network import FORMAT, NETWORK_FILE, VERSION, Network

#: Largest |output difference| allowed between the exported network and PyTorch's in float64.
TOLERANCE = 1e-6


def _activation(module: Any) -> str:
    """The name of a PyTorch activation module (ConfigError for others)."""
    import torch.nn as nn

    for cls, name in ((nn.ReLU, "relu"), (nn.Tanh, "tanh")):
        if isinstance(module, cls):
            return name
    raise ConfigError(f"invalid config: activation {type(module).__name__} is outside the allowed range [ReLU, Tanh]")


def _mlp(modules: list[Any]) -> list[tuple[Any, str]]:
    """(Linear, activation) pairs of a stable-baselines3 MLP (Linear, activation, Linear, ...)."""
    import torch.nn as nn

    out: list[tuple[Any, str]] = []
    for m in modules:
        if isinstance(m, nn.Linear):
            out.append((m, "identity"))
        elif out and out[-1][1] == "identity":
            out[-1] = (out[-1][0], _activation(m))
        else:
            raise ConfigError(f"invalid config: unexpected module {type(m).__name__} in the policy network")
    return out


def network_arrays(model: Any, algo: str, stats: Any, env: dict[str, Any]) -> dict[str, Any]:
    """The arrays and the JSON ``spec`` of ``model``'s deterministic actor (a loaded PPO or SAC
    model on a Box action space, flat observations), its VecNormalize statistics ``stats`` (or
    None) and the env options ``env`` (residual, history) it was trained with."""
    import torch.nn as nn
    from stable_baselines3.common.torch_layers import FlattenExtractor

    from accd_gym.learning.asymmetric import ActorInputs

    policy = model.policy
    if algo == "sac":
        actor = policy.actor
        if getattr(actor, "use_sde", False):
            raise ConfigError("invalid config: a SAC actor with gSDE is not exportable (its mean is not tanh(mu))")
        layers = _mlp(list(actor.latent_pi)) + [(actor.mu, "identity")]
        extractor = actor.features_extractor
        squash = "tanh"
    elif algo == "ppo":
        layers = _mlp(list(policy.mlp_extractor.policy_net)) + [(policy.action_net, "identity")]
        extractor = policy.pi_features_extractor
        squash = "none"
    else:
        raise ConfigError(f"invalid config: algorithm {algo!r} is outside the allowed range ['ppo', 'sac']")
    dim = int(model.observation_space.shape[0])
    if isinstance(extractor, ActorInputs):  # an asymmetric critic's run: the actor reads the first entries
        dim = extractor.actor_dim
    elif not isinstance(extractor, FlattenExtractor):
        raise ConfigError(f"invalid config: features extractor {type(extractor).__name__} is not exportable "
                          "(only flat observations)")
    if bool(policy.squash_output) != (squash == "tanh"):
        raise ConfigError(f"invalid config: {algo} policy with squash_output={policy.squash_output}")
    arrays: dict[str, Any] = {}
    spec_layers = []
    for k, (linear, act) in enumerate(layers):
        assert isinstance(linear, nn.Linear)
        # Stored (inputs, outputs): the forward pass runs over the input axis.
        arrays[f"layer{k}_weight"] = linear.weight.detach().cpu().numpy().astype(np.float32).T.copy()
        arrays[f"layer{k}_bias"] = linear.bias.detach().cpu().numpy().astype(np.float32).copy()
        spec_layers.append({"weight": f"layer{k}_weight", "bias": f"layer{k}_bias", "activation": act})
    space = model.action_space
    norm = None
    if stats is not None and stats.norm_obs:
        arrays["obs_mean"] = np.asarray(stats.obs_rms.mean, dtype=np.float64)[:dim].copy()
        arrays["obs_var"] = np.asarray(stats.obs_rms.var, dtype=np.float64)[:dim].copy()
        norm = {"mean": "obs_mean", "var": "obs_var", "epsilon": float(stats.epsilon), "clip": float(stats.clip_obs)}
    import stable_baselines3
    import torch

    spec = {
        "format": FORMAT,
        "version": VERSION,
        "algo": algo,
        "observation_dim": dim,
        "action_dim": int(space.shape[0]),
        "normalization": norm,
        "layers": spec_layers,
        "action": {"squash": squash, "low": [float(v) for v in space.low], "high": [float(v) for v in space.high]},
        "env": env,
        "exported_from": {"stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__},
    }
    arrays["spec"] = np.array(json.dumps(spec, sort_keys=True))
    return arrays


def export(folder: Path) -> Path:
    """Writes ``folder/network.npz`` from the folder's ``final_model.zip``, ``vecnormalize.pkl``
    and ``run.json`` (a shipped policy or a training run); returns the file."""
    from accd_gym.envs.agent_io import split_agent_options
    from accd_gym.evals.policies import SB3Policy

    policy = SB3Policy(folder)
    env = split_agent_options(_run_env(folder))[0].to_dict()
    arrays = network_arrays(policy.model, policy.algo, policy.normalizer, env)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    out = folder / NETWORK_FILE
    write_bytes(out, buf.getvalue())
    return out


def _run_env(folder: Path) -> dict[str, Any]:
    from accd_gym.files import read_user_json

    doc = read_user_json(folder / "run.json", "run summary")
    return dict(doc.get("config", {}).get("env", {}))


def torch_actions(model: Any, algo: str, normalized: np.ndarray, double: bool) -> np.ndarray:
    """PyTorch's deterministic actions of ``model`` (PPO or SAC) for normalised observations, as
    ``predict`` computes them (float32), or with the network in float64 (``double``; SAC's
    tanh output and PPO's mean, before any unscaling or clipping)."""
    if not double:
        return np.asarray(model.predict(normalized, deterministic=True)[0], dtype=np.float64)
    import copy

    import torch

    policy = copy.deepcopy(model.policy).double()
    with torch.no_grad():
        x = torch.as_tensor(np.asarray(normalized, dtype=np.float32).astype(np.float64))
        if algo == "sac":
            return torch.tanh(policy.actor.mu(policy.actor.latent_pi(x))).numpy()
        return policy.action_net(policy.mlp_extractor.policy_net(x)).numpy()


def differences(folder: Path, n: int = 4096, seed: int = 0) -> tuple[float, float]:
    """The largest |action difference| between the exported network of ``folder`` and PyTorch on
    ``n`` observations drawn around the normalisation statistics: to PyTorch's network in float64
    (the network's float64 output) and to stable-baselines3's ``predict`` in float32 (the
    network's actions)."""
    from accd_gym.evals.policies import SB3Policy

    sb3 = SB3Policy(folder)
    net = Network(folder)
    obs = sample_observations(sb3.normalizer, net.obs_dim, n, seed)
    normalized = sb3.normalizer.normalize_obs(obs)
    d64 = np.abs(net.outputs(obs) - torch_actions(sb3.model, sb3.algo, normalized, double=True)).max()
    d32 = np.abs(net.actions(obs) - torch_actions(sb3.model, sb3.algo, normalized, double=False)).max()
    return float(d64), float(d32)


def sample_observations(stats: Any, dim: int, n: int, seed: int) -> np.ndarray:
    """``n`` float32 observations around VecNormalize statistics ``stats`` (standard normal
    without them), wide enough that some are clipped by the normalisation."""
    rng = np.random.default_rng(seed)
    z = rng.standard_normal((n, dim)) * 2.0
    if stats is None:
        return z.astype(np.float32)
    return (stats.obs_rms.mean + z * np.sqrt(stats.obs_rms.var)).astype(np.float32)


def main(argv: list[str] | None = None) -> int:
    """Exports and checks the named shipped policies (all by default); 0 when all are within
    :data:`TOLERANCE` of PyTorch's network in float64."""
    from accd_gym.evals.shipped import available, policy_dir

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--name", action="append", help="a shipped policy (repeatable; default: all)")
    ap.add_argument("--folder", action="append", type=Path,
                    help="a policy or run folder (final_model.zip, vecnormalize.pkl, run.json) instead")
    args = ap.parse_args(argv)
    folders = list(args.folder or []) + [policy_dir(n) for n in (args.name or ([] if args.folder else available()))]
    worst = 0.0
    for folder in folders:
        out = export(folder)
        d64, d32 = differences(folder)
        worst = max(worst, d64)
        print(f"exported {out} ({out.stat().st_size} bytes): largest difference to PyTorch in float64 {d64:.2e}, "
              f"to stable-baselines3's float32 predict {d32:.2e}")
    return 0 if worst <= TOLERANCE else 1


if __name__ == "__main__":
    sys.exit(main())
