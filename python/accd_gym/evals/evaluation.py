"""Held-out evaluation of policies: episodes on fixed wake and initial-condition seeds, metrics, plots.

Every policy sees the same episodes: episode ``k`` is the first episode of a single env seeded
``seed + k`` (initial conditions and RLV motion; ``seed`` is :data:`EVAL_BASE_SEED` by default)
with wake seed ``wake_seeds[k]``, by default the first ``K`` of
:data:`accd_gym.HELD_OUT_WAKE_SEEDS`, which training never draws. That definition depends on
nothing else: not on ``num_envs``, and not on how the episodes are split over Ray workers
(:mod:`accd_gym.evals.distributed`), which therefore reproduce the local results bit for bit (see
:func:`accd_gym.evals.episodes.run_episode_range` for the one condition on the policy).

A *policy* is any object with ``predict(obs_batch) -> actions`` ((N, 25) -> (N, 4)) and
optionally ``reset(mask)`` (or ``start_episodes(mask, episode_indices)``): the baselines of :mod:`accd_gym.control.baselines` and :class:`~accd_gym.evals.policies.SB3Policy`
(a stable-baselines3 model with its VecNormalize statistics).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Optional, Sequence, Callable

import numpy as np

from accd_gym.control.registry import CONTROLLERS
from accd_gym.envs.task import EVENT_NAMES, HELD_OUT_WAKE_SEEDS
from accd_gym.errors import ConfigError
from accd_gym.evals.episodes import EVAL_BASE_SEED, Episode, run_episode_range, run_episodes
from accd_gym.evals.policies import SB3Policy, load_policy
from accd_gym import files
from accd_gym.envs.config import env_config
from accd_gym.evals import distributed
from accd_gym.control.lqr import is_lqr_tuning
from accd_gym.files import save_figure


#: Writes replays of one policy's evaluated episodes: ``(spec, label, episodes, context)`` -> one
#: entry per page written; ``context`` holds the evaluation's ``folder`` (``out/replays``),
#: ``seed``, ``wake_seeds``, ``num_envs``, ``num_threads``, ``config`` and ``allow_unnormalized``.
ReplayWriter = Callable[[str, str, list[Episode], dict[str, Any]], list[dict[str, Any]]]


#: The files :func:`evaluate` writes into its folder (besides ``replays/`` and ``ray_tasks.json``).
EVALUATION_FILES = ("results.json", "summary.md", "trajectories.npz", "trajectories.png", "miss_distance_cdf.png")


def wilson_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % for the default ``z``); (0, 1) for n = 0."""
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def mcnemar_exact(only_a: int, only_b: int) -> float:
    """Two-sided exact McNemar test of paired outcomes: the probability, if both policies
    captured equally often, of a split of the ``only_a + only_b`` discordant episodes (captured
    by one policy only) at least as uneven as the one seen: ``min(1, 2 P(X <= min))`` for
    ``X ~ Binomial(only_a + only_b, 1/2)``; 1 when no episode is discordant. Exact in integer
    arithmetic up to the final division."""
    if only_a < 0 or only_b < 0:
        raise ConfigError(f"invalid config: discordant counts {only_a}, {only_b} are outside the allowed range >= 0")
    n = only_a + only_b
    if n == 0:
        return 1.0
    from math import comb

    tail = sum(comb(n, k) for k in range(min(only_a, only_b) + 1))
    return min(1.0, 2 * tail / 2**n)


def paired_comparisons(runs: dict[str, list["Episode"]]) -> list[dict[str, Any]]:
    """Every pair of policies evaluated on the same episodes: the episodes captured by both, by
    the first only, by the second only, and the exact McNemar p-value (:func:`mcnemar_exact`)."""
    specs = list(runs)
    out = []
    for i, a in enumerate(specs):
        for b in specs[i + 1:]:
            pa = [e.captured for e in runs[a]]
            pb = [e.captured for e in runs[b]]
            both = sum(x and y for x, y in zip(pa, pb))
            only_a = sum(x and not y for x, y in zip(pa, pb))
            only_b = sum(y and not x for x, y in zip(pa, pb))
            out.append({"a": a, "b": b, "both": both, "only_a": only_a, "only_b": only_b,
                        "mcnemar_p": mcnemar_exact(only_a, only_b)})
    return out


