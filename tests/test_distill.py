"""Behaviour cloning and DAgger (accd_gym.learning.distill): the student fits a known teacher, the
teacher labels the states the student visits, runs are deterministic and resume to the same
weights, the run folder is a policy for load_policy, the benchmark and RL fine-tuning, and the CLI
reports bad input on one line."""

import json

import numpy as np
import pytest
import torch

from accd_gym.cli import main
from accd_gym.envs.task import OBS_DIM, VALIDATION_WAKE_SEEDS
from accd_gym.evals.episodes import VALIDATION_BASE_SEED
from accd_gym.evals.policies import SB3Policy, load_policy
from accd_gym.learning import distill, training

SHORT = {"capture_window": 5.0}
W = np.random.default_rng(3).normal(0.0, 0.4, size=(OBS_DIM, 4)).astype(np.float32)


class LinearTeacher:
    """A known teacher: flaps = clip(obs W, -1, 1); records every observation it labels and every
    offset it is told (the commands sent minus its own)."""

    name = "linear"

    def __init__(self) -> None:
        self.seen: list[np.ndarray] = []
        self.offsets: list[np.ndarray] = []

    def predict(self, obs):
        o = np.asarray(obs, dtype=np.float32)
        self.seen.append(o.copy())
        return np.clip(o @ W, -1.0, 1.0).astype(np.float32)

    def reset(self, mask=None):
        pass

    def sent(self, offset):
        self.offsets.append(np.array(offset))

    def get_state(self):
        return {}

    def set_state(self, state):
        pass


def _recipe(**kw):
    cfg = {"trainer": "distill", "teacher": "linear", "env": {**SHORT, "history": 1}, "seed": 5, "num_envs": 4,
           "num_threads": 1, "teacher_steps": 256, "rounds": 2, "round_steps": 256, "beta": {"start": 0.0},
           "updates": 40, "batch_size": 64, "learning_rate": 3e-3, "net_arch": [32, 32]}
    cfg.update(kw)
    return cfg


def _weights(run):
    from stable_baselines3 import PPO

    return PPO.load(str(run / "final_model.zip"), device="cpu").policy.state_dict()


def test_bc_fits_a_known_linear_teacher(tmp_path):
    teacher = LinearTeacher()
    meta = distill.train(_recipe(rounds=0, teacher_steps=2048, updates=600, batch_size=128, env=SHORT), tmp_path / "bc",
                         make_teacher=lambda *a: teacher)
    assert meta["status"] == "done" and meta["method"] == "bc"
    policy = load_policy(str(tmp_path / "bc"))
    assert isinstance(policy, SB3Policy)
    with np.load(tmp_path / "bc" / "checkpoints" / "data_00.npz") as z:
        obs, labels = z["obs"], z["labels"]
    # the labels are the teacher's commands for the stored observations
    np.testing.assert_array_equal(labels, np.clip(obs[:, :OBS_DIM] @ W, -1, 1))
    err = float(np.mean((policy.predict(obs) - labels) ** 2))
    assert err < 0.05 * float(np.var(labels)), (err, float(np.var(labels)))


def test_dagger_relabels_the_students_visited_states(tmp_path):
    teacher = LinearTeacher()
    run = tmp_path / "dagger"
    distill.train(_recipe(), run, make_teacher=lambda *a: teacher)
    with np.load(run / "checkpoints" / "data_01.npz") as z:
        obs, labels = z["obs"], z["labels"]
    n = 4
    calls = np.concatenate(teacher.seen)
    round1 = calls[256:512]  # round 0: 64 vector steps of 4 envs, then round 1
    # the teacher was asked about exactly the observations round 1 visited, and labelled them
    np.testing.assert_array_equal(round1, obs[:, :OBS_DIM])
    np.testing.assert_array_equal(labels, np.clip(obs[:, :OBS_DIM] @ W, -1, 1))
    # beta 0: the student flew round 1 (the command of step t is in step t+1's history) ...
    from stable_baselines3 import PPO
    from accd_gym.learning.training import load_statistics

    student = PPO.load(str(run / "checkpoints" / "student_00.zip"), device="cpu").policy
    stats = load_statistics((run / "vecnormalize.pkl").read_bytes(), "vecnormalize.pkl", obs_dim=obs.shape[1])
    u_student = distill.student_actions(student, stats.normalize_obs(obs))
    nxt_cmd = obs[n:, -4:]
    same_episode = np.any(nxt_cmd != 0, axis=1)  # a new episode's history holds zero commands
    assert same_episode.sum() > 100
    np.testing.assert_array_equal(nxt_cmd[same_episode], u_student[:-n][same_episode])
    # ... its commands differ from the teacher's, and the teacher was told the difference
    assert np.abs(u_student - labels).max() > 1e-3
    assert teacher.offsets and np.abs(np.concatenate(teacher.offsets)).max() > 1e-3


