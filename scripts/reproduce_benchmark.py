"""Re-evaluates a benchmark folder's runs and baselines on the first N of their held-out episodes
in this process and compares each episode's record (captured, outcome, miss distance, closing
speeds, capture time) bit for bit with the records stored in the folder (each run's result.json, each baseline's file under
baselines/): the check that the
benchmark's rows reproduce with this machine, Python, numpy, SciPy and PyTorch, under this
arithmetic (``ACCD_GYM_ARITHMETIC``), BLAS kernel choice (``OPENBLAS_CORETYPE``) and PyTorch
thread count. Exit status 1 when any episode differs.

    python scripts/reproduce_benchmark.py [--results runs/benchmark] [--episodes 100]
        [--torch-threads 1] [--only NAME,NAME] [--skip-baselines mpc] [--out FILE]
"""

import argparse
import fnmatch
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from accd_gym.evals import benchmark
from accd_gym.evals.policies import load_policy

FIELDS = ("captured", "outcome", "min_distance", "closest_speed", "final_speed", "capture_time")


def versions() -> dict:
    """The software and settings the numbers were computed with."""
    out = {"python": platform.python_version(), "numpy": np.__version__,
           "machine": f"{platform.machine()} {platform.processor() or platform.platform()}, {os.cpu_count()} CPUs",
           "ACCD_GYM_ARITHMETIC": os.environ.get("ACCD_GYM_ARITHMETIC"),
           "OPENBLAS_CORETYPE": os.environ.get("OPENBLAS_CORETYPE")}
    try:  # SciPy is a test-only dependency: nothing evaluated here uses it
        import scipy

        out["scipy"] = scipy.__version__
    except ImportError:
        out["scipy"] = None
    try:
        import torch

        out |= {"torch": torch.__version__, "torch_threads": torch.get_num_threads()}
    except ImportError:
        out["torch"] = None
    return out


def differences(stored: dict, fresh: dict, n: int) -> list[dict]:
    """The episodes among the first ``n`` whose fields differ in any bit (floats compared as
    stored by JSON, which writes every double exactly)."""
    fresh = json.loads(json.dumps(fresh))
    out = []
    for i in range(n):
        a = {f: stored[f][i] for f in FIELDS}
        b = {f: fresh[f][i] for f in FIELDS}
        if a != b:
            out.append({"episode": i, "stored": a, "now": b})
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--results", default="runs/benchmark", help="benchmark folder (its runs/*/result.json and baselines/*.json)")
    p.add_argument("--episodes", type=int, default=100, help="the first N held-out episodes of each run and baseline")
    p.add_argument("--torch-threads", type=int, default=0, help="PyTorch's thread count (0: its default)")
    p.add_argument("--only", default="", help="comma-separated glob patterns of run / baseline names (tier_name)")
    p.add_argument("--skip-baselines", default="", help="comma-separated baseline names not to re-evaluate")
    p.add_argument("--out", default=None, help="also write the summary to this JSON file")
    args = p.parse_args()
    if args.torch_threads:
        import torch

        torch.set_num_threads(args.torch_threads)
    folder = Path(args.results)
    patterns = [x for x in args.only.split(",") if x]
    skip = {x for x in args.skip_baselines.split(",") if x}
    todo = []  # (name, tier, what to load, stored record, batch size): from each run's and baseline's own store
    for path in sorted(folder.glob("runs/*/" + benchmark.RESULT_FILE)):
        stored = json.loads(path.read_text())
        r = stored["result"]
        todo.append((r["name"], r["job"]["tier"], ("run", path.parent), r["episodes"], stored["key"]["num_envs"]))
    for path in sorted(folder.glob("baselines/*.json")):
        stored = json.loads(path.read_text())
        name, tier = stored["key"]["baseline"], path.stem[: -len(stored["key"]["baseline"]) - 1]
        if name not in skip:
            todo.append((f"{tier}_{name}", tier, ("baseline", name), stored["record"], stored["key"]["num_envs"]))
    if patterns:
        todo = [t for t in todo if any(fnmatch.fnmatch(t[0], pat) for pat in patterns)]
    n = min([args.episodes, *(len(t[3]["captured"]) for t in todo)])

    summary = {"results": str(folder), "episodes_each": n, "versions": versions(), "checked": [], "differ": {}}
    t0 = time.perf_counter()
    for name, tier, (kind, what), record, num_envs in todo:
        # a baseline is built for its tier, as the benchmark builds it
        policy = load_policy(str(what)) if kind == "run" else load_policy(what, 0, config={"tier": tier})
        fresh = benchmark.evaluate_policy(policy, tier, n, num_envs)
        diff = differences(record, fresh, n)
        summary["checked"].append(name)
        if diff:
            summary["differ"][name] = {"episodes": len(diff), "first": diff[0]}
        print(f"{name}: {'SAME' if not diff else f'{len(diff)} of {n} episodes differ'}", flush=True)
    summary["wall_s"] = round(time.perf_counter() - t0, 1)
    summary["episodes_checked"] = n * len(summary["checked"])
    text = json.dumps(summary, indent=1)
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    return 1 if summary["differ"] else 0


if __name__ == "__main__":
    sys.exit(main())
