"""The flat layout's module paths (``accd_gym.vector``, ...) still work: each is the module of its
new home, importing it warns naming the new path, and what was pickled under an old path loads
(without a warning, so also under ``-W error``); every name README.md and docs/*.md use resolves."""

from __future__ import annotations

import importlib
import pickle
import re
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import accd_gym
from accd_gym._aliases import MOVED

ROOT = Path(__file__).resolve().parents[1]

#: Every module of the flat layout but those that stayed (errors, cli, __main__, _core, zoo).
FLAT_LAYOUT = (
    "baselines", "benchmark", "browser", "config", "core_env", "distributed", "env", "evaluation", "fidelity",
    "lqr", "recording", "render", "replay", "rllib", "sb3", "settle", "study", "sweep", "task", "tiers",
    "training", "vector",
)

#: Classes whose instances users pickle or save, by their module in the flat layout.
PICKLED_CLASSES = [
    ("accd_gym.env", "InAirCaptureEnv"),
    ("accd_gym.vector", "InAirCaptureVectorEnv"),
    ("accd_gym.sb3", "AccdVecEnv"),
    ("accd_gym.baselines", "GuidancePolicy"),
    ("accd_gym.baselines", "GuidanceGains"),
    ("accd_gym.baselines", "RandomPolicy"),
    ("accd_gym.baselines", "ZeroPolicy"),
    ("accd_gym.lqr", "LqrPolicy"),
    ("accd_gym.evaluation", "SB3Policy"),
    ("accd_gym.evaluation", "Episode"),
    ("accd_gym.rllib", "RLlibPolicy"),
    ("accd_gym.recording", "Recording"),
    ("accd_gym.tiers", "Tier"),
]


def test_every_module_of_the_flat_layout_has_an_alias_to_an_existing_module():
    assert sorted(MOVED) == sorted(f"accd_gym.{m}" for m in FLAT_LAYOUT)
    for old, new in MOVED.items():
        assert new.rsplit(".", 1)[-1] == old.rsplit(".", 1)[-1] and new != old
        assert importlib.util.find_spec(new) is not None, new


@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_path_is_its_new_module_and_warns_naming_it(old, monkeypatch):
    new = importlib.import_module(MOVED[old])
    monkeypatch.delitem(sys.modules, old, raising=False)
    with pytest.warns(DeprecationWarning, match=re.escape(MOVED[old])) as record:
        module = importlib.import_module(old)
    assert module is new
    assert sys.modules[old] is new
    assert record[0].filename == __file__  # points at the importing code, not at importlib
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert importlib.import_module(old) is new  # once per process


def test_import_statements_and_attribute_access_reach_the_new_modules():
    """In a fresh process (an old path warns once per process, so other tests' imports must not
    have used it up): import statements and attribute access reach the new modules and warn."""
    code = textwrap.dedent(
        """
        import warnings
        import accd_gym
        from accd_gym.envs import tiers, vector

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            import accd_gym.vector as old_vector
            from accd_gym.tiers import TIERS
        messages = [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)]
        assert any("accd_gym.envs.vector" in m for m in messages), messages
        assert any("accd_gym.envs.tiers" in m for m in messages), messages
        assert old_vector is vector and accd_gym.vector is vector
        assert TIERS is tiers.TIERS and accd_gym.tiers is tiers
        try:
            accd_gym.no_such_module
        except AttributeError:
            pass
        else:
            raise AssertionError("accd_gym.no_such_module resolved")
        try:
            from accd_gym import no_such_module  # noqa: F401
        except ImportError:
            pass
        else:
            raise AssertionError("accd_gym.no_such_module imported")
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]


def test_the_aliases_work_in_a_fresh_process_under_w_error():
    code = (
        "import pickle, accd_gym\n"
        "cls = pickle.loads(b'caccd_gym.vector\\nInAirCaptureVectorEnv\\n.')\n"
        "assert cls is accd_gym.InAirCaptureVectorEnv\n"
        "from accd_gym.evals import evaluation\n"
        "try:\n"
        "    import accd_gym.evaluation\n"
        "except DeprecationWarning as e:\n"
        "    assert 'accd_gym.evals.evaluation' in str(e)\n"
        "else:\n"
        "    raise SystemExit('no warning')\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


@pytest.mark.parametrize("module,name", PICKLED_CLASSES)
def test_a_class_pickled_under_its_old_module_loads_quietly(module, name, monkeypatch):
    if module == "accd_gym.sb3":
        pytest.importorskip("stable_baselines3")
    cls = getattr(importlib.import_module(MOVED[module]), name)
    monkeypatch.delitem(sys.modules, module, raising=False)
    blob = f"c{module}\n{name}\n.".encode()  # protocol 0: GLOBAL module name
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert pickle.loads(blob) is cls
        monkeypatch.delitem(sys.modules, module, raising=False)
        assert pickle._loads(blob) is cls  # the pure-Python unpickler too


def _as_flat_layout(blob: bytes) -> bytes:
    """A protocol-2 pickle with every module path of a moved module rewritten to its old path."""
    for old, new in MOVED.items():
        blob = blob.replace(f"c{new}\n".encode(), f"c{old}\n".encode())
    return blob


def test_an_env_pickled_by_the_flat_layout_loads_and_steps_alike(monkeypatch):
    env = accd_gym.InAirCaptureVectorEnv(2, capture_window=1.0, initial={"settle_time": 5.0})
    env.reset(seed=11)
    blob = pickle.dumps(env, protocol=2)
    old = _as_flat_layout(blob)
    assert b"caccd_gym.vector\nInAirCaptureVectorEnv\n" in old and b"accd_gym.envs" not in old
    monkeypatch.delitem(sys.modules, "accd_gym.vector", raising=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        copy = pickle.loads(old)
    assert type(copy) is accd_gym.InAirCaptureVectorEnv
    actions = np.full((2, 4), 0.3, np.float32)
    for _ in range(3):
        a, b = env.step(actions), copy.step(actions)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])


def test_a_policy_pickled_by_the_flat_layout_acts_alike():
    from accd_gym.control.baselines import GuidancePolicy

    policy = GuidancePolicy()
    old = _as_flat_layout(pickle.dumps(policy, protocol=2))
    assert b"caccd_gym.baselines\nGuidancePolicy\n" in old
    copy = pickle.loads(old)
    obs = np.random.default_rng(0).uniform(-1, 1, (3, 25)).astype(np.float32)
    np.testing.assert_array_equal(policy.predict(obs), copy.predict(obs))


def test_registered_ids_point_at_the_new_modules():
    for env_id in [t.id for t in accd_gym.TIERS.values()]:
        spec = gym.spec(env_id)
        for entry, cls in ((spec.entry_point, accd_gym.InAirCaptureEnv),
                           (spec.vector_entry_point, accd_gym.InAirCaptureVectorEnv)):
            module, _, name = entry.partition(":")
            assert module not in MOVED, entry  # gym.make imports it: no deprecation warning
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
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        for name in sorted(names):
            try:
                _resolve(name)
            except (ImportError, AttributeError) as e:
                broken.append(f"{name}: {type(e).__name__}: {e}")
    assert not broken, "names in README.md/docs that do not resolve:\n" + "\n".join(broken)