def test_action_noise_perturbs_the_commands_sent_and_keeps_the_labels_clean(tmp_path):
    """DART: with ``action_noise`` every command sent (the teacher's in round 0, the mix in the DAgger
    rounds) carries Gaussian noise of that standard deviation, the teacher is told it, and the labels
    stay the teacher's own commands; without the key the recipe validates as before."""
    assert "action_noise" not in distill.validate_recipe(_recipe())
    teacher = LinearTeacher()
    run = tmp_path / "dart"
    distill.train(_recipe(action_noise=0.2, beta={"start": 1.0, "decay": 1.0}), run, make_teacher=lambda *a: teacher)
    n = 4
    told = np.concatenate(teacher.offsets)  # one row per env and step: every step's commands were perturbed
    assert told.shape == (768, 4)  # rounds 0, 1 and 2
    for k in (0, 1, 2):
        with np.load(run / "checkpoints" / f"data_0{k}.npz") as z:
            obs, labels = z["obs"], z["labels"]
        np.testing.assert_array_equal(labels, np.clip(obs[:, :OBS_DIM] @ W, -1, 1))
        # the command of step t (in step t+1's history) is the teacher's plus the noise ...
        sent = obs[n:, -4:]
        same_episode = np.any(sent != 0, axis=1)
        noise = (sent - labels[:-n])[same_episode]
        inside = np.abs(sent[same_episode]) < 1.0  # the clip at the flap range leaves these alone
        assert noise.size > 400 and 0.17 < float(noise[inside].std()) < 0.23, float(noise[inside].std())
        assert abs(float(noise[inside].mean())) < 0.03
        # ... and the teacher was told exactly that offset
        np.testing.assert_allclose(told[k * 256:(k + 1) * 256][:-n][same_episode], noise, atol=1e-6)
    # the same seed draws the same noise; the noise is refused outside its range, named
    distill.train(_recipe(action_noise=0.2, beta={"start": 1.0, "decay": 1.0}), tmp_path / "again",
                  make_teacher=lambda *a: LinearTeacher())
    a, b = _weights(run), _weights(tmp_path / "again")
    assert all(torch.equal(a[k], b[k]) for k in a)
    with pytest.raises(distill.ConfigError, match="`action_noise` = -0.1"):
        distill.validate_recipe(_recipe(action_noise=-0.1))


def test_same_seed_same_weights_and_resume_gives_the_same_result(tmp_path):
    make = lambda *a: LinearTeacher()  # noqa: E731
    distill.train(_recipe(), tmp_path / "a", make_teacher=make)
    distill.train(_recipe(), tmp_path / "b", make_teacher=make)
    a, b = _weights(tmp_path / "a"), _weights(tmp_path / "b")
    assert all(torch.equal(a[k], b[k]) for k in a)

    def stop_after_round_0(line):
        if line.startswith("round 0/"):
            raise KeyboardInterrupt("test")

    meta = distill.train(_recipe(), tmp_path / "c", make_teacher=make, report=stop_after_round_0)
    assert meta["status"] == "interrupted" and len(meta["rounds"]) == 1
    assert distill.completed_rounds(tmp_path / "c") == 1
    lines = []
    meta = distill.resume(tmp_path / "c", make_teacher=make, report=lines.append)
    assert meta["status"] == "done" and [r["round"] for r in meta["rounds"]] == [0, 1, 2]
    assert lines[0].startswith("round 1/2")
    c = _weights(tmp_path / "c")
    assert all(torch.equal(a[k], c[k]) for k in a)
    with pytest.raises(distill.ConfigError, match="complete"):
        distill.resume(tmp_path / "c", make_teacher=make)
    other = distill.train(_recipe(seed=6), tmp_path / "d", make_teacher=make)
    assert other["status"] == "done"
    d = _weights(tmp_path / "d")
    assert not all(torch.equal(a[k], d[k]) for k in a)


