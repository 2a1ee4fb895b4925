"""The physics fingerprint: every output of a fixed set of episodes is unchanged.

``scripts/physics_hash.py`` hashes 8 envs x 700 agent steps under the default and the precision
configurations with the guidance controller and with seeded random flaps. The recorded hashes in
``tests/data/physics_hashes.json`` are those of the exact air scheme (``exact/*`` and
``exact_precision/*``) and of the default fast scheme (``default/*`` and ``precision/*``; the two
schemes compared in docs/decisions.md). A change of the numerical scheme must be measured,
documented and recorded here on purpose. The same hashes must come out of a process started
with ``ACCD_GYM_ARITHMETIC=portable`` (the code path of a processor without AVX2 and FMA).
"""

import importlib.util
import json
import os
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("physics_hash", ROOT / "scripts" / "physics_hash.py")
physics_hash = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(physics_hash)


def test_every_output_of_the_fixed_episodes_is_unchanged():
    recorded = json.loads((ROOT / "tests" / "data" / "physics_hashes.json").read_text())
    assert physics_hash.hashes() == recorded


def test_the_exact_scheme_keeps_its_recorded_hashes():
    """The exact air scheme's hashes are those recorded when the physics took one arithmetic on
    every processor (fused multiply-adds in every build, libm's transcendental functions;
    docs/decisions.md): only a change of the physics on purpose may re-record them."""
    recorded = json.loads((ROOT / "tests" / "data" / "physics_hashes.json").read_text())
    assert recorded["exact/guidance"] == "fb0e57054d0219d669f83e90a27adb09a3ae00f7ecc5caa86035ea41df5e909d"
    assert recorded["exact_precision/guidance"] == "8f0dee1123e9dc697e0e5371a6b9b1254c51530661d63b16799327d842740559"
    assert recorded["exact/random"] == "ed4e60f42d58448c765795cd1cddf993bda41ef1158353c09498f6955e70c1e4"
    assert recorded["exact_precision/random"] == "6dfe868539e4b3b7fc52fbcdb14ba1c6cd4a361efdea1f619ab2d35683d05b63"


def test_the_portable_arithmetic_gives_the_recorded_fingerprints():
    """A process that takes the code path of a processor without AVX2 and FMA
    (``ACCD_GYM_ARITHMETIC=portable``, read once when the extension loads) hashes the same."""
    recorded = json.loads((ROOT / "tests" / "data" / "physics_hashes.json").read_text())
    done = subprocess.run([sys.executable, str(ROOT / "scripts" / "physics_hash.py")], capture_output=True,
                          text=True, env={**os.environ, "ACCD_GYM_ARITHMETIC": "portable"}, timeout=600)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == recorded
