"""The arithmetic's build: named by ``accd_gym.arithmetic()``, chosen by ``ACCD_GYM_ARITHMETIC``.

Both builds compute the same bits (``tests/test_physics_hash.py`` runs under both in
``scripts/test.sh``); here only the variable's handling.
"""

import os
import subprocess
import sys

import accd_gym


def _import_with(value: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "ACCD_GYM_ARITHMETIC": value}
    code = "import accd_gym; print(accd_gym.arithmetic())"
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)


def test_the_build_in_use_is_named():
    assert accd_gym.arithmetic() in ("native", "portable")


def test_portable_is_taken_when_asked():
    done = _import_with("portable")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "portable"


def test_a_misspelt_value_fails_on_import_naming_it():
    done = _import_with("portabel")
    assert done.returncode != 0
    assert "ConfigError" in done.stderr
    assert "ACCD_GYM_ARITHMETIC" in done.stderr and "portabel" in done.stderr
    assert "native, portable" in done.stderr
