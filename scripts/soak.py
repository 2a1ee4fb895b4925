#!/usr/bin/env python3
"""Soak test (not in CI): steps the native vector env with random actions for a while and reports
steps, episodes, divergences, NaN counts and resident-memory growth.

    python scripts/soak.py --minutes 30 --num-envs 16

Besides plain stepping it mixes in, every few hundred steps, the calls a long training run or a
user makes: ``reset`` with new seeds, ``get_state``/``set_state``, read-only outputs, rendering
data, a ``CaptureSim`` and a ``Tether`` built, stepped and dropped. Memory is sampled from
``/proc/self/status`` (VmRSS) after a warm-up minute; growth beyond ``--max-rss-growth-mib``
or any NaN in an observation or reward makes the exit code 1.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Optional

import numpy as np


def rss_mib() -> float:
    """Resident set size of this process, MiB (Linux)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def main(argv: Optional[list] = None) -> int:
    """Runs the soak and prints a JSON report; returns the exit code."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=30.0, help="how long to run (default 30)")
    p.add_argument("--num-envs", type=int, default=16, help="envs in the batch (default 16)")
    p.add_argument("--num-threads", type=int, default=0, help="threads (default 0: one per core)")
    p.add_argument("--seed", type=int, default=0, help="seed of actions and episodes")
    p.add_argument("--warmup-minutes", type=float, default=1.0, help="memory baseline taken after this (default 1)")
    p.add_argument("--max-rss-growth-mib", type=float, default=32.0, help="allowed RSS growth after warm-up")
    p.add_argument("--report-every", type=float, default=60.0, help="seconds between progress lines")
    args = p.parse_args(argv)

    import accd_gym

    rng = np.random.default_rng(args.seed)
    env = accd_gym.AccdVecEnv(num_envs=args.num_envs, seed=args.seed, num_threads=args.num_threads)
    obs = env.reset()
    t0 = time.monotonic()
    end = t0 + 60.0 * args.minutes
    baseline = None
    peak = rss_mib()
    counts = {"steps": 0, "env_steps": 0, "episodes": 0, "diverged": 0, "captured": 0, "nan_obs": 0,
              "nan_reward": 0, "resets": 0, "state_round_trips": 0, "side_objects": 0}
    next_report = t0 + args.report_every
    k = 0
    while time.monotonic() < end:
        k += 1
        actions = rng.uniform(-1.2, 1.2, (args.num_envs, 4)).astype(np.float32)
        env.step_async(actions)
        obs, reward, dones, infos = env.step_wait()
        counts["steps"] += 1
        counts["env_steps"] += args.num_envs
        counts["nan_obs"] += int(np.count_nonzero(~np.isfinite(obs)))
        counts["nan_reward"] += int(np.count_nonzero(~np.isfinite(reward)))
        for i in np.flatnonzero(dones):
            counts["episodes"] += 1
            counts["diverged"] += bool(infos[i]["diverged"])
            counts["captured"] += bool(infos[i]["captured"])
        if k % 500 == 0:
            env.seed(int(rng.integers(0, 2**63)))
            obs = env.reset()
            counts["resets"] += 1
        if k % 700 == 0:
            state = env.get_state()
            env.set_state(state)
            counts["state_round_trips"] += 1
        if k % 900 == 0:
            obs.flags.writeable = False
            env.get_images() if env.render_mode else None
            sim = accd_gym.CaptureSim(seed=int(rng.integers(0, 2**32)))
            sim.step([1.0, -1.0, 0.0, 0.5], steps=50)
            tether = accd_gym.Tether()
            tether.tow()
            tether.advance(1.0)
            counts["side_objects"] += 1
        now = time.monotonic()
        if baseline is None and now - t0 >= 60.0 * args.warmup_minutes:
            baseline = rss_mib()
        peak = max(peak, rss_mib()) if k % 100 == 0 else peak
        if now >= next_report:
            next_report = now + args.report_every
            print(f"[{(now - t0) / 60:5.1f} min] {counts['env_steps']} env steps, {counts['episodes']} episodes, "
                  f"RSS {rss_mib():.1f} MiB", file=sys.stderr, flush=True)
    elapsed = time.monotonic() - t0
    final = rss_mib()
    growth = final - (baseline if baseline is not None else final)
    report = dict(counts, minutes=round(elapsed / 60, 2), env_steps_per_s=round(counts["env_steps"] / elapsed, 1),
                  rss_baseline_mib=baseline, rss_final_mib=round(final, 1), rss_peak_mib=round(peak, 1),
                  rss_growth_mib=round(growth, 1))
    print(json.dumps(report, indent=1))
    ok = counts["nan_obs"] == 0 and counts["nan_reward"] == 0 and growth <= args.max_rss_growth_mib
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
