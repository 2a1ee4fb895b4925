"""The trained policies shipped with the package (accd_gym.trained): each loads by name, runs its
first held-out episodes as stored when it was shipped (outcome, steps, miss distance), its
recorded held-out row is consistent, its files are small and in the wheel's package folder, and
the command line evaluates it by name on its tier."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from accd_gym import ConfigError, trained
from accd_gym.evals.policies import load_policy

SHIPPED = ["dagger_residual_sac_hard", "dagger_residual_sac_precision", "residual_ppo_hard", "residual_ppo_precision",
           "residual_sac_hard", "residual_sac_precision"]
#: A shipped policy's files at most (bytes): SAC's model holds its actor, two critics and their
#: targets (256 x 256 each), PPO's one actor-critic; the exported actor (network.npz) adds about
#: a sixth. A distilled student is a PPO model (its critic untrained) whose input is the last 8
#: observations and commands, so its first layers are wider, and its exported actor a third.
MAX_BYTES = {"ppo": 700_000, "sac": 3_000_000, "distill": 1_800_000}


def test_catalog_lists_the_shipped_policies_and_their_metadata():
    assert trained.available() == SHIPPED
    for name in SHIPPED:
        doc = trained.info(name)
        # Named for the benchmark's method and tier the policy was chosen from.
        assert doc["name"] == name == f"{doc['selection']['method']}_{doc['tier']}"
        distilled = json.loads((trained.policy_dir(name) / "run.json").read_text()).get("trainer") == "distill"
        # (a distilled student is a PPO model whose actor is the student)
        assert doc["algo"] == "ppo" if distilled else doc["algo"] in name
        held = doc["held_out"]
        assert held["episodes"] == len(held["captured"]) == 500
        assert held["captures"] == held["captured"].count("1")
        # The LQR's outcomes on the same episodes, and every episode's length and miss distance.
        assert len(held["lqr_captured"]) == 500 and held["lqr_captures"] == held["lqr_captured"].count("1")
        assert len(held["steps"]) == len(held["min_distance"]) == 500
        folder = trained.policy_dir(name)
        sizes = {f.name: f.stat().st_size for f in folder.iterdir()}
        assert set(sizes) == {"final_model.zip", "vecnormalize.pkl", "run.json", "policy.json", "network.npz"}
        assert sum(sizes.values()) < MAX_BYTES["distill" if distilled else doc["algo"]], sizes


def test_unknown_name_is_one_error_naming_the_value_and_the_shipped_names():
    with pytest.raises(ConfigError, match=r"'nope'.*allowed range.*residual_ppo_hard"):
        trained.info("nope")


_CHECK = """
import json, sys
from accd_gym import trained
name, n = sys.argv[1], int(sys.argv[2])
eps = trained.held_out_episodes(name, n)
print(json.dumps([{"index": e.index, "outcome": e.outcome, "steps": e.steps, "min_distance": e.min_distance,
                   "captured": bool(e.captured)} for e in eps]))
"""


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policy_reproduces_its_stored_held_out_episodes(name):
    pytest.importorskip("stable_baselines3")
    doc = trained.info(name)
    stored = doc["check_episodes"]
    # The LQR inside a residual policy is fixed-order Rust: no BLAS kernel decides its bits,
    # so the check runs as a user would, with no environment variable set.
    r = subprocess.run([sys.executable, "-c", _CHECK, name, str(len(stored))], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    episodes = json.loads(r.stdout.splitlines()[-1])
    assert [e["index"] for e in episodes] == [s["index"] for s in stored]
    assert [e["outcome"] for e in episodes] == [s["outcome"] for s in stored]
    assert [e["steps"] for e in episodes] == [s["steps"] for s in stored]
    # Every bit: the physics, the LQR and the network are fixed-order arithmetic (JSON keeps a
    # double exactly).
    assert [e["min_distance"] for e in episodes] == [s["min_distance"] for s in stored]
    recorded = doc["held_out"]["captured"][: len(stored)]
    assert "".join("1" if e["captured"] else "0" for e in episodes) == recorded


def test_load_policy_resolves_a_shipped_name_to_its_exported_network():
    from accd_gym.evals.network import NetworkPolicy

    policy = load_policy("residual_ppo_hard", config={"tier": "hard"})
    assert isinstance(policy, NetworkPolicy)
    assert policy.agent_options.enabled and policy.algo == "ppo"


def test_rollout_runs_a_shipped_policy_by_name_on_its_tier():
    r = subprocess.run([sys.executable, "-m", "accd_gym", "rollout", "--policy", "residual_ppo_precision",
                        "--episodes", "2", "--quiet", "--json"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "tier 'precision'" in r.stderr
    doc = json.loads(r.stdout[r.stdout.index("\n{") + 1:])
    assert doc["summary"]["episodes"] == 2
