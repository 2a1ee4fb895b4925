"""Training, held-out evaluation, baselines and rollouts: short runs, sane results, files written."""

import json

import numpy as np
import pytest

import accd_gym
from accd_gym.learning import training
from accd_gym.control.registry import CONTROLLERS, make_controller
from accd_gym.control.baselines import GuidancePolicy, RandomPolicy, ZeroPolicy, quaternion_to_euler
from accd_gym.cli import main
from accd_gym.evals.evaluation import mcnemar_exact, paired_comparisons, run_episodes, summarize, wilson_interval
from accd_gym.envs.task import OBS_DIM, OBSERVATION_SCALE, observation_indices

SHORT = {"capture_window": 5.0}  # 50 agent steps per episode


def _obs(n=3, rel=(0.0, 0.0, 0.0)):
    """Observations of an ACCD level and at rest with the boom tip at ``rel`` (m) from the capture point."""
    o = np.zeros((n, OBS_DIM), dtype=np.float32)
    o[:, observation_indices("boom_rel_x", "boom_rel_y", "boom_rel_z")] = np.asarray(rel) * OBSERVATION_SCALE["boom_rel_x"]
    o[:, observation_indices("quat_w", "time_left")] = 1.0
    return o


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
def test_baselines_give_bounded_actions_of_the_right_shape(name):
    policy = make_controller(name, seed=3)
    obs = np.random.default_rng(0).uniform(-1, 1, (5, 25)).astype(np.float32)
    quat = observation_indices("quat_w", "quat_x", "quat_y", "quat_z")
    obs[:, quat] /= np.linalg.norm(obs[:, quat], axis=1, keepdims=True)
    a = policy.predict(obs)
    assert a.shape == (5, 4) and a.dtype == np.float32
    assert np.all(np.isfinite(a)) and np.all(np.abs(a) <= 1.0)
    with pytest.raises(ValueError, match="expected"):
        policy.predict(np.zeros((2, 24)))


def test_guidance_signs_follow_the_flap_conventions():
    g = GuidancePolicy(ki=0.0, kd=0.0)
    below = g.predict(_obs(rel=(0.0, 0.0, 2.0)))[0]  # boom below: go down = nose down = pitch < 0
    assert below[0] < 0 and below[1] < 0 and below[0] == pytest.approx(below[1])
    starboard = g.predict(_obs(rel=(0.0, 2.0, 0.0)))[0]  # boom to starboard: nose right = yaw > 0
    assert starboard[2] > 0 and starboard[3] > 0
    assert np.allclose(g.predict(_obs())[0], 0.0)


def test_guidance_integrator_resets_per_env():
    g = GuidancePolicy(kp=0.0, kd=0.0, ki=0.1)
    for _ in range(5):
        a = g.predict(_obs(n=2, rel=(0.0, 0.0, 1.0)))
    assert np.all(a[:, 0] < 0)
    g.reset(np.array([True, False]))
    a = g.predict(_obs(n=2, rel=(0.0, 0.0, 0.0)))
    assert a[0, 0] == pytest.approx(0.0) and a[1, 0] < 0


def test_random_policy_is_seeded():
    assert np.array_equal(RandomPolicy(5).predict(_obs(4)), RandomPolicy(5).predict(_obs(4)))
    assert not np.array_equal(RandomPolicy(5).predict(_obs(4)), RandomPolicy(6).predict(_obs(4)))


def test_quaternion_to_euler_of_a_pure_roll():
    half = np.radians(30.0) / 2
    roll, pitch, yaw = quaternion_to_euler(np.array([[np.cos(half), np.sin(half), 0.0, 0.0]]))
    assert np.degrees(roll[0]) == pytest.approx(30.0) and abs(pitch[0]) < 1e-12 and abs(yaw[0]) < 1e-12


def test_wilson_interval_matches_the_closed_form():
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.27753), abs=1e-4)
    assert wilson_interval(5, 10) == pytest.approx((0.23659, 0.76341), abs=1e-4)
    lo, hi = wilson_interval(10, 10)
    assert hi == pytest.approx(1.0) and lo == pytest.approx(0.72247, abs=1e-4)


def test_mcnemar_exact_matches_the_binomial_tail():
    """Two-sided exact McNemar: 2 P(X <= min(b, c)) for X ~ Binomial(b + c, 1/2), at most 1."""
    assert mcnemar_exact(0, 5) == 2 / 2**5
    assert mcnemar_exact(10, 2) == pytest.approx(2 * (1 + 12 + 66) / 2**12, rel=1e-15)
    assert mcnemar_exact(3, 3) == 1.0 and mcnemar_exact(0, 0) == 1.0 and mcnemar_exact(1, 0) == 1.0
    assert mcnemar_exact(196, 52) == mcnemar_exact(52, 196)
    assert mcnemar_exact(196, 52) == pytest.approx(7.591015324052e-21, rel=1e-9)  # scipy.stats.binomtest
    with pytest.raises(accd_gym.ConfigError, match="discordant"):
        mcnemar_exact(-1, 3)


