"""Smoke test of an installed accd-gym wheel in an environment without a Rust toolchain: what a
user who installed the wheel does first. scripts/test.sh runs it in a fresh virtual environment of
the newest Python on the machine; .github/workflows/release.yml runs it on every platform's wheel.

1. **installed, not built**: no ``cargo`` or ``rustc`` on PATH; ``accd_gym`` imported from the
   environment's site-packages (not from a source tree) with its extension built against the
   stable ABI (``_core.abi3.so``, or ``_core.pyd`` on Windows);
2. **the README's quick start**: the first Python block under ``## Quick start`` of README.md,
   run as written;
3. **the command line**: ``accd-gym rollout --policy lqr`` through the console script the wheel
   installed;
4. **gymnasium's checker**: ``gymnasium.utils.env_checker.check_env`` on every registered
   ``accd_gym/`` id (one per tier), warnings as errors;
5. **the shipped policies**: each loads from the installed package as its exported network and
   runs the first ``--episodes`` of its stored held-out check episodes exactly as stored
   (outcome, steps and miss distance to the last bit: the physics, the LQR and the network are
   fixed-order arithmetic, whatever the CPU, the batch size or the libraries), without importing
   PyTorch or stable-baselines3 (installed or not).

Usage: python scripts/wheel_smoke.py [--readme README.md] [--episodes K]
Prints each check's wall time; exits non-zero on the first failure.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def check_installed() -> None:
    """No Rust toolchain on PATH; accd_gym from site-packages with a stable-ABI extension."""
    found = {tool: shutil.which(tool) for tool in ("cargo", "rustc")}
    assert not any(found.values()), f"a Rust toolchain is on PATH: {found}"
    import accd_gym
    from accd_gym import _core

    site = Path(sysconfig.get_paths()["purelib"]).resolve()
    package = Path(accd_gym.__file__).resolve().parent
    assert site in package.parents, f"accd_gym imported from {package}, not from {site}"
    extension = Path(_core.__file__).name
    assert extension in ("_core.abi3.so", "_core.pyd"), f"the extension {extension} is not a stable-ABI build"
    print(f"accd_gym {accd_gym.__version__} from {package}, extension {extension}, Python {sys.version.split()[0]}")


def readme_quick_start(readme: Path) -> str:
    """The first ```python block after the ``## Quick start`` heading of ``readme``."""
    text = readme.read_text(encoding="utf-8")
    section = text.split("\n## Quick start\n", 1)
    assert len(section) == 2, f"{readme} has no '## Quick start' section"
    block = re.search(r"```python\n(.*?)```", section[1], re.DOTALL)
    assert block, f"{readme}'s quick start has no python block"
    return block.group(1)


def check_quick_start(readme: Path) -> None:
    """Runs the README's quick-start loop in a fresh interpreter; it prints the episode's end."""
    out = subprocess.run([sys.executable, "-c", readme_quick_start(readme)], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "captured=" in out.stdout, out.stdout
    print(out.stdout.strip())


def check_rollout() -> None:
    """``accd-gym rollout --policy lqr`` through the installed console script."""
    script = Path(sysconfig.get_paths()["scripts"]) / ("accd-gym.exe" if os.name == "nt" else "accd-gym")
    assert script.exists(), f"the console script {script} is missing"
    out = subprocess.run([str(script), "rollout", "--policy", "lqr", "--episodes", "4", "--num-envs", "4", "--quiet"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    print(out.stdout.strip().splitlines()[-1] if out.stdout.strip() else "(no output)")


def check_envs() -> None:
    """gymnasium's env checker on every registered accd_gym id, warnings as errors."""
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    import accd_gym  # noqa: F401  (registers the ids)

    ids = sorted(i for i in gym.registry if i.startswith("accd_gym/"))
    assert len(ids) >= 5, f"expected one id per tier, found {ids}"
    for env_id in ids:
        env = gym.make(env_id)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(env.unwrapped, skip_render_check=True)
        env.close()
    print(f"check_env passed: {', '.join(ids)}")


_CHECK = """
import json, sys
from accd_gym import trained
n = int(sys.argv[1])
out = {name: [[e.index, e.outcome, e.steps, e.min_distance, bool(e.captured)]
              for e in trained.held_out_episodes(name, n, num_envs=n)] for name in trained.available()}
print(json.dumps({"episodes": out, "imported": sorted(m for m in ("torch", "stable_baselines3") if m in sys.modules)}))
"""


def check_shipped(episodes: int) -> None:
    """Each shipped policy runs the first ``episodes`` of its stored check episodes exactly as
    stored, in a fresh interpreter that imports neither PyTorch nor stable-baselines3."""
    from accd_gym import trained

    docs = {name: trained.info(name) for name in trained.available()}
    assert docs, "no shipped policy in the installed package"
    out = subprocess.run([sys.executable, "-c", _CHECK, str(episodes)], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    doc = json.loads(out.stdout.splitlines()[-1])
    assert doc["imported"] == [], f"evaluating the shipped policies imported {doc['imported']}"
    for name, info in docs.items():
        stored = info["check_episodes"][:episodes]
        got = doc["episodes"][name]
        assert len(got) == len(stored) == episodes, (name, len(got), len(stored))
        for (index, outcome, steps, distance, captured), s in zip(got, stored):
            assert (index, outcome, steps, distance) == (s["index"], s["outcome"], s["steps"], s["min_distance"]), \
                (name, (index, outcome, steps, distance), s)
            assert captured == (info["held_out"]["captured"][index] == "1"), (name, index)
        print(f"{name}: {episodes} check episodes as stored (outcome, steps, miss distance)")


def main() -> None:
    """Runs every check in order, timing each."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readme", type=Path, default=ROOT / "README.md", help="the README whose quick start runs")
    parser.add_argument("--episodes", type=int, default=3, help="held-out episodes per shipped policy (default 3)")
    args = parser.parse_args()
    checks = [("installed wheel", check_installed), ("README quick start", lambda: check_quick_start(args.readme)),
              ("accd-gym rollout --policy lqr", check_rollout), ("check_env on every tier", check_envs),
              ("shipped policies", lambda: check_shipped(args.episodes))]
    total = time.perf_counter()
    for name, check in checks:
        t0 = time.perf_counter()
        print(f"== {name}", flush=True)
        check()
        print(f"   {time.perf_counter() - t0:.1f} s", flush=True)
    print(f"wheel smoke test passed in {time.perf_counter() - total:.1f} s")


if __name__ == "__main__":
    main()