def test_load_policy_runs_a_distilled_lqr_student_on_the_plain_env(tmp_path):
    """The LQR as teacher (stateful: its filter follows the student's trajectory); the run folder
    is a policy with the history option, acting on plain observations."""
    run = tmp_path / "lqr"
    meta = distill.train(_recipe(teacher="lqr", rounds=1, beta={"start": 0.5}), run)
    assert meta["status"] == "done" and meta["rounds"][1]["student_mse"] is not None
    policy = load_policy(str(run))
    assert policy.agent_options.history == 1
    with np.load(run / "checkpoints" / "data_00.npz") as z:
        first = z["obs"][:4]  # the envs' first observations: history = the observation, zero commands
    np.testing.assert_array_equal(first[:, OBS_DIM:2 * OBS_DIM], first[:, :OBS_DIM])
    from stable_baselines3 import PPO
    from accd_gym.learning.training import load_statistics

    student = PPO.load(str(run / "final_model.zip"), device="cpu").policy
    stats = load_statistics((run / "vecnormalize.pkl").read_bytes(), "vecnormalize.pkl", obs_dim=first.shape[1])
    expected = distill.student_actions(student, stats.normalize_obs(first))
    np.testing.assert_allclose(policy.predict(first[:, :OBS_DIM]), expected, atol=1e-6)
    # the torch-free export takes the run as any run (scripts/export_networks.py)
    import sys
    from pathlib import Path

    from accd_gym.evals.network import NetworkPolicy

    scripts = str(Path(__file__).resolve().parents[1] / "scripts")
    sys.path.insert(0, scripts)
    try:
        from export_networks import export
    finally:
        sys.path.remove(scripts)
    export(run)
    net = NetworkPolicy(run)
    np.testing.assert_allclose(net.predict(first[:, :OBS_DIM]), expected, atol=1e-5)


def test_fine_tuning_starts_from_the_student(tmp_path):
    run = tmp_path / "s"
    distill.train(_recipe(rounds=0), run, make_teacher=lambda *a: LinearTeacher())
    cfg = training.validate_config({"algo": "ppo", "num_envs": 4, "num_threads": 1, "seed": 1,
                                    "env": {**SHORT, "history": 1}, "init_from": str(run),
                                    "algo_kwargs": {"n_steps": 16, "batch_size": 64},
                                    "policy_kwargs": {"net_arch": {"pi": [32, 32], "vf": [32, 32]}, "activation_fn": "tanh",
                                                      "log_std_init": -3.0}})
    env, model = training._new_model(cfg, tmp_path / "ft")
    try:
        student = _weights(run)
        own = model.policy.state_dict()
        assert all(torch.equal(own[k], v) for k, v in student.items() if k != "log_std")
        assert torch.all(own["log_std"] == -3.0)
        stats = load_policy(str(run)).normalizer
        np.testing.assert_array_equal(env.obs_rms.mean, stats.obs_rms.mean)
        # the student's input scaling stays fixed while PPO steps the envs
        model.learn(total_timesteps=64)
        np.testing.assert_array_equal(env.obs_rms.mean, stats.obs_rms.mean)
        np.testing.assert_array_equal(env.obs_rms.var, stats.obs_rms.var)
        assert env.ret_rms.count > 1  # the rewards are still normalised as configured
    finally:
        env.close()
    with pytest.raises(training.ConfigError, match="init_from"):
        training.validate_config({"algo": "sac", "init_from": str(run)})
    with pytest.raises(training.ConfigError, match="init_from"):
        training.validate_config({"init_from": str(tmp_path / "missing")})
    with pytest.raises(training.ConfigError, match="another network"):
        training._new_model(training.validate_config({**cfg, "policy_kwargs": {"net_arch": [8]}}), tmp_path / "ft2")
    # a config without init_from validates to the same dict as before the key existed
    assert "init_from" not in training.validate_config({})


