"""accd_gym.linearize and the LQR baseline (accd_gym.control.lqr).

The linear model is checked against the nonlinear step it was taken from (errors shrink
quadratically with the perturbation where the dynamics are smooth; crates/sim/tests/integration/linearize.rs
has the finer checks), the design's closed loop and observer on the linear model itself, and the
policy on a handful of training-seed episodes of the default task.
"""

import json
import pickle

import numpy as np
import pytest

import accd_gym
from accd_gym import ConfigError
from accd_gym.evals.evaluation import load_policy, run_episodes, summarize
from accd_gym.control.lqr import LqrPolicy, LqrTuning, design, linearize
from accd_gym.envs.task import OBS_DIM, OBSERVATION_SCALE, TRAINING_WAKE_SEEDS, observation_indices


@pytest.fixture(scope="module")
def lin():
    return linearize()


@pytest.fixture(scope="module")
def policy():
    return LqrPolicy.for_config()


def _direction(lin, scale, seed=0):
    """Every state component a uniform multiple in [-1, 1] of its finite-difference step, times scale."""
    return np.random.default_rng(seed).uniform(-1.0, 1.0, lin.trim.shape) * lin.steps * scale


def _norm(v, lin):
    return float(np.linalg.norm(v / lin.steps))


def test_shapes_and_names_follow_the_config(lin):
    n = 2 * (2 * 30 + 1) + 10  # tether q and q' (30 segments), attitude error, body rates, flaps
    assert lin.a.shape == (n, n) and lin.b.shape == (n, 4) and lin.e.shape == (n, 2) and lin.c.shape == (OBS_DIM, n)
    assert len(lin.state_names) == n and lin.state_names[:3] == ["s", "phi_1", "psi_1"]
    assert lin.state_names[-10:-7] == ["att_x", "att_y", "att_z"] and lin.dt == pytest.approx(0.1)
    short = linearize(tether={"segments": 10})
    assert short.a.shape == (2 * 21 + 10,) * 2


def test_the_trim_is_a_fixed_point(lin):
    nxt = lin.step(np.zeros_like(lin.trim))
    assert np.max(np.abs(nxt)) < 1e-9
    assert lin.trim_residual < 1e-9 < lin.settle_residual  # the settled state moved; Newton removed it


def test_a_state_perturbation_follows_a_to_second_order(lin):
    # 1600 to 400 finite-difference steps (1.6e-3 to 4e-4 rad of every angle): the error is the
    # model's O(eps^2) and halves to a quarter. Below that a first-order term of about 1e-3 of the
    # response takes over: the tables' kinks (aerodynamic nodes at sideslip 0, trilinear wake),
    # where the central differences give the mean of the one-sided slopes (measured: relative
    # error 2.0e-2, 1.0e-2, 5.3e-3, 3.0e-3, 1.9e-3, 1.4e-3 from 3200 to 100 steps).
    errors = []
    for scale in (1600.0, 800.0, 400.0):
        dx = _direction(lin, scale)
        nxt = lin.step(dx)
        errors.append((_norm(nxt - lin.a @ dx, lin), _norm(nxt, lin)))
    ratios = [errors[i][0] / errors[i + 1][0] for i in range(2)]
    assert all(3.3 < r < 4.7 for r in ratios), ratios  # halving the perturbation quarters the error
    assert errors[-1][0] < 5e-3 * errors[-1][1]


def test_a_flap_input_follows_b_within_the_tables_kink(lin):
    # The aerodynamic tables are linear in the deflection with a node at 0, so the flap input's
    # error is first order (the mean of the one-sided slopes): it halves with the input and
    # stays below 1e-3 of the response, over a second-order part that shows at larger inputs
    # (halving then divides by 2 to 4). (A smooth table gives pure second order: the Rust tests.)
    errors = []
    for u in (0.02, 0.01, 0.005):
        uu = np.array([1.0, -0.7, 0.4, 0.8]) * u
        nxt = lin.step(np.zeros_like(lin.trim), uu)
        errors.append((_norm(nxt - lin.b @ uu, lin), _norm(nxt, lin)))
    ratios = [errors[i][0] / errors[i + 1][0] for i in range(2)]
    assert all(1.8 < r < 4.2 for r in ratios), ratios
    assert ratios[-1] < 2.6  # the smallest inputs: first order
    assert all(e < 1e-3 * s for e, s in errors)


