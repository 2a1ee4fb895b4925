"""The performance targets against one run of ``scripts/bench.sh``, as a markdown table.

Reads what that run wrote: ``physics.json`` (``bench_physics.py``: MuJoCo's bare chain, the
tether and the capture system side by side in one process), ``envs_default.json``
(``bench_envs.py``; the vector envs against the Rust batch from its side-by-side rounds, else
against criterion's ``batch_step``), ``training_default.json`` (``bench_training.py``) from the run's folder, and
criterion's estimates of the batch benchmark (``batch_step/agent_steps/default-n{N}-threads{T}``)
from the cargo target folder. Every row says which file its figure comes from; a missing input
is reported as such, never guessed.

    python scripts/bench_summary.py OUT_DIR [--criterion target/criterion] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
from typing import Any, Optional


def _load(path: pathlib.Path) -> Optional[Any]:
    """The JSON at ``path``, or None when the file is missing."""
    if not path.is_file():
        return None
    with open(path) as f:
        return json.load(f)


def criterion_rates(root: pathlib.Path, n: int) -> dict[int, float]:
    """Agent steps/s of criterion's ``batch_step`` cases with ``n`` envs (default scheme), by
    thread count (``n`` over the mean time of one batch step); empty when criterion has none.
    The thread counts are read from the cases' names (the batch labels them with the threads
    it really uses), not assumed from this machine's core count."""
    rates: dict[int, float] = {}
    cases = root / "batch_step" / "agent_steps"
    for case in cases.glob(f"default-n{n}-threads*") if cases.is_dir() else ():
        threads = case.name.rsplit("threads", 1)[1]
        est = _load(case / "new" / "estimates.json")
        if threads.isdigit() and est is not None:
            rates[int(threads)] = n / (est["mean"]["point_estimate"] * 1e-9)
    return rates


def targets(out: pathlib.Path, criterion: pathlib.Path) -> list[dict[str, Any]]:
    """One row per target: what, the bound, the measured value (None if not measured), met."""
    rows: list[dict[str, Any]] = []

    def row(what: str, bound: str, value: Optional[float], met: Optional[bool], source: str, fmt: str) -> None:
        rows.append({"target": what, "bound": bound, "value": value, "met": met, "source": source, "format": fmt})

    physics = _load(out / "physics.json")
    ratios = physics["ratios"] if physics else {}

    def ratio(name: str) -> Optional[float]:
        return ratios.get(name)

    def at_most(v: Optional[float], b: float) -> Optional[bool]:
        return None if v is None else v <= b

    def at_least(v: Optional[float], b: float) -> Optional[bool]:
        return None if v is None else v >= b

    r = ratio("capture default / tether")
    row("capture-system step / tether step", "<= 2x", r, at_most(r, 2.0), "physics.json", "{:.2f}x")
    r = ratio("mujoco / capture default")
    row("MuJoCo bare chain / capture-system step", ">= 20x", r, at_least(r, 20.0), "physics.json", "{:.1f}x")
    r = ratio("mujoco / tether")
    row("MuJoCo bare chain / tether step", ">= 50x", r, at_least(r, 50.0), "physics.json", "{:.1f}x")
    r = ratio("tether n=300 / n=30 (per step)")
    row("tether n = 300 / n = 30", "<= 11x", r, at_most(r, 11.0), "physics.json", "{:.2f}x")

    envs = _load(out / "envs_default.json")
    python_rates: dict[tuple[str, int], float] = {}
    if envs:
        for e in envs["rows"]:
            python_rates[(e["env"], e["num_envs"])] = e["agent_steps_per_s"]
    vector_names = ("native VectorEnv (gymnasium.make_vec)", "native SB3 AccdVecEnv")
    for n in (16, 256):
        worst = min((python_rates[(v, n)] for v in vector_names if (v, n) in python_rates), default=None)
        row(f"vector envs, N = {n} (the slower of the two)", ">= 25,000 agent steps/s", worst,
            at_least(worst, 25_000.0), "envs_default.json", "{:,.0f}")
        rates = criterion_rates(criterion, n)
        most = max(rates, default=None)
        beside = (envs or {}).get("side_by_side", {}).get(str(n))
        if beside:
            # One process, interleaved rounds: the Rust batch and both envs in the same minutes.
            share = min(beside[v] for v in ("native VectorEnv", "native SB3 AccdVecEnv")) / beside["rust batch"]
            source = "envs_default.json, side by side"
        else:
            rust = None if most is None else rates[most]
            share = None if (worst is None or rust is None) else worst / rust
            source = "envs_default.json, criterion"
        row(f"vector envs / Rust batch, N = {n}", ">= 0.90", share, at_least(share, 0.9), source, "{:.2f}")
        one = rates.get(1)
        scaling = None if (one is None or most is None or most == 1) else rates[most] / one
        row(f"Rust batch 1 -> {most or 'all'} threads, N = {n}", ">= 1.8x", scaling, at_least(scaling, 1.8),
            "criterion", "{:.2f}x")

    training = _load(out / "training_default.json")
    ppo = training["accd env"]["agent_steps_per_s"] if training else None
    row("PPO with training/ppo.json, end to end", ">= 8,000 agent steps/s", ppo, at_least(ppo, 8000.0),
        "training_default.json", "{:,.0f}")
    return rows


def markdown(rows: list[dict[str, Any]]) -> str:
    """The rows as a markdown table."""
    lines = ["| target | bound | measured | met | from |", "|---|---|---|---|---|"]
    for r in rows:
        value = "not measured" if r["value"] is None else r["format"].format(r["value"])
        met = "-" if r["met"] is None else ("yes" if r["met"] else "no")
        lines.append(f"| {r['target']} | {r['bound']} | {value} | {met} | {r['source']} |")
    return "\n".join(lines)


def main() -> None:
    """Prints the targets table of one ``bench.sh`` run (and writes it as JSON with ``--json``)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", help="the folder bench.sh wrote (physics.json, envs_default.json, ...)")
    target_dir = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", "target"))
    p.add_argument("--criterion", default=str(target_dir / "criterion"), help="criterion's output folder")
    p.add_argument("--json", help="write the rows here")
    a = p.parse_args()
    rows = targets(pathlib.Path(a.out), pathlib.Path(a.criterion))
    print(markdown(rows))
    if a.json:
        with open(a.json, "w") as f:
            json.dump([{k: v for k, v in r.items() if k != "format"} for r in rows], f, indent=2)


if __name__ == "__main__":
    main()