def test_benchmark_job_trains_and_evaluates_a_distillation_recipe(tmp_path):
    from accd_gym.evals import benchmark

    recipe = tmp_path / "bc.json"
    recipe.write_text(json.dumps(_recipe(teacher="lqr", rounds=0, env={"history": 1}, updates=20)))
    job = benchmark.Job("nominal", "bc", 0, str(recipe), 256)
    result = benchmark.run_job(job, str(tmp_path / "bench"), 2, 2, 1, validation_episodes=2)
    assert result["status"] == "done" and len(result["validation"]["captured"]) == 2
    assert benchmark.run_job(job, str(tmp_path / "bench"), 2, 2, 1, validation_episodes=2)["reused"]
    with pytest.raises(benchmark.ConfigError, match="total_timesteps"):
        benchmark.run_job(benchmark.Job("nominal", "bc", 1, str(recipe), 999), str(tmp_path / "bench"), 2, 2, 1)
    cfg = benchmark.load_config("training/benchmark.json")
    assert {"bc", "dagger"} <= set(cfg["learners"])
    for algo in ("bc", "dagger"):
        for tier, path in cfg["learners"][algo]["train_config"].items():
            recipe = distill.load_recipe(path, total_timesteps=cfg["learners"][algo]["timesteps"])
            assert recipe["env"]["tier"] == tier