def test_the_observation_follows_c_and_the_boom_rows_are_minus_the_capture_point(lin):
    y0 = lin.observe(np.zeros_like(lin.trim))
    assert np.array_equal(y0, lin.trim_observation) and np.all(np.abs(y0[:6]) < 1e-9)
    dx = _direction(lin, 100.0, seed=1)
    y = lin.observe(dx)
    assert np.linalg.norm(y - y0 - lin.c @ dx) < 1e-3 * np.linalg.norm(y - y0)
    # The tip's lateral position: accd_dy and boom_rel_y see it with opposite signs.
    j = lin.state_names.index("psi_30")
    (by,), (ay,) = observation_indices("boom_rel_y"), observation_indices("accd_dy")
    assert lin.c[by, j] / OBSERVATION_SCALE["boom_rel_y"] == pytest.approx(-lin.c[ay, j] / OBSERVATION_SCALE["accd_dy"])


def test_the_closed_loop_linear_system_is_stable(lin, policy):
    d = policy.design
    radius = np.max(np.abs(np.linalg.eigvals(lin.a - lin.b @ d.k)))
    assert radius < 1.0 and radius == pytest.approx(d.closed_loop_radius)
    assert np.max(np.abs(np.linalg.eigvals(lin.a))) == pytest.approx(1.0, abs=1e-6)  # roll is neutral open loop
    assert d.observer_radius < 1.0


def _linear_episode(lin, policy, steps, seed=3):
    """The policy on the linear model: a random start, a constant wind bias and a boom offset."""
    d = policy.design
    n = d.n
    rng = np.random.default_rng(seed)
    z = np.zeros(d.f.shape[0])
    z[:n] = _direction(lin, 1e3, seed)
    z[n:n + 2] = rng.uniform(-0.5, 0.5, 2)  # wind bias, m/s
    z[n + 2:n + 5] = [0.0, rng.uniform(-3, 3), rng.uniform(-3, 3)]  # boom tip minus trim capture point, m
    policy.reset()
    obs_rows = np.array([i for i in range(OBS_DIM) if i != observation_indices("time_left")[0]])
    est_errors, track = [], []
    for _ in range(steps):
        obs = np.zeros((1, OBS_DIM))
        obs[0, obs_rows] = d.y_trim + d.h @ z
        obs[0, observation_indices("time_left")] = 1.0
        u = policy.predict(obs)[0].astype(np.float64)
        est_errors.append(np.abs(policy.get_state()["z"][0] - z))
        cp = -(lin.c[observation_indices("boom_rel_y", "boom_rel_z")] @ z[:n]) / OBSERVATION_SCALE["boom_rel_y"]
        track.append(z[n + 3:n + 5] - cp)
        z = d.f @ z + d.g @ u
    return np.array(est_errors), np.array(track), z


def test_the_observer_converges_on_the_linear_model(lin, policy):
    # From the first observation's estimate to 100 s later: every block's error (the plant state
    # in units of its finite-difference steps, the wind bias, the boom) falls below 1e-3 of its
    # start; the observer's slowest mode (spectral radius 0.990 per step) allows 4e-5.
    est, _, _ = _linear_episode(lin, policy, 1000)
    n = policy.design.n
    plant = (est[:, :n] / lin.steps).max(axis=1)
    wind = est[:, n:n + 2].max(axis=1)
    boom = est[:, n + 2:].max(axis=1)
    for name, err in (("plant", plant), ("wind", wind), ("boom", boom)):
        assert err[-1] < 1e-3 * err[:10].max(), (name, err[:10].max(), err[-1])
    assert policy.design.observer_radius ** 1000 < 1e-3


