"""The asymmetric actor-critic (training config ``asymmetric_critic``): the critic's extra input is
the true observation at reset, every step and episode end; the actor never reads it; a run
trains, is evaluated on plain observations and exported like any other; a distilled student's
actor starts it with its input scaling kept."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
import torch  # noqa: E402

from accd_gym import ConfigError  # noqa: E402
from accd_gym.envs.task import OBS_DIM  # noqa: E402
from accd_gym.evals.policies import load_policy  # noqa: E402
from accd_gym.learning import distill, training  # noqa: E402
from accd_gym.learning.asymmetric import AsymmetricActorCriticPolicy, CriticObservation, TRUE_DIM  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SHORT = {"capture_window": 3.0}


def _config(**kw):
    cfg = {"algo": "ppo", "total_timesteps": 256, "num_envs": 4, "num_threads": 1, "seed": 1,
           "env": {**SHORT, "tier": "hard"}, "asymmetric_critic": True,
           "algo_kwargs": {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
           "policy_kwargs": {"net_arch": [16, 16]}, "checkpoint_every": 10_000}
    cfg.update(kw)
    return cfg


@pytest.mark.parametrize("tier", ["nominal", "hard"])
def test_the_critics_input_is_the_true_observation_at_reset_every_step_and_episode_end(tier):
    from stable_baselines3.common.vec_env import VecMonitor

    from accd_gym.envs.sb3 import AccdVecEnv

    plain = AccdVecEnv(3, seed=4, tier=tier, true_observation=True, capture_window=1.0)
    env = CriticObservation(VecMonitor(AccdVecEnv(3, seed=4, tier=tier, true_observation=True, capture_window=1.0)))
    assert env.observation_space.shape == (OBS_DIM + TRUE_DIM,) and env.actor_dim == OBS_DIM
    first = env.reset()
    np.testing.assert_array_equal(first[:, :OBS_DIM], plain.reset())
    np.testing.assert_array_equal(first[:, OBS_DIM:], [ri["true_obs"] for ri in plain.reset_infos])
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(25):  # 1 s windows: every env ends once at least
        a = rng.uniform(-1, 1, (3, 4)).astype(np.float32)
        obs, _, dones, infos = env.step(a)
        pobs, _, pdones, pinfos = plain.step(a)
        np.testing.assert_array_equal(obs[:, :OBS_DIM], pobs)
        for i in range(3):
            true_now = plain.reset_infos[i]["true_obs"] if pdones[i] else pinfos[i]["true_obs"]
            np.testing.assert_array_equal(obs[i, OBS_DIM:], true_now)
            if dones[i]:
                ended += 1
                end = infos[i]["terminal_observation"]
                np.testing.assert_array_equal(end[:OBS_DIM], pinfos[i]["terminal_observation"])
                np.testing.assert_array_equal(end[OBS_DIM:], pinfos[i]["true_obs"])  # the ended episode's last
        if tier == "nominal":  # perfect sensors: the true observation is the observation
            np.testing.assert_array_equal(obs[:, OBS_DIM:], obs[:, :OBS_DIM])
    assert ended >= 3
    if tier == "hard":  # the sensors' noise and delays: the critic sees something else
        assert not np.array_equal(obs[:, OBS_DIM:], obs[:, :OBS_DIM])
    env.close()
    plain.close()


def test_the_actor_never_reads_the_critics_inputs():
    from gymnasium import spaces

    space = spaces.Box(-10, 10, (OBS_DIM + TRUE_DIM,), np.float32)
    policy = AsymmetricActorCriticPolicy(space, spaces.Box(-1, 1, (4,), np.float32), lambda _: 3e-4,
                                         actor_dim=OBS_DIM, net_arch=[16, 16])
    x = torch.as_tensor(np.random.default_rng(1).normal(size=(5, OBS_DIM + TRUE_DIM)), dtype=torch.float32)
    y = x.clone()
    y[:, OBS_DIM:] += 3.0
    with torch.no_grad():
        np.testing.assert_array_equal(policy.get_distribution(x).distribution.mean,
                                      policy.get_distribution(y).distribution.mean)
        assert not torch.equal(policy.predict_values(x), policy.predict_values(y))
    # the standard policy's parameter names; only the critic's first layer is wider
    from stable_baselines3.common.policies import ActorCriticPolicy

    standard = ActorCriticPolicy(spaces.Box(-10, 10, (OBS_DIM,), np.float32), spaces.Box(-1, 1, (4,), np.float32),
                                 lambda _: 3e-4, net_arch=[16, 16])
    mine, theirs = policy.state_dict(), standard.state_dict()
    assert set(mine) == set(theirs)
    assert [k for k in mine if mine[k].shape != theirs[k].shape] == ["mlp_extractor.value_net.0.weight"]


def test_an_asymmetric_run_trains_then_acts_and_exports_on_plain_observations(tmp_path):
    from accd_gym import AccdVecEnv
    from accd_gym.evals.network import NetworkPolicy

    run = tmp_path / "run"
    meta = training.train(_config(checkpoint_every=128), run, progress=False)
    assert meta["status"] == "done" and meta["config"]["asymmetric_critic"] is True
    # stopped after its last checkpoint: resumes with the same policy class and critic input
    (run / "run.json").write_text(json.dumps({**json.loads((run / "run.json").read_text()), "status": "interrupted"}))
    (run / "final_model.zip").unlink()
    assert training.resume(run, progress=False)["status"] == "done"
    policy = load_policy(str(run))
    assert policy.critic_inputs == TRUE_DIM
    env = AccdVecEnv(4, seed=3, tier="hard", **SHORT)
    obs = env.reset()
    actions = policy.predict(obs)
    assert actions.shape == (4, 4) and np.all(np.isfinite(actions))
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from export_networks import export
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    export(run)
    net = NetworkPolicy(run)
    assert net.network.obs_dim == OBS_DIM
    np.testing.assert_allclose(net.predict(obs), actions, atol=1e-6)


def test_asymmetric_fine_tuning_starts_the_actor_from_the_student_and_learns_the_critics_scaling(tmp_path):
    from stable_baselines3 import PPO

    student = tmp_path / "student"
    env = {**SHORT, "tier": "hard", "history": 1}
    distill.train({"trainer": "distill", "teacher": "lqr", "env": env, "seed": 5, "num_envs": 4, "num_threads": 1,
                   "teacher_steps": 256, "rounds": 0, "round_steps": 256, "beta": {"start": 0.0}, "updates": 20,
                   "batch_size": 64, "learning_rate": 3e-3, "net_arch": [32, 32]}, student)
    cfg = training.validate_config(_config(env=env, init_from=str(student), policy_kwargs={
        "net_arch": {"pi": [32, 32], "vf": [32, 32]}, "activation_fn": "tanh", "log_std_init": -3.0}))
    venv, model = training._new_model(cfg, tmp_path / "ft")
    try:
        actor_dim = training.actor_dim(cfg)
        theirs = PPO.load(str(student / "final_model.zip"), device="cpu").policy.state_dict()
        own = model.policy.state_dict()
        for k, v in theirs.items():
            if k == "log_std" or k.startswith(("mlp_extractor.value_net.", "value_net.")):
                continue
            assert torch.equal(own[k], v), k  # the actor: the student's
        assert own["mlp_extractor.value_net.0.weight"].shape[1] == actor_dim + TRUE_DIM  # the critic: its own
        kept = load_policy(str(student)).normalizer.obs_rms
        np.testing.assert_array_equal(venv.obs_rms.mean[:actor_dim], kept.mean)
        model.learn(total_timesteps=64)
        np.testing.assert_array_equal(venv.obs_rms.mean[:actor_dim], kept.mean)  # the actor's scaling kept
        np.testing.assert_array_equal(venv.obs_rms.var[:actor_dim], kept.var)
        assert not np.allclose(venv.obs_rms.mean[actor_dim:], 0.0)  # the critic's learned from the steps
    finally:
        venv.close()


def test_bad_asymmetric_configs_are_refused_naming_the_key():
    with pytest.raises(ConfigError, match="`asymmetric_critic` = 1"):
        training.validate_config(_config(asymmetric_critic=1))
    with pytest.raises(ConfigError, match="`asymmetric_critic` = true .* PPO only"):
        training.validate_config(_config(algo="sac", algo_kwargs={}))
    with pytest.raises(ConfigError, match="env.true_observation"):
        training.validate_config(_config(env={**SHORT, "true_observation": True}))
    # false, or absent: the config validates to the dict it always did
    assert "asymmetric_critic" not in training.validate_config(_config(asymmetric_critic=False))
