"""accd-gym benchmark: its statistics against closed forms and scipy, its config checks, and the
whole pipeline in its --quick mode (every tier, PPO and SAC, every baseline, the report)."""

import json
from pathlib import Path

import numpy as np
import pytest

from accd_gym import ConfigError
from accd_gym.evals import benchmark

ROOT = Path(__file__).resolve().parents[1]


def test_iqm_is_scipys_trimmed_mean():
    from scipy.stats import trim_mean

    rng = np.random.default_rng(1)
    for n in (1, 2, 3, 4, 5, 8, 13):
        x = rng.uniform(size=n)
        assert benchmark.iqm(x) == pytest.approx(trim_mean(x, 0.25), abs=1e-15)


def test_stratified_bootstrap_covers_the_rate_and_narrows_with_episodes():
    # Five seeds of the same true rate: the interval holds it, and shrinks like 1/sqrt(n).
    widths = []
    for n in (100, 1600):
        rng = np.random.default_rng(n)
        caps = [rng.uniform(size=n) < 0.6 for _ in range(5)]
        lo, hi = benchmark.stratified_bootstrap(caps, resamples=4000)
        assert lo < 0.6 < hi
        widths.append(hi - lo)
    assert 2.5 < widths[0] / widths[1] < 6.0  # 4x fewer... sqrt(16) = 4
    # Seeds that disagree widen it beyond the episode noise alone.
    caps = [np.arange(400) < k for k in (80, 160, 240, 320, 390)]
    lo, hi = benchmark.stratified_bootstrap(caps, resamples=4000)
    assert hi - lo > 0.3
    # Deterministic: a fixed generator seed.
    assert benchmark.stratified_bootstrap(caps) == benchmark.stratified_bootstrap(caps)


@pytest.mark.parametrize(
    "raw, field",
    [({"tiers": ["nope"]}, "tiers"), ({"episodes": 0}, "episodes"), ({"episodes": 5000}, "episodes"),
     ({"baselines": ["pid"]}, "baselines"), ({"learners": {"a2c": {}}}, "learners.a2c"),
     ({"learners": {"ppo": {"train_config": "training/ppo.json", "seeds": [], "timesteps": 10}}}, "learners.ppo.seeds"),
     ({"learners": {"ppo": {"train_config": "training/ppo.json", "seeds": [1, 1], "timesteps": 10}}}, "learners.ppo.seeds"),
     ({"learners": {"ppo": {"train_config": "nope.json", "seeds": [1], "timesteps": 10}}}, "learners.ppo.train_config"),
     ({"cpus": 2}, "cpus")],
)
def test_bad_configs_are_refused_naming_the_key(raw, field):
    with pytest.raises(ConfigError, match=rf"`?{field}"):
        benchmark.validate_config(raw, root=ROOT)