def test_the_linear_closed_loop_tracks_the_boom_despite_the_wind_bias(lin, policy):
    _, track, _ = _linear_episode(lin, policy, 600, seed=5)
    assert np.abs(track[0]).max() > 0.5  # it starts off the boom
    assert np.abs(track[-1]).max() < 1e-3  # offset-free: the wind bias is estimated and rejected


def test_the_policy_captures_training_seed_episodes_of_the_default_task(policy):
    # Training wake seeds 3000-3007, base seed 11 (other episodes than the tuning's 2000.., seed 7).
    seeds = list(range(3000, 3008))
    assert all(s in TRAINING_WAKE_SEEDS for s in seeds)
    s = summarize(run_episodes(policy, 8, seed=11, wake_seeds=seeds, num_envs=8))
    assert s["captures"] >= 7, s["outcomes"]


#: The numpy/SciPy LQR's first 12 held-out episodes of the precision tier (outcome, agent steps,
#: miss distance in m), recorded before the design and the filter moved to fixed-order Rust.
_PRECISION_HELD_OUT = [
    ("captured", 590, 0.099064), ("captured", 152, 0.237017), ("captured", 639, 0.086383),
    ("captured", 212, 0.233902), ("captured", 233, 0.116585), ("captured", 173, 0.234999),
    ("captured", 266, 0.151876), ("captured", 205, 0.197404), ("captured", 289, 0.153161),
    ("captured", 241, 0.150258), ("truncated", 700, 0.218769), ("truncated", 700, 0.076153),
]


def test_the_held_out_episodes_are_those_of_the_numpy_scipy_lqr():
    # Same outcomes and lengths; the miss distances moved by under 4e-7 m on these (under 4e-6 m
    # on 72 episodes of the nominal, precision and hard tiers), far inside 1e-4 m.
    from accd_gym.envs.task import HELD_OUT_WAKE_SEEDS
    from accd_gym.envs.tiers import TIERS

    cfg = TIERS["precision"].config()
    eps = run_episodes(LqrPolicy.for_config(cfg), 12, wake_seeds=list(HELD_OUT_WAKE_SEEDS), num_envs=4, config=cfg)
    assert [(e.outcome, e.steps) for e in eps] == [(o, n) for o, n, _ in _PRECISION_HELD_OUT]
    np.testing.assert_allclose([e.min_distance for e in eps], [d for *_, d in _PRECISION_HELD_OUT], atol=1e-4)


def test_designs_are_scheduled_by_config_and_cached():
    a = LqrPolicy.for_config()
    b = LqrPolicy.for_config(wake_seed=12)  # the seeds do not change the plant
    c = LqrPolicy.for_config(tether={"length": 200.0})
    assert a.design is b.design and c.design is not a.design
    assert not np.allclose(a.design.k, c.design.k)
    built = load_policy("lqr", config={"tether": {"length": 200.0}})
    assert isinstance(built, LqrPolicy) and built.design is c.design


def test_configurations_with_one_plant_share_one_design(monkeypatch):
    """The capture limits and the turbulence do not enter the linearization: the precision
    tier's design is the nominal one's, designed once; another plant gets its own."""
    from accd_gym.control import lqr
    from accd_gym.envs.tiers import TIERS

    monkeypatch.setattr(lqr, "_DESIGNS", {})
    monkeypatch.setattr(lqr, "_PLANT_DESIGNS", {})
    calls = []
    real = lqr.design
    monkeypatch.setattr(lqr, "design", lambda lin, t: calls.append(t) or real(lin, t))
    nominal = LqrPolicy.for_config(TIERS["nominal"].config())
    precision = LqrPolicy.for_config(TIERS["precision"].config())
    assert precision.design is nominal.design and len(calls) == 1
    assert len(lqr._DESIGNS) == 2  # both configurations skip the linearization next time
    heavier = LqrPolicy.for_config(TIERS["precision"].config(), accd={"mass": 60.0})
    assert heavier.design is not nominal.design and len(calls) == 2
    assert not np.allclose(heavier.design.k, nominal.design.k)