def test_paired_comparisons_count_the_discordant_episodes():
    from types import SimpleNamespace as E

    runs = {"a": [E(captured=c) for c in (1, 1, 0, 0, 1)], "b": [E(captured=c) for c in (1, 0, 1, 0, 0)]}
    (c,) = paired_comparisons(runs)
    assert (c["a"], c["b"], c["both"], c["only_a"], c["only_b"]) == ("a", "b", 1, 2, 1)
    assert c["mcnemar_p"] == mcnemar_exact(2, 1)


def test_run_episodes_on_held_out_seeds_records_every_episode():
    seeds = list(accd_gym.HELD_OUT_WAKE_SEEDS[:5])
    eps = run_episodes(ZeroPolicy(), 5, wake_seeds=seeds, num_envs=2, num_threads=1, config=SHORT)
    assert [e.index for e in eps] == list(range(5))
    assert [e.wake_seed for e in eps] == seeds
    for e in eps:
        assert e.outcome in ("captured", "overload", "envelope_exit", "diverged", "truncated")
        assert 1 <= e.steps <= 50 and e.trajectory.shape == (e.steps + 1, 3)
        assert np.all(np.isfinite(e.trajectory)) and 0 <= e.min_distance <= e.trajectory.__len__() * 100
        assert e.min_distance <= np.linalg.norm(e.trajectory[0]) + 1e-3
        assert e.peak_tension > 0 and e.mean_abs_action == 0.0
    s = summarize(eps)
    assert s["episodes"] == 5 and 0.0 <= s["capture_rate"] <= 1.0
    assert s["capture_rate_ci95"][0] <= s["capture_rate"] <= s["capture_rate_ci95"][1]


def test_guidance_closes_in_on_the_boom_better_than_zero_flaps():
    """The tuned controller's miss distance beats neutral flaps on the same 8 training-seed episodes."""
    seeds = list(range(500, 508))
    cfg = {"capture_window": 20.0}
    zero = summarize(run_episodes(ZeroPolicy(), 8, seed=11, wake_seeds=seeds, num_envs=8, num_threads=1, config=cfg))
    guid = summarize(run_episodes(GuidancePolicy(), 8, seed=11, wake_seeds=seeds, num_envs=8, num_threads=1, config=cfg))
    assert guid["miss_distance_m"]["median"] < 0.5 * zero["miss_distance_m"]["median"]
    assert guid["captures"] > zero["captures"]


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
def test_rollout_command_with_each_baseline(name, capsys):
    rc = main(["rollout", "--policy", name, "--episodes", "3", "--num-envs", "3", "--num-threads", "1",
               "--env", json.dumps(SHORT), "--quiet", "--json"])
    assert rc == 0
    out = capsys.readouterr().out
    assert f"{name}: " in out and "captured" in out
    doc = json.loads(out[out.index("\n{") + 1:])
    assert len(doc["episodes"]) == 3 and all(1 <= e["steps"] <= 50 for e in doc["episodes"])


def test_bad_cli_input_names_the_value(capsys, tmp_path):
    assert main(["rollout", "--policy", "autopilot", "--episodes", "1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "autopilot" in err and "guidance" in err
    with pytest.raises(SystemExit):
        main(["rollout", "--policy", "zero", "--episodes", "0"])
    assert "--episodes = 0 is outside the allowed range" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"algo": "dqn"}))
    assert main(["train", "--config", str(bad), "--out", str(tmp_path / "run")]) == 2
    assert "`algo` = 'dqn'" in capsys.readouterr().err


def test_training_config_validation_names_the_field(tmp_path):
    with pytest.raises(accd_gym.ConfigError, match="learning_rat"):
        training.validate_config({"learning_rat": 1e-3})
    with pytest.raises(accd_gym.ConfigError, match="num_envs"):
        training.validate_config({"num_envs": 0})
    with pytest.raises(accd_gym.ConfigError, match="capture_windw"):
        training.validate_config({"env": {"capture_windw": 3}})
    for name in ("ppo", "sac"):
        cfg = training.load_config(f"training/{name}.json")
        assert cfg["algo"] == name
    assert training.load_config("training/sac.json")["vec_normalize"]["norm_reward"] is False


