"""Held-out evaluation fanned out over a Ray cluster (``pip install 'accd-gym[ray]'``).

``accd-gym evaluate ... --ray local`` (a Ray instance on this machine) or ``--ray ADDRESS``
(``auto`` or ``HOST:PORT`` of a running cluster) runs :func:`accd_gym.evals.evaluation.evaluate` with
the episodes split into contiguous index ranges, one Ray task per range. Each task builds its
own native vector env of the evaluation's batch size and runs its range with
:func:`accd_gym.evals.evaluation.run_episode_range`; since episode ``k``'s seeds (``seed + k``,
``wake_seeds[k]``) and the policy's batch size do not depend on the split, the gathered episodes
are bitwise those of the local evaluation, whatever the number of workers or tasks, and
``results.json`` and ``summary.md`` are byte for byte the same. Where each task ran and how long
it took goes to ``ray_tasks.json`` beside them.

Lost workers: every task has ``max_retries`` (Ray re-runs a task whose worker process or node
died); results are gathered by episode index, so a range delivered twice is counted once (and
must be identical), and a range that fails after its retries is an error naming it, never a
silent gap.

Policies travel to the workers pickled: baselines as they are, trained models
(:class:`~accd_gym.evals.evaluation.SB3Policy`, :class:`accd_gym.learning.rllib.RLlibPolicy`) as the contents
of their files, so the workers need no shared filesystem. Each task unpickles its own copy, so
per-env state (the guidance integrators) never crosses ranges.

Ray stays optional: importing this module does not import Ray; the functions that need it do.
"""

from __future__ import annotations

import copy
import math
import os
import socket
import time
from typing import Any, Optional, Sequence

from accd_gym import files
from accd_gym.errors import ConfigError
from accd_gym.learning.ray_cluster import connect
from accd_gym.evals.episodes import run_episode_range

#: Retries of a task whose worker died (Ray's ``max_retries``).
MAX_RETRIES: int = 3


class _WakeSlice(Sequence[int]):
    """Wake seeds ``start .. stop - 1`` of an evaluation, indexed by the episode index."""

    def __init__(self, seeds: Sequence[int], start: int) -> None:
        self._seeds = [int(s) for s in seeds]
        self._start = start

    def __len__(self) -> int:
        return self._start + len(self._seeds)

    def __getitem__(self, k: Any) -> Any:
        if isinstance(k, slice):
            raise TypeError("a wake-seed slice is indexed by episode")
        if k < self._start:
            raise IndexError(f"episode {k} is before this range ({self._start})")
        return self._seeds[k - self._start]


def _run_part(
    policy: Any,
    start: int,
    stop: int,
    seed: int,
    wake_seeds: Optional[list[int]],
    batch: int,
    num_threads: int,
    config: Optional[dict[str, Any]],
    crash_marker: Optional[str] = None,
) -> dict[str, Any]:
    """One Ray task: episodes ``start .. stop - 1``; returns them with where and how long it ran.

    ``crash_marker`` (fault injection for the tests): when given and the file does not exist
    yet, the task creates it after running its episodes and kills its own worker process, as a
    lost worker would, so Ray must retry it."""
    import ray

    t0 = time.perf_counter()
    policy = copy.deepcopy(policy)  # Ray hands arguments over read-only; the policy keeps per-env state
    wake = None if wake_seeds is None else _WakeSlice(wake_seeds, start)
    episodes = run_episode_range(policy, start, stop, seed=seed, wake_seeds=wake, batch=batch,
                                 num_threads=num_threads, config=config)
    if crash_marker is not None and not os.path.exists(crash_marker):
        files.write_text(crash_marker, f"{start}..{stop}\n")
        os._exit(1)
    return {
        "start": start,
        "stop": stop,
        "episodes": episodes,
        "node_id": ray.get_runtime_context().get_node_id(),
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "wall_time_s": time.perf_counter() - t0,
    }


def default_chunk(episodes: int, batch: int, cpus: int) -> int:
    """Episodes per task: about four tasks per CPU (so a slow or retried task delays little),
    and never fewer than ``batch`` (a smaller range would leave envs of its batch idle)."""
    return max(int(batch), math.ceil(episodes / (4 * max(1, int(cpus)))))


