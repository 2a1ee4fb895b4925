"""Measures a change of the numerical scheme against the exact one on held-out episodes.

Runs the same ``--episodes`` held-out episodes (the evaluation's wake seeds, base seed and env
layout) under a reference configuration and a candidate, with the guidance controller in closed
loop, and reports per episode whether the outcome (captured / overload / envelope exit /
truncated) is the same and the RMS over the episode of the difference in the ACCD's position
(over the steps both runs share). The acceptance rule of the performance work: the same outcome in
at least 99 % of the episodes and at most 2 cm RMS.

    python scripts/compare_schemes.py --episodes 200 \
        --reference '{"wake": {"sampling": "per_stage"}}' --candidate '{"wake": {"sampling": "per_step"}}'
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from accd_gym.control.baselines import GuidancePolicy
from accd_gym.evals.evaluation import EVAL_BASE_SEED
from accd_gym.envs.sb3 import AccdVecEnv
from accd_gym.envs.task import EVENT_NAMES, HELD_OUT_WAKE_SEEDS, OBSERVATION_INDEX, OBSERVATION_SCALE

POSITION = [OBSERVATION_INDEX[k] for k in ("accd_dx", "accd_dy", "accd_dz")]
SCALE = OBSERVATION_SCALE["accd_dx"]


def run(config: dict, episodes: int, steps: int = 700) -> tuple[list[str], list[np.ndarray]]:
    """Outcome and ACCD position history (m, relative to the equilibrium) of each episode."""
    env = AccdVecEnv(num_envs=episodes, seed=EVAL_BASE_SEED, **config)
    env.set_options({"wake_seeds": list(HELD_OUT_WAKE_SEEDS)[:episodes]})
    obs = env.reset()
    policy = GuidancePolicy()
    alive = np.ones(episodes, dtype=bool)
    outcome = ["truncated"] * episodes
    hist = [[obs[i, POSITION] / SCALE] for i in range(episodes)]
    for _ in range(steps):
        obs, _, dones, infos = env.step(policy.predict(obs))
        for i in np.flatnonzero(alive):
            last = infos[i]["terminal_observation"] if dones[i] else obs[i]
            hist[i].append(last[POSITION] / SCALE)
            if dones[i]:
                alive[i] = False
                outcome[i] = next((e for e in EVENT_NAMES if infos[i][e]), "truncated")
        policy.reset(dones)
        if not alive.any():
            break
    env.close()
    return outcome, [np.asarray(h, dtype=np.float64) for h in hist]


def compare(reference: dict, candidate: dict, episodes: int) -> dict:
    """Outcome agreement and position RMS differences of ``candidate`` against ``reference``."""
    out_a, pos_a = run(reference, episodes)
    out_b, pos_b = run(candidate, episodes)
    same = [a == b for a, b in zip(out_a, out_b)]
    rms = []
    for a, b in zip(pos_a, pos_b):
        n = min(len(a), len(b))
        rms.append(float(np.sqrt(np.mean(np.sum((a[:n] - b[:n]) ** 2, axis=1)))))
    rms = np.asarray(rms)
    return {
        "episodes": episodes,
        "same_outcome": int(sum(same)),
        "same_outcome_fraction": sum(same) / episodes,
        "captured_reference": out_a.count("captured"),
        "captured_candidate": out_b.count("captured"),
        "position_rms_m": {"median": float(np.median(rms)), "p90": float(np.quantile(rms, 0.9)), "max": float(rms.max()), "mean": float(rms.mean())},
        "differing": [
            {"episode": i, "reference": a, "candidate": b, "rms_m": float(r)}
            for i, (a, b, r) in enumerate(zip(out_a, out_b, rms))
            if a != b
        ],
    }


def main() -> None:
    """Prints the comparison as JSON."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=200)
    p.add_argument("--reference", default='{"wake": {"sampling": "per_stage"}}', help="JSON config")
    p.add_argument("--candidate", default='{"wake": {"sampling": "per_step"}}', help="JSON config")
    a = p.parse_args()
    print(json.dumps(compare(json.loads(a.reference), json.loads(a.candidate), a.episodes), indent=2))


if __name__ == "__main__":
    main()