def summarize(episodes: Sequence[Episode]) -> dict[str, Any]:
    """Capture rate with its Wilson 95 % interval, miss distance, capture time, tension, flap usage."""
    n = len(episodes)
    caught = [e for e in episodes if e.captured]
    lo, hi = wilson_interval(len(caught), n)
    miss = np.array([e.min_distance for e in episodes])
    times = np.array([e.capture_time for e in caught]) if caught else np.array([])
    peak = np.array([e.peak_tension for e in episodes])
    return {
        "episodes": n,
        "captures": len(caught),
        "capture_rate": len(caught) / n,
        "capture_rate_ci95": [lo, hi],
        "outcomes": {o: sum(e.outcome == o for e in episodes) for o in (*EVENT_NAMES, "truncated")},
        "miss_distance_m": {
            "mean": float(miss.mean()),
            "median": float(np.median(miss)),
            "p90": float(np.percentile(miss, 90)),
            "max": float(miss.max()),
        },
        "capture_time_s": {
            "mean": float(times.mean()) if caught else None,
            "median": float(np.median(times)) if caught else None,
        },
        "peak_tension_N": {"median": float(np.median(peak)), "max": float(peak.max())},
        "mean_abs_action": float(np.mean([e.mean_abs_action for e in episodes])),
        "mean_abs_delta_action": float(np.mean([e.mean_abs_delta_action for e in episodes])),
        "mean_return": float(np.mean([e.episode_return for e in episodes])),
    }