_DESIGN_BITS = """
import hashlib, numpy as np
from accd_gym.control.lqr import LqrPolicy, default_tuning, design, linearize
from accd_gym.envs.tiers import tier
d = design(linearize(tier("hard").config()), default_tuning())
obs = np.random.default_rng(0).uniform(-0.3, 0.3, (40, 3, 25)).astype(np.float32)
obs[..., 12] = 1.0
p = LqrPolicy(d)
u = [p.predict(o) for o in obs]
print(hashlib.sha256(b"".join(np.ascontiguousarray(x).tobytes() for x in [d.k, d.k_ff, d.l, *u])).hexdigest())
"""


def test_the_design_and_the_filter_are_bitwise_the_same_whatever_the_blas_kernels_and_threads():
    # A process with one BLAS thread (a Ray worker, `accd-gym train`) and one with several (a
    # command-line evaluation), on a CPU whose OpenBLAS picks the AVX-512 or the AVX2 kernels,
    # must design the same gains and step the same commands: their last bits decide episodes.
    # (The numpy/SciPy design differed in the last bits of its gains between OpenBLAS's kernels.)
    import os
    import subprocess
    import sys

    bits = set()
    for threads, kernels in (("1", None), ("3", None), ("2", "Haswell"), ("1", "Prescott")):
        env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS") and k != "OPENBLAS_CORETYPE"}
        env["OPENBLAS_NUM_THREADS"] = threads
        if kernels:
            env["OPENBLAS_CORETYPE"] = kernels
        r = subprocess.run([sys.executable, "-c", _DESIGN_BITS], env=env, capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        bits.add(r.stdout.strip())
    assert len(bits) == 1, bits


def test_bad_configs_and_tunings_are_config_errors():
    with pytest.raises(ConfigError, match="segments"):
        linearize(tether={"segments": 0})
    with pytest.raises(ConfigError, match="agent_step"):
        LqrPolicy.for_config({"agent_step": -1.0})
    with pytest.raises(ConfigError, match="nosuch"):
        accd_gym.linearize(nosuch=1)
    with pytest.raises(ConfigError, match="r_flap"):
        LqrPolicy.for_config(tuning={"r_flap": 0.0})
    with pytest.raises(ConfigError, match="q_nothing"):
        LqrTuning.from_mapping({"q_nothing": 1.0})
    lin = linearize(tether={"segments": 10})
    with pytest.raises(ConfigError, match="dx"):
        lin.step(np.zeros(3))
    with pytest.raises(ConfigError, match=r"dx\[1\]"):
        lin.step(np.array([0.0, np.nan] + [0.0] * (lin.trim.size - 2)))


def test_the_tuning_file_is_a_policy_and_its_winner_is_the_default():
    doc = json.loads(open("training/lqr_tuning.json").read())
    assert doc["policy"] == "lqr"
    lo, hi = doc["wake_seeds"]
    assert lo in TRAINING_WAKE_SEEDS and hi in TRAINING_WAKE_SEEDS  # tuned on training seeds only
    assert LqrTuning.from_mapping(doc["best"]["tuning"]) == LqrTuning()
    loaded = load_policy("training/lqr_tuning.json")
    assert isinstance(loaded, LqrPolicy) and loaded.design.tuning == LqrTuning()


def test_the_policy_pickles_with_its_estimates(policy):
    obs = np.zeros((2, OBS_DIM), dtype=np.float32)
    obs[:, observation_indices("quat_w", "time_left")] = 1.0
    policy.reset()
    policy.predict(obs)
    copy = pickle.loads(pickle.dumps(policy))
    assert np.array_equal(copy.predict(obs), policy.predict(obs))


def test_evaluate_names_an_lqr_tuning_file_as_lqr(tmp_path):
    from accd_gym.evals.evaluation import evaluate

    results = evaluate(["training/lqr_tuning.json"], 2, tmp_path, num_envs=2, num_threads=1,
                       config={"capture_window": 1.0}, progress=False)
    assert "lqr (lqr_tuning)" in (tmp_path / "summary.md").read_text()
    assert list(results["policies"]) == ["training/lqr_tuning.json"]