def test_short_ppo_training_then_held_out_evaluation(tmp_path):
    cfg = training.validate_config({
        "algo": "ppo", "total_timesteps": 256, "num_envs": 4, "num_threads": 1, "seed": 1, "env": SHORT,
        "algo_kwargs": {"n_steps": 32, "batch_size": 64, "n_epochs": 2},
        "policy_kwargs": {"net_arch": [16, 16]}, "checkpoint_every": 128,
    })
    run = tmp_path / "ppo"
    meta = training.train(cfg, run, progress=False)
    assert meta["timesteps"] >= 256 and meta["steps_per_s"] > 0
    for f in ("final_model.zip", "vecnormalize.pkl", "run.json"):
        assert (run / f).is_file()
    ckpt = run / "checkpoints" / "ppo_accd_128_steps.zip"
    assert ckpt.is_file() and (run / "checkpoints" / "ppo_accd_vecnormalize_128_steps.pkl").is_file()
    assert list((run / "tb").rglob("events.out.tfevents.*"))

    out = tmp_path / "eval"
    rc = main(["evaluate", "--policy", str(run), "--policy", str(ckpt), "--policy", "guidance", "--episodes", "3",
               "--num-envs", "3", "--num-threads", "1", "--env", json.dumps(SHORT), "--out", str(out), "--quiet"])
    assert rc == 0
    res = json.loads((out / "results.json").read_text())
    assert res["wake_seeds_held_out"] and res["wake_seeds"] == [10**9, 10**9 + 2]
    assert len(res["policies"]) == 3
    for doc in res["policies"].values():
        s = doc["summary"]
        assert s["episodes"] == 3 and np.isfinite(s["miss_distance_m"]["median"])
        assert [e["wake_seed"] for e in doc["episodes"]] == [10**9, 10**9 + 1, 10**9 + 2]
    # every policy starts from the same initial conditions (first trajectory point, per episode)
    traj = np.load(out / "trajectories.npz")
    for k in range(3):
        firsts = [traj[name][0] for name in traj.files if name.endswith(f"__{k}")]
        assert len(firsts) == 3 and all(np.array_equal(firsts[0], f) for f in firsts)
    md = (out / "summary.md").read_text()
    assert "| ppo |" in md and "| guidance |" in md and "Wilson" in md
    assert len(res["paired"]) == 3 and "McNemar" in md  # every pair of the three policies
    for c in res["paired"]:
        assert c["both"] + c["only_a"] + c["only_b"] <= 3 and 0 < c["mcnemar_p"] <= 1
    for png in ("trajectories.png", "miss_distance_cdf.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_guidance_tuning_file_is_a_policy_with_its_winning_gains(tmp_path):
    from accd_gym.evals.evaluation import _label, load_policy

    path = tmp_path / "tuning_x.json"
    path.write_text(json.dumps({"best": {"gains": {"kp": 0.3, "kd": 0.1, "ki": 0.0, "kq": 0.2}}}))
    policy = load_policy(str(path))
    assert isinstance(policy, GuidancePolicy)
    assert (policy.gains.kp, policy.gains.kd, policy.gains.kq) == (0.3, 0.1, 0.2)
    assert _label(str(path)) == "guidance (tuning_x)"
    bad = tmp_path / "not_tuning.json"
    bad.write_text("{}")
    with pytest.raises(accd_gym.ConfigError, match="not a guidance tuning file"):
        load_policy(str(bad))


def test_training_refuses_held_out_wake_seeds():
    for env in ({"wake_seed": 1_000_000_005}, {"wake_seeds": [3, 1_000_000_999]}):
        with pytest.raises(accd_gym.ConfigError, match="held-out"):
            training.validate_config({"env": env})
    training.validate_config({"env": {"wake_seed": 999_999_999}})


def test_ppo_updates_run_on_update_threads_and_the_envs_step_beside_torch_threads(tmp_path, monkeypatch):
    """``update_threads``: PyTorch has that many threads in every gradient update and
    ``torch_threads`` while the envs step, and the process keeps ``torch_threads`` afterwards."""
    import torch
    from stable_baselines3 import PPO

    seen = {"train": set(), "step": set()}
    train = PPO.train

    def recording_train(self):
        seen["train"].add(torch.get_num_threads())
        return train(self)

    monkeypatch.setattr(PPO, "train", recording_train)
    from accd_gym.envs.sb3 import AccdVecEnv

    step_wait = AccdVecEnv.step_wait

    def recording_step_wait(self):
        seen["step"].add(torch.get_num_threads())
        return step_wait(self)

    monkeypatch.setattr(AccdVecEnv, "step_wait", recording_step_wait)
    before = torch.get_num_threads()
    try:
        cfg = training.validate_config({
            "algo": "ppo", "total_timesteps": 96, "num_envs": 2, "num_threads": 1, "seed": 1, "env": SHORT,
            "torch_threads": 1, "update_threads": 3,
            "algo_kwargs": {"n_steps": 16, "batch_size": 32, "n_epochs": 1},
            "policy_kwargs": {"net_arch": [8]}, "checkpoint_every": 10**6,
        })
        training.train(cfg, tmp_path / "ppo", progress=False)
        assert seen == {"train": {3}, "step": {1}}
        assert torch.get_num_threads() == 1
        # 0 (the default) is torch_threads everywhere
        seen = {"train": set(), "step": set()}
        training.train(dict(cfg, update_threads=0), tmp_path / "ppo0", progress=False)
        assert seen == {"train": {1}, "step": {1}}
    finally:
        torch.set_num_threads(before)
    with pytest.raises(accd_gym.ConfigError, match="update_threads"):
        training.validate_config({"update_threads": -1})
    with pytest.raises(accd_gym.ConfigError, match="`update_threads` = 2 .* for algo 'sac'"):
        training.validate_config({"algo": "sac", "update_threads": 2})
