"""The public names: every registered env id's entry points are the env classes, and every
``accd_gym...`` name README.md and docs/*.md use resolves (the package has one path per module;
nothing is aliased)."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import gymnasium as gym

import accd_gym

ROOT = Path(__file__).resolve().parents[1]


def test_registered_ids_point_at_the_env_classes():
    for env_id in [t.id for t in accd_gym.TIERS.values()]:
        spec = gym.spec(env_id)
        for entry, cls in ((spec.entry_point, accd_gym.InAirCaptureEnv),
                           (spec.vector_entry_point, accd_gym.InAirCaptureVectorEnv)):
            module, _, name = entry.partition(":")
            assert getattr(importlib.import_module(module), name) is cls


# -- every name the documentation uses ---------------------------------------------------------

def _documents() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _documented_names() -> set[str]:
    """Dotted ``accd_gym.X.Y`` names and ``from accd_gym... import a, b`` imports of the docs."""
    names: set[str] = set()
    for doc in _documents():
        text = doc.read_text()
        names.update(re.findall(r"\baccd_gym(?:\.[A-Za-z_][A-Za-z0-9_]*)+", text))
        for base, imported in re.findall(r"^\s*from (accd_gym[\w.]*) import ([\w, ]+)", text, re.M):
            names.update(f"{base}.{n.split(' as ')[0].strip()}" for n in imported.split(",") if n.strip())
    return names


def _resolve(dotted: str) -> object:
    """The object a dotted name names: its longest importable module prefix, then attributes."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(dotted)


def test_every_name_the_docs_use_resolves():
    names = _documented_names()
    assert len(names) > 20, names  # the docs were found and read
    assert "accd_gym.InAirCaptureEnv" in names
    broken = []
    for name in sorted(names):
        try:
            _resolve(name)
        except (ImportError, AttributeError) as e:
            broken.append(f"{name}: {type(e).__name__}: {e}")
    assert not broken, "names in README.md/docs that do not resolve:\n" + "\n".join(broken)
