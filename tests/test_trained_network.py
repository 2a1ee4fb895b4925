"""The shipped policies' exported networks (accd_gym.evals.network): the fixed-order forward
pass equals PyTorch's network (run in float64) to rounding and stable-baselines3's float32
``predict`` to float32 rounding; its functions are accurate and batch-independent; a damaged file
is a ConfigError naming it; and ``accd-gym evaluate`` runs a shipped policy with PyTorch and
stable-baselines3 made unimportable."""

from __future__ import annotations

import hashlib
import json
import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from accd_gym import ConfigError, trained
from accd_gym.evals.network import NETWORK_FILE, Network, NetworkPolicy, exp_nonpositive, linear, tanh

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = trained.available()


def observations(net: Network, n: int, spread: float = 2.0) -> np.ndarray:
    """``n`` float32 observations around the network's normalisation statistics (mean + spread *
    std * u, u uniform in [-1, 1] from an integer generator: the same values on every machine)."""
    k = np.arange(n * net.obs_dim, dtype=np.uint64)
    bits = (k * np.uint64(6364136223846793005) + np.uint64(1442695040888963407)) >> np.uint64(11)
    u = (bits.astype(np.float64) / float(2**53)).reshape(n, net.obs_dim) * 2.0 - 1.0
    mean = net._norm[0] if net._norm is not None else 0.0
    std = net._norm[1] if net._norm is not None else 1.0
    return (mean + spread * std * u).astype(np.float32)


@pytest.mark.parametrize("name", SHIPPED)
def test_exported_network_equals_pytorchs(name):
    pytest.importorskip("stable_baselines3")
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from export_networks import torch_actions
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    from accd_gym.evals.policies import SB3Policy

    sb3 = SB3Policy(trained.policy_dir(name))
    net = Network(trained.policy_dir(name))
    obs = observations(net, 512)
    normalized = sb3.normalizer.normalize_obs(obs)
    # The normalisation is VecNormalize's, bit for bit.
    assert np.array_equal(net.normalize(obs), normalized)
    # PyTorch's network in float64: the same result to the last few bits (measured: 4e-15).
    assert np.abs(net.outputs(obs) - torch_actions(sb3.model, sb3.algo, normalized, double=True)).max() < 1e-12
    # stable-baselines3's float32 predict: PyTorch's float32 sums are off the exact result by up
    # to a few 1e-6 (measured: 2.9e-6 for SAC's 256 x 256 network, 1.8e-7 for PPO's 128 x 128);
    # the exported network is within 1e-7 of the exact result.
    ref = torch_actions(sb3.model, sb3.algo, normalized, double=False)
    assert np.abs(net.actions(obs) - ref).max() < 1e-5
    if sb3.algo == "ppo":
        assert np.abs(net.actions(obs) - ref).max() < 1e-6


def test_tanh_and_exp_are_accurate_from_basic_operations():
    x = np.linspace(-25.0, 25.0, 200_001)
    want = np.array([math.tanh(v) for v in x])
    assert np.abs(tanh(x) - want).max() < 4e-16
    assert np.array_equal(tanh(-x), -tanh(x))
    assert tanh(np.array([0.0, -0.0]))[1] == 0.0 and math.copysign(1.0, tanh(np.array([-0.0]))[0]) == -1.0
    y = np.linspace(-40.0, 0.0, 100_001)
    rel = np.abs(exp_nonpositive(y) / np.array([math.exp(v) for v in y]) - 1.0)
    assert rel.max() < 1e-15


def test_linear_sums_in_input_order():
    # 1 + 1e16 - 1e16 in input order is 0 (1 is lost against 1e16); any other order of the same
    # three terms that sums the large ones first gives 1.
    x = np.array([[1.0, 1e16, -1e16]])
    w = np.ones((3, 1))
    assert linear(x, w, np.zeros(1))[0, 0] == 0.0
    assert linear(x[:, ::-1], w, np.zeros(1))[0, 0] == 1.0


@pytest.mark.parametrize("name", ["residual_sac_hard", "residual_ppo_hard"])
def test_actions_are_independent_of_the_batch(name):
    net = Network(trained.policy_dir(name))
    obs = observations(net, 64)
    batch = net.actions(obs)
    assert batch.dtype == np.float32 and batch.shape == (64, 4) and np.abs(batch).max() <= 1.0
    rows = np.concatenate([net.actions(obs[i : i + 1]) for i in range(0, 64, 7)])
    assert np.array_equal(rows, batch[::7])