def run_policies(
    policies: dict[str, Any],
    episodes: int,
    *,
    seed: int,
    wake_seeds: Optional[Sequence[int]],
    num_envs: int = 16,
    config: Optional[dict[str, Any]] = None,
    address: Optional[str] = "local",
    chunk: Optional[int] = None,
    cpus_per_task: int = 1,
    progress: bool = False,
    crash_marker: Optional[str] = None,
) -> tuple[dict[str, list[Any]], dict[str, Any]]:
    """Runs episodes ``0 .. episodes - 1`` of every policy as Ray tasks; returns ``(episodes by
    policy spec, task log)``. The episodes are those of :func:`accd_gym.evals.evaluation.run_episodes`
    with the same ``seed``, ``wake_seeds``, ``num_envs`` and ``config``, bit for bit.

    ``chunk``: episodes per task (default :func:`default_chunk`); ``cpus_per_task``: CPUs Ray
    reserves for each task, which are also the threads stepping its envs.
    """
    if episodes < 1:
        raise ConfigError(f"invalid config: `episodes` = {episodes} is outside the allowed range >= 1")
    if cpus_per_task < 1:
        raise ConfigError(f"invalid config: `cpus_per_task` = {cpus_per_task} is outside the allowed range >= 1")
    if chunk is not None and chunk < 1:
        raise ConfigError(f"invalid config: `chunk` = {chunk} is outside the allowed range >= 1")
    if wake_seeds is not None and len(wake_seeds) < episodes:
        raise ConfigError(f"invalid config: {len(wake_seeds)} wake seeds for {episodes} episodes; need at least as many")
    ray = connect(address)
    batch = min(int(num_envs), episodes)
    cpus = int(ray.cluster_resources().get("CPU", 1))
    size = chunk or default_chunk(episodes, batch, cpus // cpus_per_task)
    task = ray.remote(num_cpus=cpus_per_task, max_retries=MAX_RETRIES, retry_exceptions=False)(_run_part)
    t0 = time.perf_counter()
    pending: dict[Any, tuple[str, int, int]] = {}
    for spec, policy in policies.items():
        ref = ray.put(policy)
        for a in range(0, episodes, size):
            b = min(episodes, a + size)
            wake = None if wake_seeds is None else [int(s) for s in wake_seeds[a:b]]
            pending[task.remote(ref, a, b, seed, wake, batch, cpus_per_task, config, crash_marker)] = (spec, a, b)
    gathered: dict[str, dict[int, Any]] = {spec: {} for spec in policies}
    log: list[dict[str, Any]] = []
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=episodes * len(policies), desc="episodes (ray)", unit="ep")
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            spec, a, b = pending.pop(done[0])
            try:
                part = ray.get(done[0])
            except Exception as e:  # a range that failed after its retries
                raise RuntimeError(f"evaluation of {spec!r}, episodes {a}..{b - 1}, failed after "
                                   f"{MAX_RETRIES} retries: {e}") from e
            mine = gathered[spec]
            for ep in part["episodes"]:
                if ep.index in mine:  # delivered twice: counted once, and must be the same
                    if ep.metrics() != mine[ep.index].metrics():
                        raise RuntimeError(f"episode {ep.index} of {spec!r} came back twice with different results")
                    continue
                mine[ep.index] = ep
            log.append({"policy": spec, **{k: v for k, v in part.items() if k != "episodes"}})
            if bar is not None:
                bar.update(b - a)
    finally:
        if bar is not None:
            bar.close()
        for ref in pending:
            ray.cancel(ref, force=True)
    out: dict[str, list[Any]] = {}
    for spec, mine in gathered.items():
        missing = [k for k in range(episodes) if k not in mine]
        if missing:
            raise RuntimeError(f"evaluation of {spec!r}: episodes {missing[:5]}... are missing")
        out[spec] = [mine[k] for k in range(episodes)]
    nodes = sorted({t["node_id"] for t in log})
    info = {
        "address": address,
        "cluster_cpus": cpus,
        "nodes": nodes,
        "tasks": sorted(log, key=lambda t: (t["policy"], t["start"])),
        "episodes_per_task": size,
        "cpus_per_task": cpus_per_task,
        "wall_time_s": time.perf_counter() - t0,
    }
    return out, info


__all__ = ["MAX_RETRIES", "connect", "default_chunk", "run_policies"]