def test_jobs_follow_the_config():
    cfg = benchmark.load_config(ROOT / "training" / "benchmark.json")
    jobs = benchmark.jobs(cfg)
    ppo = [j for j in jobs if j.algo == "ppo"]
    sac = [j for j in jobs if j.algo == "sac"]
    assert len(ppo) == 5 * len(cfg["tiers"]) and {j.seed for j in ppo} == {0, 1, 2, 3, 4}
    assert not sac  # the untuned plain SAC recipe only in the quick run (docs/decisions.md)
    # plain PPO and SAC tuned on validation episodes, at the rl-zoo3 budgets, on precision and hard
    tuned = [j for j in jobs if j.algo in ("ppo_tuned", "sac_tuned")]
    assert {(j.algo, j.tier) for j in tuned} == {(a, t) for a in ("ppo_tuned", "sac_tuned") for t in ("precision", "hard")}
    assert all(j.train_config.endswith(f"{j.algo[:3]}_{j.tier}.json") for j in tuned) and len(tuned) == 20
    assert {j.timesteps for j in tuned if j.algo == "ppo_tuned"} == {3_000_000}
    assert {j.timesteps for j in tuned if j.algo == "sac_tuned"} == {500_000}
    assert cfg["episodes"] == 500
    quick = benchmark.load_config(ROOT / "training" / "benchmark.json", quick=True)
    assert quick["episodes"] == quick["validation_episodes"] == 4 and quick["learners"]["ppo"]["timesteps"] == 4096
    assert quick["learners"]["sac"]["tiers"] == ["nominal"] and quick["learners"]["sac"]["train_config"].endswith("training/sac.json")
    # residual learners: a recipe per tier (its env options kept), only in the full run
    res = [j for j in jobs if j.algo.startswith("residual_")]
    assert {(j.algo, j.tier) for j in res} == {(a, t) for a in ("residual_ppo", "residual_sac") for t in ("precision", "hard")}
    assert len(res) == 20 and all(j.train_config.endswith(f"{j.algo}_{j.tier}.json") for j in res)
    assert {j.timesteps for j in res if j.algo == "residual_ppo"} == {3_000_000}
    assert {j.timesteps for j in res if j.algo == "residual_sac"} == {500_000}
    assert set(quick["learners"]) == {"ppo", "sac"}
    # standalone students of the validation-chosen residual SAC run, on the tiers that have it
    students = [j for j in jobs if j.algo == "dagger_residual_sac"]
    assert {(j.tier, j.teacher_from) for j in students} == {(t, "residual_sac") for t in ("precision", "hard")}
    assert len(students) == 10 and all(j.teacher is None for j in students)