def evaluate(
    policies: Sequence[str],
    episodes: int,
    out: str | Path,
    *,
    wake_seeds: Optional[Sequence[int]] = None,
    seed: int = EVAL_BASE_SEED,
    num_envs: int = 16,
    num_threads: int = 0,
    config: Optional[dict[str, Any]] = None,
    progress: bool = True,
    dpi: int = 90,
    allow_unnormalized: bool = False,
    replay_writer: Optional[ReplayWriter] = None,
    ray_address: Optional[str] = None,
    ray_chunk: Optional[int] = None,
) -> dict[str, Any]:
    """Evaluates each policy spec on the same episodes; writes results.json, summary.md and plots.

    ``wake_seeds`` defaults to the first ``episodes`` held-out wake seeds. Returns the results
    document (also in ``out/results.json``). ``replay_writer`` (e.g.
    :func:`accd_gym.replays.replay.evaluation_replays`) also writes replays of each policy's
    episodes under ``out/replays/``; what it returns goes to the document's ``replays``. ``ray_address``
    (``"local"``, ``"auto"`` or ``HOST:PORT``) runs the episodes as Ray tasks of ``ray_chunk``
    episodes each (:mod:`accd_gym.evals.distributed`): the same results bit for bit, plus
    ``out/ray_tasks.json`` (where each task ran, timings). ``num_threads`` is then per task (0:
    the task's CPUs).
    """
    if not policies:
        raise ConfigError("invalid config: `policy` is empty; give at least one baseline name or model path")
    if episodes > len(HELD_OUT_WAKE_SEEDS) and wake_seeds is None:
        raise ConfigError(
            f"invalid config: `episodes` = {episodes} is outside the allowed range 1..{len(HELD_OUT_WAKE_SEEDS)} (held-out wake seeds)"
        )
    seeds = list(wake_seeds) if wake_seeds is not None else list(HELD_OUT_WAKE_SEEDS[:episodes])

    # before the episodes: a read-only folder or a special file among the outputs is refused at once
    out = files.writable_folder(out, "--out", EVALUATION_FILES)
    loaded = [(spec, load_policy(spec, allow_unnormalized=allow_unnormalized, config=config)) for spec in policies]  # fail early
    results: dict[str, Any] = {
        "episodes": episodes,
        "base_seed": seed,
        "wake_seeds": [seeds[0], seeds[episodes - 1]] if episodes else [],
        "wake_seeds_held_out": all(s in HELD_OUT_WAKE_SEEDS for s in seeds[:episodes]),
        "num_envs": min(num_envs, episodes),
        "config": config or {},
        "policies": {},
    }
    runs: dict[str, list[Episode]] = {}
    if ray_address is not None:
        runs, ray_info = distributed.run_policies(dict(loaded), episodes, seed=seed, wake_seeds=seeds, num_envs=num_envs,
                                                  config=config, address=ray_address, chunk=ray_chunk,
                                                  cpus_per_task=max(1, num_threads), progress=progress)
        files.write_text(out / "ray_tasks.json", json.dumps(ray_info, indent=1))
    for spec, policy in loaded:
        if ray_address is None:
            runs[spec] = run_episodes(policy, episodes, seed=seed, wake_seeds=seeds, num_envs=num_envs,
                                      num_threads=num_threads, config=config, progress=progress, desc=_label(spec))
        eps = runs[spec]
        results["policies"][spec] = {"summary": summarize(eps), "episodes": [e.metrics() for e in eps]}
        if getattr(policy, "note", None):
            results["policies"][spec]["note"] = policy.note
    results["paired"] = paired_comparisons(runs)
    if replay_writer is not None:
        context = {"folder": out / "replays", "seed": seed, "wake_seeds": seeds[:episodes], "num_envs": num_envs,
                   "num_threads": num_threads, "config": config, "allow_unnormalized": allow_unnormalized}
        results["replays"] = {spec: replay_writer(spec, _label(spec), eps, context) for spec, eps in runs.items()}
    # each file atomically: a full disk leaves the previous evaluation's file, never half a file
    files.write_text(out / "results.json", json.dumps(results, indent=1))
    with files.atomic_open(out / "trajectories.npz") as f:
        np.savez_compressed(f, **{f"{_label(s)}__{e.index}": e.trajectory for s, eps in runs.items() for e in eps})
    plot_trajectories(runs, out / "trajectories.png", dpi=dpi)

    radius = env_config(config or {})["boom"]["capture_radius"]
    plot_miss_cdf(runs, out / "miss_distance_cdf.png", dpi=dpi, capture_radius=radius)
    files.write_text(out / "summary.md", summary_markdown(results))
    return results


def _label(spec: str) -> str:
    """A short name for a policy spec (a path's run folder or file stem)."""
    p = Path(spec)
    if spec in CONTROLLERS or not p.exists():
        return spec
    if p.suffix == ".json":
        return f"{'lqr' if is_lqr_tuning(spec) else 'guidance'} ({p.stem})"
    return p.name if p.is_dir() else f"{p.parent.name}/{p.stem}"


