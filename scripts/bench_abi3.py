"""Agent steps per second of two builds of the extension in one process: the installed
``accd_gym._core`` (the stable-ABI build) against another build of it given by path (built for
one interpreter version: ``maturin build --profile ci --no-default-features --features lockstep``,
its ``_core.cpython-3XX-*.so`` taken out of the wheel). Each case steps the native batch
(``BatchEnv.step``, one crossing of the Python boundary per agent step, as the vector envs make)
for N = 1, 16 and 256 envs, in interleaved rounds, best round of each build: on a shared machine
other load only ever slows a round.

Usage: python scripts/bench_abi3.py OTHER_SO [--rounds R] [--seconds S] [--threads T]
"""

from __future__ import annotations

import argparse
import importlib.machinery
import importlib.util
import time

import numpy as np

from accd_gym import _core
from accd_gym.envs.config import valid_config


def load_other(path: str):
    """The extension at ``path``, loaded beside the installed one (its init function is also
    ``PyInit__core``, so the module name ends in ``_core``)."""
    loader = importlib.machinery.ExtensionFileLoader("other._core", path)
    spec = importlib.util.spec_from_file_location("other._core", path, loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def rate(core, n: int, seconds: float, threads: int) -> float:
    """Agent steps per second of ``core.BatchEnv`` with ``n`` envs over about ``seconds``."""
    config = core.EnvConfig(valid_config().to_json())
    batch = core.BatchEnv(config, n, 0, "same_step", threads)
    batch.reset(0)
    actions = (((np.arange(n * 4) % 7) - 3) / 4.0).astype(np.float32).reshape(n, 4)
    batch.step(actions)
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        batch.step(actions)
        steps += 1
    return steps * n / (time.perf_counter() - t0)


def main() -> None:
    """Prints one row per N: the best round of each build and their ratio."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("other", help="path of the other build's extension module")
    parser.add_argument("--rounds", type=int, default=10, help="interleaved rounds (default 10)")
    parser.add_argument("--seconds", type=float, default=0.5, help="time per case and round, s (default 0.5)")
    parser.add_argument("--threads", type=int, default=1, help="batch threads (default 1)")
    args = parser.parse_args()
    other = load_other(args.other)
    print(f"installed: {_core.__file__}\nother: {other.__file__}")
    print("| N | installed, agent steps/s | other, agent steps/s | installed / other |\n|---|---|---|---|")
    for n in (1, 16, 256):
        best = {"installed": 0.0, "other": 0.0}
        for _ in range(args.rounds):
            best["installed"] = max(best["installed"], rate(_core, n, args.seconds, args.threads))
            best["other"] = max(best["other"], rate(other, n, args.seconds, args.threads))
        print(f"| {n} | {best['installed']:,.0f} | {best['other']:,.0f} | {best['installed'] / best['other']:.3f} |",
              flush=True)


if __name__ == "__main__":
    main()
