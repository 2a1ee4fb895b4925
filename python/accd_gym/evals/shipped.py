"""The catalog of the trained policies shipped with the package: one folder per policy under
``accd_gym/trained/`` (``final_model.zip``, ``vecnormalize.pkl``, the training run's ``run.json``,
``policy.json``, what :func:`info` returns, and ``network.npz``, the exported actor network). Needs
neither stable-baselines3 nor the env, so the policy resolver
(:func:`accd_gym.evals.policies.load_policy`) resolves names through it; :mod:`accd_gym.trained` is
the users' interface to the same catalog."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from accd_gym.errors import ConfigError
from accd_gym.files import read_user_json

#: The folder holding one subfolder per shipped policy (the package data of :mod:`accd_gym.trained`).
TRAINED_DIR: Path = Path(__file__).resolve().parent.parent / "trained"

#: The files every shipped policy's folder holds.
POLICY_FILES: tuple[str, ...] = ("final_model.zip", "vecnormalize.pkl", "run.json", "policy.json", "network.npz")


def available() -> list[str]:
    """The names of the shipped policies, sorted."""
    return sorted(p.name for p in TRAINED_DIR.iterdir() if p.is_dir() and (p / "policy.json").is_file())


def policy_dir(name: str) -> Path:
    """The folder of shipped policy ``name``; ConfigError naming the value and the shipped names."""
    names = available()
    if name not in names:
        raise ConfigError(f"invalid config: trained policy {name!r} is outside the allowed range {names}")
    return TRAINED_DIR / name


def info(name: str) -> dict[str, Any]:
    """What shipped policy ``name`` is: tier, algorithm, seed, steps, source run, env options and
    its recorded held-out result (``policy.json``)."""
    doc = read_user_json(policy_dir(name) / "policy.json", "trained policy metadata")
    if not isinstance(doc, dict):
        raise ConfigError(f"invalid config: {str(policy_dir(name) / 'policy.json')!r} is not a JSON object")
    return doc


def is_trained(spec: str) -> bool:
    """Whether ``spec`` names a shipped policy: one of :func:`available`, not a path, and no file or
    folder of that name in the working folder (a path the user has wins over a shipped name)."""
    return "/" not in spec and "\\" not in spec and spec in available() and not Path(spec).exists()