def summary_markdown(results: dict[str, Any]) -> str:
    """The markdown table comparing the policies of an :func:`evaluate` results document."""
    lines = [
        f"# Held-out evaluation: {results['episodes']} episodes",
        "",
        f"Wake seeds {results['wake_seeds'][0]}..{results['wake_seeds'][1]} "
        f"({'held out' if results['wake_seeds_held_out'] else 'NOT held out'}), base seed {results['base_seed']}; "
        "every policy sees the same episodes.",
        "",
        "| policy | capture rate | 95 % CI (Wilson) | miss distance median / p90 (m) | time to capture median (s) "
        "| peak tension median / max (kN) | mean abs action | mean abs delta action | outcomes |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for spec, doc in results["policies"].items():
        s = doc["summary"]
        lo, hi = s["capture_rate_ci95"]
        ct = s["capture_time_s"]["median"]
        outcomes = ", ".join(f"{k} {v}" for k, v in s["outcomes"].items() if v)
        lines.append(
            f"| {_label(spec)} | {s['captures']}/{s['episodes']} = {s['capture_rate']:.1%} | {lo:.1%} - {hi:.1%} "
            f"| {s['miss_distance_m']['median']:.2f} / {s['miss_distance_m']['p90']:.2f} "
            f"| {'-' if ct is None else f'{ct:.1f}'} "
            f"| {s['peak_tension_N']['median'] / 1e3:.2f} / {s['peak_tension_N']['max'] / 1e3:.2f} "
            f"| {s['mean_abs_action']:.3f} | {s['mean_abs_delta_action']:.3f} | {outcomes} |"
        )
    if results.get("paired"):
        lines += ["", "Paired on the same episodes (captured by both / by the first only / by the second only; "
                  "exact McNemar test, two-sided):", "",
                  "| policies | both | first only | second only | McNemar p |", "|---|---|---|---|---|"]
        for c in results["paired"]:
            lines.append(f"| {_label(c['a'])} vs {_label(c['b'])} | {c['both']} | {c['only_a']} | {c['only_b']} "
                         f"| {c['mcnemar_p']:.3g} |")
    notes = [f"- {_label(spec)}: {doc['note']}" for spec, doc in results["policies"].items() if doc.get("note")]
    if notes:
        lines += ["", "Notes:", *notes]
    lines += ["", "Plots: `trajectories.png` (capture point minus boom tip, side and top views), "
              "`miss_distance_cdf.png` (minimum distance over each episode)."]
    return "\n".join(lines) + "\n"


def plot_trajectories(runs: dict[str, list[Episode]], path: Path, max_episodes: int = 20, dpi: int = 90) -> None:
    """Side (x, height) and top (x, y) views of capture point minus boom tip, one row per policy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = len(runs)
    fig, axes = plt.subplots(rows, 2, figsize=(11, 3.2 * rows), squeeze=False)
    for r, (spec, eps) in enumerate(runs.items()):
        side, top = axes[r]
        for e in eps[:max_episodes]:
            t = e.trajectory
            colour = "tab:green" if e.captured else "tab:red"
            side.plot(t[:, 0], -t[:, 2], color=colour, lw=0.7, alpha=0.7)
            top.plot(t[:, 0], t[:, 1], color=colour, lw=0.7, alpha=0.7)
            side.plot(t[0, 0], -t[0, 2], "o", color=colour, ms=2)
            top.plot(t[0, 0], t[0, 1], "o", color=colour, ms=2)
        for ax, ylabel in ((side, "height above boom tip, -z (m)"), (top, "starboard of boom tip, y (m)")):
            ax.plot(0, 0, "k+", ms=12, mew=2)
            ax.set_xlabel("ahead of boom tip, x (m)")
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
        side.set_title(f"{_label(spec)}: side view (green captured, red not)", fontsize=9)
        top.set_title(f"{_label(spec)}: top view", fontsize=9)
    fig.tight_layout()

    save_figure(fig, path, dpi=dpi)
    plt.close(fig)


def plot_miss_cdf(runs: dict[str, list[Episode]], path: Path, dpi: int = 90, capture_radius: float = 0.5) -> None:
    """Empirical CDF of the minimum capture-point-to-boom distance per episode, per policy, with the
    capture radius (m) of the evaluated config marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4))
    for spec, eps in runs.items():
        d = np.sort([e.min_distance for e in eps])
        ax.step(d, np.arange(1, len(d) + 1) / len(d), where="post", label=_label(spec))
    ax.axvline(capture_radius, color="k", ls=":", lw=1, label=f"capture radius ({capture_radius:g} m)")
    ax.set_xscale("log")
    ax.set_xlabel("miss distance: minimum distance to the boom tip (m)")
    ax.set_ylabel("fraction of episodes")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()

    save_figure(fig, path, dpi=dpi)
    plt.close(fig)


__all__ = ["EVAL_BASE_SEED", "Episode", "SB3Policy", "evaluate", "load_policy", "run_episode_range", "run_episodes", "summarize", "wilson_interval"]
