"""Hashes every output of a fixed set of episodes: the physics fingerprint kept by refactors.

Runs 8 envs x 700 agent steps of the native vector env under the default and the precision
configurations (and both again under the exact air scheme, the default of the first releases), each with the guidance controller (closed loop, captures) and with seeded
uniform random flaps (open loop, failures), and hashes per step the observations, rewards,
terminated/truncated flags and every info value (``wake_seed`` as int64). Info values of the
step after an episode ended (the autoreset step of ``NEXT_STEP``) are left out: they describe
the reset, whose reporting is an API choice, not physics. The observations of those steps are
hashed. ``tests/test_physics_hash.py`` compares the result with ``tests/data/physics_hashes.json``.

    python scripts/physics_hash.py            # print the hashes as JSON
    python scripts/physics_hash.py --write    # record them in tests/data/physics_hashes.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pathlib

import numpy as np

import accd_gym
from accd_gym.control.baselines import GuidancePolicy

# The exact air scheme (docs/decisions.md, "The fast air scheme is the default; the exact scheme
# stays"): its hashes are those of the default and precision configs under that scheme.
EXACT = {"wake": {"sampling": "per_stage"}, "turbulence": {"normal_sampler": "box_muller", "lane_streams": "shared"}}
PRECISION = {
    "turbulence": {"ambient": "severe"},
    "boom": {"capture_radius": 0.3, "max_closing_speed": 1.0},
}
CONFIGS = {
    "default": {},
    "precision": PRECISION,
    "exact": EXACT,
    "exact_precision": {**EXACT, "turbulence": {**EXACT["turbulence"], **PRECISION["turbulence"]}, "boom": PRECISION["boom"]},
}
NUM_ENVS = 8
STEPS = 700
SEEDS = [7 + 13 * i for i in range(NUM_ENVS)]
DATA = pathlib.Path(__file__).resolve().parent.parent / "tests" / "data" / "physics_hashes.json"


def run(config: dict, policy: str) -> str:
    """SHA-256 of every output of NUM_ENVS x STEPS agent steps under ``config``."""
    env = accd_gym.InAirCaptureVectorEnv(NUM_ENVS, num_threads=2, **config)
    h = hashlib.sha256()
    obs, _ = env.reset(seed=SEEDS)
    h.update(np.ascontiguousarray(obs, dtype=np.float32).tobytes())
    rng = np.random.default_rng(12345)
    guidance = GuidancePolicy()
    after_done = np.zeros(NUM_ENVS, dtype=bool)
    for _ in range(STEPS):
        if policy == "guidance":
            actions = guidance.predict(obs)
        else:
            actions = rng.uniform(-1.0, 1.0, size=(NUM_ENVS, 4)).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(actions)
        for array in (obs, reward, terminated, truncated):
            h.update(np.ascontiguousarray(array).tobytes())
        keep = ~after_done
        for name in sorted(k for k in info if not k.startswith("_") and k not in ("final_obs", "final_info")):
            value = np.asarray(info[name])
            value = value.astype(np.int64) if value.dtype.kind in "iub" else value.astype(np.float64)
            h.update(name.encode())
            h.update(np.ascontiguousarray(value[keep]).tobytes())
        after_done = terminated | truncated
        if policy == "guidance":
            guidance.reset(after_done)
    env.close()
    return h.hexdigest()


def hashes() -> dict[str, str]:
    """The fingerprint of every (config, policy) pair."""
    return {f"{name}/{policy}": run(cfg, policy) for name, cfg in CONFIGS.items() for policy in ("guidance", "random")}


def main() -> None:
    """Prints the hashes, or records them with ``--write``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="record the hashes in tests/data")
    args = parser.parse_args()
    out = hashes()
    print(json.dumps(out, indent=2))
    if args.write:
        DATA.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