@pytest.mark.timeout(1800)  # trains every tier with PPO and SAC
def test_quick_benchmark_runs_the_whole_pipeline(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3")
    from accd_gym.cli import main

    out, docs = tmp_path / "bench", tmp_path / "docs"
    assert main(["benchmark", "--quick", "--out", str(out), "--docs", str(docs), "--quiet"]) == 0
    doc = json.loads((out / "benchmark.json").read_text())
    cfg = doc["config"]
    report = (docs / "benchmark.md").read_text()
    assert (docs / "figures" / "benchmark_profile.png").stat().st_size > 1000
    for tier in cfg["tiers"]:
        rows = doc["tiers"][tier]["policies"]
        assert "ppo" in rows and len(rows["ppo"]["rates"]) == 2
        assert {"zero", "random", "guidance", "lqr", "mpc"} <= set(rows)
        best = doc["tiers"][tier]["best"]
        assert best["classical"] in ("guidance", "lqr", "mpc") and best["standalone"] in ("ppo", "sac")
        assert best["hybrid"] is None  # the quick run has no residual learner
        lo, hi = rows["ppo"]["ci95"]
        assert 0.0 <= lo <= hi <= 1.0
        assert f"## {tier} " in report
        assert rows["ppo"]["failures"]["episodes"] == 2 * cfg["episodes"]
        m = doc["tiers"][tier]["mcnemar"]
        assert m["both"] + m["only_learned"] + m["only_classical"] + m["neither"] == cfg["episodes"]
    assert "sac" in doc["tiers"]["nominal"]["policies"]
    # The report's numbers are the episodes' own: recompute one rate from the per-episode record.
    eps = json.loads((out / "episodes.json").read_text())
    zero = eps["baselines"]["nominal"]["zero"]["captured"]
    assert doc["tiers"]["nominal"]["policies"]["zero"]["rate"] == sum(zero) / len(zero)
    # Every policy of a tier met the same episodes: the baselines' outcomes per episode are those
    # a fresh evaluation gives.
    from accd_gym.control.baselines import ZeroPolicy

    again = benchmark.evaluate_policy(ZeroPolicy(), "nominal", cfg["episodes"], cfg["num_envs"])
    assert again["captured"] == zero
    assert "wall time" in report and doc["wall_time_s"] > 0
    assert "closing speed at capture" in report and "Relative to the best classical controller" in report
    assert "## Summary" in report and "| best classical | best hybrid (IQM) | best standalone (IQM) |" in report
    assert not any(r["reused"] for r in doc["runs"])

    # Resumable: a rerun into the same folder reuses every finished job (training is not called)
    # and reports the same episodes; a job whose key differs (other episodes) is run afresh.
    from accd_gym.learning import training

    def no_training(*_a, **_k):
        raise AssertionError("a finished job was trained again")

    monkeypatch.setattr(training, "train", no_training)
    said: list[str] = []
    again_doc = benchmark.run(cfg, out, progress=said.append)
    assert not any(m.startswith("baseline") for m in said)  # stored once in OUT/baselines, reused
    assert all(r["reused"] for r in again_doc["runs"])
    assert json.loads((out / "episodes.json").read_text())["runs"] == eps["runs"]
    assert "reused" in benchmark.report_markdown(again_doc)
    # A stale evaluation (other episodes, other code: another key) is evaluated again, not retrained.
    job = benchmark.jobs(cfg)[0]
    fresh = benchmark.run_job(job, str(out), cfg["episodes"] + 1, cfg["num_envs"])
    assert not fresh["reused"] and len(fresh["episodes"]["captured"]) == cfg["episodes"] + 1
    # ... and reports the run's own training time with the run trained by an earlier invocation.
    meta = json.loads((out / "runs" / job.name / "run.json").read_text())
    assert not fresh["trained_now"] and fresh["train_wall_s"] == meta["wall_time_s"] > 0
    assert all(r["trained_now"] for r in doc["runs"])
    n = len(again_doc["runs"])
    evaluated_now = {**again_doc, "runs": [{**r, "reused": False, "trained_now": False} for r in again_doc["runs"]]}
    assert f"{n} of {n} runs were trained by an earlier invocation" in benchmark.report_markdown(evaluated_now)
    assert "trained by an earlier invocation" not in benchmark.report_markdown(doc)

    # Filters: an unknown value is one error line naming it and the allowed ones (exit 2); a run of
    # some jobs reports every finished one and lists the others as missing.
    assert main(["benchmark", "--quick", "--out", str(out), "--seeds", "7", "--quiet"]) == 2
    assert main(["benchmark", "--quick", "--out", str(out), "--algos", "dqn", "--quiet"]) == 2
    import shutil

    gone = benchmark.jobs(cfg)[-1]
    shutil.rmtree(out / "runs" / gone.name)
    part = benchmark.run(cfg, out, progress=lambda _m: None, chosen=benchmark.selection(cfg, seeds=[0], algos=["ppo"]))
    assert [m["name"] for m in part["missing"]] == [gone.name]
    assert len(part["runs"]) == len(benchmark.jobs(cfg)) - 1
    assert "## Missing / unfinished runs" in benchmark.report_markdown(part) and gone.name in benchmark.report_markdown(part)


def test_an_interrupted_job_continues_from_its_checkpoint(tmp_path, monkeypatch):
    # No training runs here: training.train and training.resume are replaced by probes that
    # record which one run_job chose.
    from accd_gym.learning import training

    class Chosen(Exception):
        pass

    def probe(name):
        def f(*args, **_k):
            if name == "train":
                seen.append(args[0])
            raise Chosen(name)
        return f

    seen: list[dict] = []
    monkeypatch.setattr(training, "train", probe("train"))
    monkeypatch.setattr(training, "resume", probe("resume"))
    cfg = benchmark.load_config(ROOT / "training" / "benchmark.json", quick=True)
    job = benchmark.jobs(cfg)[0]
    with pytest.raises(Chosen):  # nothing there: a fresh start
        benchmark.run_job(job, str(tmp_path), cfg["episodes"], cfg["num_envs"])
    run = tmp_path / "runs" / job.name
    for status, config, expected in (("interrupted", seen[0], "resume"), ("training", seen[0], "resume"),
                                     ("done", seen[0], "train"), ("interrupted", {**seen[0], "seed": 99}, "train"),
                                     # begun with another env thread count (a Ray task): continued
                                     ("interrupted", {**seen[0], "num_threads": 7}, "resume"),
                                     ("interrupted", {**seen[0], "checkpoint_every": 12345}, "resume"),
                                     ("interrupted", {**seen[0], "torch_threads": 3}, "train")):
        (run / "checkpoints").mkdir(parents=True, exist_ok=True)
        (run / "checkpoints" / "model_2048_steps.zip").write_bytes(b"")
        (run / "run.json").write_text(json.dumps({"status": status, "config": config}))
        with pytest.raises(Chosen, match=expected):
            benchmark.run_job(job, str(tmp_path), cfg["episodes"], cfg["num_envs"])
        # A fresh start first moves the run it replaces to OUT/superseded, whole.
        assert run.exists() == (expected == "resume")
    # Without a checkpoint an interrupted run starts afresh.
    (run / "checkpoints").mkdir(parents=True)
    (run / "run.json").write_text(json.dumps({"status": "interrupted", "config": seen[0]}))
    with pytest.raises(Chosen, match="train"):
        benchmark.run_job(job, str(tmp_path), cfg["episodes"], cfg["num_envs"])
    shelved = sorted(p.name for p in (tmp_path / "superseded").iterdir())
    assert shelved == [f"{job.name}-{k}" for k in (1, 2, 3, 4)]
    assert json.loads((tmp_path / "superseded" / f"{job.name}-2" / "run.json").read_text())["config"]["seed"] == 99


def test_a_job_with_a_cpu_budget_keeps_its_gradient_updates_within_it(tmp_path, monkeypatch):
    """A recipe's ``update_threads`` (2 here) is capped at a Ray job's ``cpus_per_job``; without a
    budget (num_threads 0, one process on the machine) the recipe's value stands."""
    import dataclasses
    from accd_gym.learning import training

    class Chosen(Exception):
        pass

    seen: list[dict] = []

    def probe(cfg, *_a, **_k):
        seen.append(cfg)
        raise Chosen()

    monkeypatch.setattr(training, "train", probe)
    cfg = benchmark.load_config(ROOT / "training" / "benchmark.json", quick=True)
    job = [j for j in benchmark.jobs(cfg) if j.train_config][0]
    recipe = json.loads(Path(job.train_config).read_text()) | {"update_threads": 2}
    (tmp_path / "recipe.json").write_text(json.dumps(recipe))
    job = dataclasses.replace(job, train_config=str(tmp_path / "recipe.json"))
    for threads, expected in ((1, 1), (2, 2), (0, 2)):
        with pytest.raises(Chosen):
            benchmark.run_job(job, str(tmp_path / str(threads)), cfg["episodes"], cfg["num_envs"], threads)
        assert seen[-1]["update_threads"] == expected and seen[-1]["num_threads"] == threads
    # A value of the wrong type is refused by the config's validation, named, not converted.
    for bad in ("2", True, 2.0):
        (tmp_path / "bad.json").write_text(json.dumps(recipe | {"update_threads": bad}))
        with pytest.raises(ConfigError, match="update_threads"):
            benchmark.run_job(dataclasses.replace(job, train_config=str(tmp_path / "bad.json")), str(tmp_path / "bad"),
                              cfg["episodes"], cfg["num_envs"], 1)


def test_ctrl_c_stops_the_benchmark_and_reports_what_is_finished(tmp_path, monkeypatch):
    # The trainer answers Ctrl+C by writing its checkpoint and returning "interrupted" (probed
    # here): the benchmark stops there, writes its report from the finished runs (none) and lists
    # every job as missing.
    from accd_gym.learning import training

    calls = []

    def interrupted(cfg, run, **_k):
        calls.append(run)
        return {"status": "interrupted", "timesteps": 2048, "config": cfg}

    monkeypatch.setattr(training, "train", interrupted)
    raw = json.loads((ROOT / "training" / "benchmark.json").read_text())
    raw.update(tiers=["nominal"], baselines=["zero"], episodes=4, validation_episodes=4,
               learners={"ppo": {"train_config": "training/ppo.json", "seeds": [0, 1], "timesteps": 4096}})
    cfg = benchmark.validate_config(raw, root=ROOT)
    doc = benchmark.run(cfg, tmp_path, progress=lambda _m: None)
    assert len(calls) == 1 and "interrupted at 2048 steps" in doc["interrupted"]
    assert [m["name"] for m in doc["missing"]] == ["nominal_ppo_seed0", "nominal_ppo_seed1"]
    report = (tmp_path / "benchmark.md").read_text()
    assert "## Missing / unfinished runs" in report and "| `nominal_ppo_seed1` | not started |" in report
    assert "zero" in doc["tiers"]["nominal"]["policies"]
    # The folder belongs to its recipe: another config is refused with one line naming what differs.
    with pytest.raises(ConfigError, match=r"another benchmark config \(differs in \['episodes'\]\)"):
        benchmark.run({**cfg, "episodes": 5}, tmp_path, progress=lambda _m: None)


def test_an_unfinished_runs_status_names_its_latest_checkpoint(tmp_path):
    run = tmp_path / "run"
    assert benchmark._run_status(run) == "not started"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({"status": "training", "total_timesteps": 500000}))
    assert benchmark._run_status(run) == "training, no checkpoint yet of 500,000 steps"
    (run / "run.json").write_text(json.dumps({"status": "training", "total_timesteps": 500000, "checkpoint_steps": 200000}))
    assert benchmark._run_status(run) == "training, at 200,000 of 500,000 steps"
    (run / "run.json").write_text(json.dumps({"status": "interrupted", "total_timesteps": 4096, "timesteps": 2048,
                                              "checkpoint_steps": 2048}))
    assert benchmark._run_status(run) == "interrupted, at 2,048 of 4,096 steps"