#: sha256 of the float32 actions of each shipped network on :func:`observations` (64 rows): the
#: forward pass uses IEEE operations alone, so every machine gives these bits.
ACTIONS_SHA256 = {
    "dagger_residual_sac_hard": "1a3d5a0119572c0d09cd94a68f7c2efd4e631f0758a303021431dcf049a6740a",
    "dagger_residual_sac_precision": "05d2b31190e696dde1607a01deed913f8cf2a58dfb5f97cc7fde465c2432e5de",
    "residual_ppo_hard": "d09924b87ebd355c34a7f879fe1233208198c6be0bb543e5a259497800a4144a",
    "residual_ppo_precision": "902f078f972bfd5296b737bef2984b54ac77384d1e98a1e5f04868c2420951a7",
    "residual_sac_hard": "e6e26fe28a112a1ceae5e9af7d73a6b48bc174c42225e80b1052f8337494440f",
    "residual_sac_precision": "0e87bc1f59497ec1ccc664c8cabac70dc828e3c30a65f567b2ebb102af0fe8cb",
}


@pytest.mark.parametrize("name", SHIPPED)
def test_actions_are_the_recorded_bits(name):
    net = Network(trained.policy_dir(name))
    got = hashlib.sha256(np.ascontiguousarray(net.actions(observations(net, 64))).tobytes()).hexdigest()
    assert got == ACTIONS_SHA256[name]


def test_a_damaged_or_foreign_network_file_names_itself(tmp_path):
    bad = tmp_path / NETWORK_FILE
    bad.write_bytes(b"not a zip")
    with pytest.raises(ConfigError, match=r"network file .*network\.npz.* cannot be read"):
        Network(tmp_path)
    with pytest.raises(ConfigError, match=r"does not exist"):
        Network(tmp_path / "nothing")
    src = dict(np.load(trained.policy_dir("residual_ppo_hard") / NETWORK_FILE, allow_pickle=False))
    spec = json.loads(str(src["spec"]))
    np.savez(bad, **{**src, "spec": np.array(json.dumps({**spec, "version": 99}))})
    with pytest.raises(ConfigError, match=r"format \('accd-gym network', 99\)"):
        Network(bad)
    np.savez(bad, **{**src, "layer0_weight": src["layer0_weight"][:-1]})
    with pytest.raises(ConfigError, match=r"layer 0 has weight"):
        Network(bad)
    np.savez(bad, **{**src, "spec": np.array(json.dumps({**spec, "env": {"history": 2}}))})
    with pytest.raises(ConfigError, match=r"its env options .*history"):
        NetworkPolicy(bad)


#: Makes PyTorch and stable-baselines3 unimportable in the process (a sitecustomize module).
_BLOCKER = textwrap.dedent('''
    import sys

    class _Blocker:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in ("torch", "stable_baselines3"):
                raise ModuleNotFoundError(f"No module named {name!r} (blocked)", name=name)
            return None

    sys.meta_path.insert(0, _Blocker())
''')


def test_evaluate_runs_a_shipped_policy_without_pytorch_or_stable_baselines3(tmp_path):
    (tmp_path / "site").mkdir()
    (tmp_path / "site" / "sitecustomize.py").write_text(_BLOCKER)
    import os

    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path / "site"), os.environ.get("PYTHONPATH", "")]))
    probe = subprocess.run([sys.executable, "-c", "import torch"], capture_output=True, text=True, env=env)
    assert probe.returncode != 0 and "blocked" in probe.stderr
    out = tmp_path / "eval"
    r = subprocess.run([sys.executable, "-m", "accd_gym", "evaluate", "--policy", "residual_sac_hard", "--episodes", "2",
                        "--num-envs", "2", "--out", str(out), "--quiet", "--env", json.dumps({"capture_window": 12.0})],
                       capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    episodes = json.loads((out / "results.json").read_text())["policies"]["residual_sac_hard"]["episodes"]
    assert len(episodes) == 2
    # The same episodes as the network in this process (with or without PyTorch installed).
    from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS
    from accd_gym.evals.episodes import run_episodes

    config = {"tier": "hard", "capture_window": 12.0}
    here = run_episodes(trained.load_policy("residual_sac_hard", config), 2, wake_seeds=list(HELD_OUT_WAKE_SEEDS[:2]),
                        num_envs=2, config=config, progress=False)
    assert [e["steps"] for e in episodes] == [e.steps for e in here]
    assert [e["min_distance"] for e in episodes] == [float(e.min_distance) for e in here]