@pytest.mark.parametrize("recipe, args, needle", [
    ({"rounds": -1}, [], "`rounds` = -1"),
    ({"beta": {"start": 2}}, [], "`beta.start` = 2"),
    ({"env": {"residual": "lqr"}}, [], "history"),
    ({"total_timesteps": 5}, [], "`total_timesteps` = 5"),
    ({"device": "gpu0"}, [], "`device` = 'gpu0'"),
    ({}, ["--resume", "nowhere"], "--resume"),
])
def test_cli_errors_are_one_line(tmp_path, capsys, recipe, args, needle):
    path = tmp_path / "r.json"
    path.write_text(json.dumps({**_recipe(teacher="lqr"), **recipe}))
    argv = ["distill", *args] if args else ["distill", "--config", str(path), "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("accd-gym: error:") and needle in err, err


def test_evaluate_validation_uses_the_validation_episodes(tmp_path):
    assert main(["evaluate", "--policy", "zero", "--episodes", "2", "--num-envs", "2", "--validation",
                 "--env", json.dumps(SHORT), "--out", str(tmp_path / "e"), "--quiet"]) == 0
    doc = json.loads((tmp_path / "e" / "results.json").read_text())
    assert doc["wake_seeds"] == [VALIDATION_WAKE_SEEDS[0], VALIDATION_WAKE_SEEDS[1]]
    assert doc["base_seed"] == VALIDATION_BASE_SEED and not doc["wake_seeds_held_out"]


def test_a_teacher_giving_nan_and_a_diverging_student_are_reported(tmp_path):
    class NanTeacher(LinearTeacher):
        def predict(self, obs):
            return np.full((len(obs), 4), np.nan, dtype=np.float32)

    with pytest.raises(distill.StateError, match="non-finite"):
        distill.train(_recipe(), tmp_path / "nan", make_teacher=lambda *a: NanTeacher())

    class HugeTeacher(LinearTeacher):
        def predict(self, obs):
            return np.full((len(obs), 4), 1e30, dtype=np.float32)

    with pytest.raises(distill.ConfigError, match="diverged"):
        distill.train(_recipe(rounds=0), tmp_path / "huge", make_teacher=lambda *a: HugeTeacher())


def test_critic_warmup_trains_only_the_critic_first(tmp_path):
    run = tmp_path / "s"
    distill.train(_recipe(rounds=0), run, make_teacher=lambda *a: LinearTeacher())
    base = {"algo": "ppo", "num_envs": 4, "num_threads": 1, "seed": 1, "total_timesteps": 128,
            "env": {**SHORT, "history": 1}, "init_from": str(run), "algo_kwargs": {"n_steps": 16, "batch_size": 32},
            "policy_kwargs": {"net_arch": {"pi": [32, 32], "vf": [32, 32]}, "activation_fn": "tanh"}}
    student = _weights(run)

    def trained(warmup):
        out = tmp_path / f"ft{warmup}"
        training.train(training.validate_config({**base, "critic_warmup": warmup}), out, progress=False)
        return _weights(out)

    frozen = trained(128)  # the whole run is warm-up: the actor is the student's, the critic learned
    assert all(torch.equal(frozen[k], v) for k, v in student.items() if k.startswith(("mlp_extractor.policy_net", "action_net")))
    assert not torch.equal(frozen["value_net.weight"], student["value_net.weight"])
    after = trained(64)  # warm-up for half the run, then the actor learns too
    assert not torch.equal(after["action_net.weight"], student["action_net.weight"])
    with pytest.raises(training.ConfigError, match="critic_warmup"):
        training.validate_config({"critic_warmup": 10})


def test_a_benchmark_fine_tuning_job_starts_from_the_run_of_its_tier_and_seed(tmp_path):
    from accd_gym.evals import benchmark

    bc = tmp_path / "bc.json"
    bc.write_text(json.dumps(_recipe(teacher="lqr", rounds=0, env={"history": 1}, updates=20)))
    ft = tmp_path / "ft.json"
    ft.write_text(json.dumps({"algo": "ppo", "num_envs": 4, "env": {"history": 1},
                              "algo_kwargs": {"n_steps": 16, "batch_size": 32, "n_epochs": 1},
                              "policy_kwargs": {"net_arch": {"pi": [32, 32], "vf": [32, 32]}, "activation_fn": "tanh",
                                                "log_std_init": -3.0}, "checkpoint_every": 10_000}))
    raw = {"tiers": ["nominal"], "baselines": ["zero"], "episodes": 2, "validation_episodes": 2, "num_envs": 2,
           "learners": {"bc": {"train_config": str(bc), "seeds": [0, 1], "timesteps": 256},
                        "bc_ppo": {"train_config": str(ft), "seeds": [1], "timesteps": 64, "init_from": "bc"}}}
    cfg = benchmark.validate_config(raw)
    jobs = benchmark.jobs(cfg)
    (tuned,) = [j for j in jobs if j.algo == "bc_ppo"]
    assert tuned.source == "nominal_bc_seed1" and all(j.source is None for j in jobs if j.algo == "bc")
    out = tmp_path / "bench"
    # Its run must exist first; the benchmark runs the jobs that start afresh first.
    with pytest.raises(benchmark.ConfigError, match="nominal_bc_seed1.*not trained.*--algos bc"):
        benchmark.run_job(tuned, str(out), 2, 2, 1, validation_episodes=2)
    doc = benchmark.run(cfg, out, progress=lambda _: None)
    assert {r["name"] for r in doc["runs"]} >= {"nominal_bc_seed0", "nominal_bc_seed1", "nominal_bc_ppo_seed1"}
    meta = json.loads((out / "runs" / "nominal_bc_ppo_seed1" / "run.json").read_text())
    assert meta["status"] == "done" and meta["config"]["init_from"] == str(out.resolve() / "runs" / "nominal_bc_seed1")
    # Started from that student: its weights (but log_std) before any update equal the student's.
    cfg_ft = training.validate_config(meta["config"])
    env, model = training._new_model(cfg_ft, tmp_path / "probe")
    try:
        student = _weights(out / "runs" / "nominal_bc_seed1")
        assert all(torch.equal(model.policy.state_dict()[k], v) for k, v in student.items() if k != "log_std")
    finally:
        env.close()
    # The folder moved elsewhere: the fine-tuned run is still its job's training (by the name of
    # the run it started from, not its path).
    from accd_gym.learning import run_state

    moved = dict(meta["config"], init_from="/elsewhere/runs/nominal_bc_seed1")
    assert run_state.same_recipe(meta["config"], moved)
    assert not run_state.same_recipe(meta["config"], dict(moved, init_from="/elsewhere/runs/nominal_bc_seed0"))
    # The run records the student it started from: the same student there, it is the job's
    # training; the student trained again (other weights), it is not, and the benchmark trains
    # the fine-tuning again, keeping the earlier one under OUT/superseded.
    run = out / "runs" / "nominal_bc_ppo_seed1"
    assert meta["init_from_digest"] == training.start_digest(out / "runs" / "nominal_bc_seed1")
    assert run_state.trained(run, cfg_ft)
    student_zip = out / "runs" / "nominal_bc_seed1" / "final_model.zip"
    student_zip.write_bytes(student_zip.read_bytes() + b"\0")
    assert not run_state.trained(run, cfg_ft)
    fresh = benchmark.run_job(tuned, str(out), 2, 2, 1, validation_episodes=2)
    assert fresh["trained_now"] and not fresh["reused"]
    assert json.loads((run / "run.json").read_text())["init_from_digest"] == training.start_digest(student_zip.parent)
    assert [p.name for p in (out / "superseded").iterdir()] == ["nominal_bc_ppo_seed1-1"]
    # A fine-tuned run that recorded no digest (an earlier version's) is not taken for the job's.
    old = dict(json.loads((run / "run.json").read_text()))
    old.pop("init_from_digest")
    assert not run_state.same_start(old, cfg_ft["init_from"]) and run_state.same_start(old, None)
    # The jobs that start afresh keep the keys they always had (no `init_from` entry).
    assert "init_from" not in benchmark.job_key(jobs[0], 2, 2)["job"]
    assert benchmark.job_key(tuned, 2, 2)["job"]["init_from"] == "bc"


@pytest.mark.parametrize("init_from, needle", [("dagger", "another learner"), ("bc_ppo", "another learner"),
                                               ("bc", r"no run for \['seed 7'\]")])
def test_a_fine_tuning_learner_names_a_learner_with_its_tiers_and_seeds(tmp_path, init_from, needle):
    from accd_gym.evals import benchmark

    recipe = tmp_path / "r.json"
    recipe.write_text("{}")
    raw = {"tiers": ["nominal"], "learners": {"bc": {"train_config": str(recipe), "seeds": [0], "timesteps": 1},
                                              "bc_ppo": {"train_config": str(recipe), "seeds": [0, 7], "timesteps": 1,
                                                         "init_from": init_from}}}
    with pytest.raises(benchmark.ConfigError, match=rf"`learners.bc_ppo.init_from` = .*{needle}"):
        benchmark.validate_config(raw)


def test_a_benchmark_distillation_learns_from_the_validation_chosen_run_of_its_teacher_learner(tmp_path):
    """``teacher_from``: the student's teacher is the other learner's run of its tier with the
    best validation record, named by its folder and recorded by its digest; a teacher trained
    again makes the student stale; the job waits for the teacher learner's runs."""
    from accd_gym.evals import benchmark
    from accd_gym.learning import run_state

    bc = tmp_path / "bc.json"
    bc.write_text(json.dumps(_recipe(teacher="lqr", rounds=0, env={"history": 1}, updates=20)))
    student = tmp_path / "student.json"
    student.write_text(json.dumps(_recipe(teacher="lqr", rounds=1, env={"history": 2}, beta={"start": 0.5}, updates=20)))
    raw = {"tiers": ["nominal"], "baselines": ["zero"], "episodes": 2, "validation_episodes": 2, "num_envs": 2,
           "learners": {"bc": {"train_config": str(bc), "seeds": [0, 1], "timesteps": 256},
                        "bc_dagger": {"train_config": str(student), "seeds": [3], "timesteps": 512, "teacher_from": "bc"}}}
    cfg = benchmark.validate_config(raw)
    (job,) = [j for j in benchmark.jobs(cfg) if j.algo == "bc_dagger"]
    assert job.teacher_from == "bc" and job.teacher is None
    out = tmp_path / "bench"
    with pytest.raises(benchmark.ConfigError, match="not every bc run of nominal is finished.*--algos bc"):
        benchmark.run_job(job, str(out), 2, 2, 1, validation_episodes=2)
    assert benchmark.with_teacher(job, out, cfg) == job  # nothing finished: no teacher
    doc = benchmark.run(cfg, out, progress=lambda _: None)
    assert {r["name"] for r in doc["runs"]} >= {"nominal_bc_seed0", "nominal_bc_seed1", "nominal_bc_dagger_seed3"}
    records = {}
    for name in ("nominal_bc_seed0", "nominal_bc_seed1"):
        stored = json.loads((out / "runs" / name / "result.json").read_text())["result"]
        records[name] = stored["validation"]["captured"]
    chosen = benchmark.choose_run(records)
    resolved = benchmark.with_teacher(job, out, cfg)
    assert resolved.teacher == chosen and resolved.name == job.name
    # The held-out records play no part: made to favour the other run, the choice stays.
    for name, value in records.items():
        path = out / "runs" / name / "result.json"
        doc = json.loads(path.read_text())
        doc["result"]["episodes"]["captured"] = [name != chosen] * 2
        path.write_text(json.dumps(doc))
    assert benchmark.with_teacher(job, out, cfg).teacher == chosen
    run = out / "runs" / "nominal_bc_dagger_seed3"
    meta = json.loads((run / "run.json").read_text())
    teacher = out.resolve() / "runs" / chosen
    assert meta["config"]["teacher"] == str(teacher) and meta["teacher_digest"] == training.start_digest(teacher)
    key = benchmark.job_key(resolved, 2, 2, 2)["job"]
    assert key["teacher_from"] == "bc" and key["teacher"] == chosen
    assert "teacher" not in benchmark.job_key(benchmark.jobs(cfg)[0], 2, 2)["job"]
    # The folder moved: the same training (the teacher by its folder's name and digest).
    assert run_state.same_recipe(meta["config"], dict(meta["config"], teacher=f"/elsewhere/runs/{chosen}"))
    # The teacher trained again (other weights): the student is stale and trained again, the
    # earlier one kept under OUT/superseded.
    cfg_student = distill.validate_recipe(meta["config"])
    assert run_state.trained(run, cfg_student)
    model = teacher / "final_model.zip"
    model.write_bytes(model.read_bytes() + b"\0")
    assert not run_state.trained(run, cfg_student)
    fresh = benchmark.run_job(resolved, str(out), 2, 2, 1, validation_episodes=2)
    assert fresh["trained_now"] and not fresh["reused"]
    assert json.loads((run / "run.json").read_text())["teacher_digest"] == training.start_digest(teacher)
    assert [p.name for p in (out / "superseded").iterdir()] == ["nominal_bc_dagger_seed3-1"]


def test_an_interrupted_distillation_resumes_only_with_its_teacher_unchanged(tmp_path):
    from accd_gym.evals import benchmark

    teacher = tmp_path / "teacher"
    distill.train(_recipe(teacher="lqr", rounds=0, env={"history": 1}, updates=20), teacher,
                  make_teacher=benchmark._teacher)
    run = tmp_path / "s"
    cfg = _recipe(teacher=str(teacher), rounds=2, env={"history": 1}, beta={"start": 0.5}, updates=20)
    meta = distill.train(cfg, run, make_teacher=benchmark._teacher)
    assert meta["teacher_digest"] == distill.teacher_digest(str(teacher)) == training.start_digest(teacher)
    # An interruption after round 1: the run continues with the same teacher, not another.
    data = json.loads((run / "run.json").read_text())
    data["status"] = "interrupted"
    (run / "run.json").write_text(json.dumps(data))
    (run / "checkpoints" / "student_02.zip").unlink()
    model = teacher / "final_model.zip"
    saved = model.read_bytes()
    model.write_bytes(saved + b"\0")
    with pytest.raises(distill.ConfigError, match="taught by another policy than the teacher"):
        distill.resume(run, make_teacher=benchmark._teacher)
    model.write_bytes(saved)
    assert distill.resume(run, make_teacher=benchmark._teacher)["status"] == "done"
    assert distill.teacher_digest("lqr") is None


@pytest.mark.parametrize("learner, needle", [
    ({"teacher_from": "dagger"}, "another learner of this config that starts afresh"),
    ({"teacher_from": "bc", "init_from": "bc"}, "sets both `init_from` and `teacher_from`"),
    ({"teacher_from": "bc", "train_config": "SB3"}, "needs distillation recipes"),
    ({"teacher_from": "bc", "tiers": ["nominal", "hard"], "train_config": None}, r"no run on the tiers \['hard'\]"),
])
def test_a_distillation_learner_names_a_teacher_learner_with_its_tiers(tmp_path, learner, needle):
    from accd_gym.evals import benchmark

    recipe = tmp_path / "r.json"
    recipe.write_text(json.dumps(_recipe(teacher="lqr")))
    sb3 = tmp_path / "sb3.json"
    sb3.write_text("{}")
    spec = {"train_config": str(recipe), "seeds": [0], "timesteps": 768, "tiers": ["nominal"], **learner}
    if spec["train_config"] == "SB3":
        spec["train_config"] = str(sb3)
    elif spec["train_config"] is None:
        spec["train_config"] = str(recipe)
    raw = {"tiers": ["nominal", "hard"],
           "learners": {"bc": {"train_config": str(recipe), "seeds": [0], "timesteps": 768, "tiers": ["nominal"]},
                        "student": spec}}
    with pytest.raises(benchmark.ConfigError, match=needle):
        benchmark.validate_config(raw)


def test_a_distillation_into_a_folder_that_holds_a_run_is_refused(tmp_path):
    run = tmp_path / "s"
    distill.train(_recipe(rounds=0), run, make_teacher=lambda *a: LinearTeacher())
    model = (run / "final_model.zip").read_bytes()
    with pytest.raises(distill.ConfigError, match="already holds a run.*--resume"):
        distill.train(_recipe(rounds=0, seed=6), run, make_teacher=lambda *a: LinearTeacher())
    assert (run / "final_model.zip").read_bytes() == model