def test_a_residual_job_keeps_its_recipes_env_options(tmp_path, monkeypatch):
    from accd_gym.learning import training

    seen = []

    def probe(cfg, *_a, **_k):
        seen.append(cfg)
        raise KeyError("probe")

    monkeypatch.setattr(training, "train", probe)
    cfg = benchmark.load_config(ROOT / "training" / "benchmark.json")
    job = [j for j in benchmark.jobs(cfg) if j.algo == "residual_ppo" and j.tier == "hard"][0]
    with pytest.raises(KeyError, match="probe"):
        benchmark.run_job(job, str(tmp_path), 4, 4)
    env = seen[0]["env"]
    assert env["tier"] == "hard" and env["residual"]["base"] == "lqr" and env["history"] == 4


def _interrupt_benchmark_at_a_checkpoint(cfg_path, out, newer_than=0):
    """Runs ``accd-gym benchmark`` in a child process and sends it SIGINT once its training run
    has a checkpoint of more than ``newer_than`` steps; returns (exit code, stderr)."""
    import signal
    import subprocess
    import sys
    import time

    from accd_gym.learning import training

    run = out / "runs" / "nominal_ppo_seed0"
    child = subprocess.Popen([sys.executable, "-m", "accd_gym", "benchmark", "--config", str(cfg_path), "--out", str(out)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        assert child.poll() is None, child.stderr.read()
        latest = training.latest_checkpoint(run) if run.is_dir() else None
        if latest is not None and latest["steps"] > newer_than:
            break
        time.sleep(0.1)
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=300)
    return child.returncode, err


def test_ctrl_c_on_the_command_exits_130_with_the_report_and_the_same_command_resumes(tmp_path):
    # The command itself, in a child process: Ctrl+C while training writes the checkpoint, the
    # report of what is finished, and exits 130; the same command again continues that run.
    train = tmp_path / "tiny_ppo.json"
    train.write_text(json.dumps({"algo": "ppo", "total_timesteps": 10**7, "num_envs": 4, "num_threads": 1,
                                 "env": {"capture_window": 5.0},
                                 "algo_kwargs": {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
                                 "policy_kwargs": {"net_arch": [16, 16]}, "checkpoint_every": 256}))
    cfg = tmp_path / "benchmark.json"
    cfg.write_text(json.dumps({"tiers": ["nominal"], "baselines": ["zero"], "episodes": 4, "validation_episodes": 4, "num_envs": 4,
                               "learners": {"ppo": {"train_config": str(train), "seeds": [0], "timesteps": 10**7}}}))
    out = tmp_path / "out"
    rc, err = _interrupt_benchmark_at_a_checkpoint(cfg, out)
    assert rc == 130, err
    assert "benchmark interrupted" in err and "run the same command again to resume" in err and "Traceback" not in err
    report = (out / "benchmark.md").read_text()
    assert "## Missing / unfinished runs" in report and "nominal_ppo_seed0" in report
    run = out / "runs" / "nominal_ppo_seed0"
    first = json.loads((run / "run.json").read_text())
    assert first["status"] == "interrupted" and first["timesteps"] > 0
    rc, err = _interrupt_benchmark_at_a_checkpoint(cfg, out, newer_than=first["timesteps"])
    assert rc == 130, err
    second = json.loads((run / "run.json").read_text())
    assert second["resumed"][0]["from_steps"] == first["timesteps"] and second["timesteps"] > first["timesteps"]


def test_a_result_is_keyed_by_the_whole_package_and_the_recipes_bytes_not_their_paths(tmp_path):
    import dataclasses
    import shutil

    import accd_gym

    package = Path(accd_gym.__file__).parent
    sources = {p.relative_to(package).as_posix() for p in benchmark.digest_sources()}
    # The env wrappers and controllers a learned policy runs with count, not only the benchmark's own code.
    assert {"envs/residual.py", "control/lqr.py", "evals/benchmark.py", "learning/training.py"} <= sources
    assert any(s.startswith("_core") for s in sources)
    # The same recipe elsewhere (a moved or fresh checkout) gives the same key and the same claim.
    cfg = benchmark.load_config(ROOT / "training" / "benchmark.json", quick=True)
    job = benchmark.jobs(cfg)[0]
    moved = tmp_path / "elsewhere" / Path(job.train_config).name
    moved.parent.mkdir()
    shutil.copy(job.train_config, moved)
    assert benchmark.job_key(job, 4, 4) == benchmark.job_key(dataclasses.replace(job, train_config=str(moved)), 4, 4)
    out = tmp_path / "out"
    out.mkdir()
    benchmark._claim(out, cfg)
    spec = dict(cfg["learners"]["ppo"], train_config=str(moved))
    benchmark._claim(out, {**cfg, "learners": {**cfg["learners"], "ppo": spec}})  # accepted
    # the config file itself read from another checkout: accepted
    benchmark._claim(out, {**cfg, "source": str(tmp_path / "clone" / "training" / "benchmark.json")})
    moved.write_text(moved.read_text() + "\n")  # an edited recipe is another config
    with pytest.raises(ConfigError, match=r"differs in \['learners'\]"):
        benchmark._claim(out, {**cfg, "learners": {**cfg["learners"], "ppo": spec}})
    # A learner added (the others unchanged) extends the folder: recorded, and then required.
    extra = {**cfg["learners"], "ppo2": dict(cfg["learners"]["ppo"])}
    benchmark._claim(out, {**cfg, "learners": extra})
    assert set(json.loads((out / benchmark.CONFIG_FILE).read_text())["learners"]) == set(extra)
    benchmark._claim(out, {**cfg, "learners": extra})
    with pytest.raises(ConfigError, match=r"differs in \['learners'\]"):  # one dropped: another config
        benchmark._claim(out, cfg)
    with pytest.raises(ConfigError, match=r"differs in \['episodes', 'learners'\]"):  # added, and more changed
        benchmark._claim(out, {**cfg, "episodes": 7, "learners": {**extra, "ppo3": dict(cfg["learners"]["ppo"])}})


def test_the_report_names_the_cpu_and_the_blas_kernels_it_ran_on():
    """The LQR's last bits follow the BLAS kernels chosen for the CPU, so the report says which."""
    import platform

    from threadpoolctl import threadpool_info

    machine = benchmark._machine()
    assert machine.startswith(platform.machine()) and f"Python {platform.python_version()}" in machine
    blas = [i for i in threadpool_info() if i.get("user_api") == "blas"]
    assert blas, "numpy/SciPy load a BLAS"
    assert f"BLAS kernels {blas[0]['internal_api']}" in machine
    assert all(i.get("architecture", "") in machine for i in blas)
