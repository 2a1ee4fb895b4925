"""Ray: distributed evaluation, RLlib training, Tune sweeps, a two-node cluster on this machine.

One local Ray instance (2 CPUs, bound to 127.0.0.1) is shared by the tests of this module; the
two-node test starts its own head and worker nodes with ``ray start`` in a temporary folder of
its own and stops them (and anything else left running from that folder) at the end. Skipped
without the ``ray`` extra.
"""

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

ray = pytest.importorskip("ray")
pytest.importorskip("ray.rllib")

import accd_gym  # noqa: E402
from accd_gym.evals import distributed, sweep  # noqa: E402
from accd_gym.learning import rllib  # noqa: E402
from accd_gym.control.baselines import GuidancePolicy, RandomPolicy  # noqa: E402
from accd_gym.evals.evaluation import evaluate, load_policy, run_episodes  # noqa: E402

# Longer than the suite's default time limit (pyproject.toml): Ray clusters start per module (per xdist worker), and RLlib and Tune train.
pytestmark = pytest.mark.timeout(1800)

SHORT = {"capture_window": 6.0}
WAKE = list(accd_gym.HELD_OUT_WAKE_SEEDS[:40])
ROOT = Path(__file__).resolve().parents[1]


def _processes_under(folder: str) -> list[int]:
    """PIDs of this machine's processes whose command line names ``folder`` (ours by construction),
    and their descendants (Ray's workers and agents retitle themselves ``ray::...``)."""
    named, parent = set(), {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        parent[int(entry)] = int(stat.rsplit(")", 1)[1].split()[1])
        if folder in cmd:
            named.add(int(entry))
    found = set(named)
    grew = True
    while grew:
        grew = False
        for pid, ppid in parent.items():
            if ppid in found and pid not in found:
                found.add(pid)
                grew = True
    return sorted(found)


def _kill(pids: list[int]) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


@pytest.fixture(scope="module")
def cluster():
    """The module's local Ray instance (2 CPUs); shut down, and its processes checked gone, after."""
    temp = tempfile.mkdtemp(prefix="accdray_", dir="/tmp")
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}  # ray.init sets SIGTERM's
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, _node_ip_address="127.0.0.1", _temp_dir=temp)
    yield ray
    ray.shutdown()
    for sig, handler in handlers.items():  # later tests rely on Python's own handlers
        signal.signal(sig, handler)
    deadline = time.monotonic() + 20
    while _processes_under(temp) and time.monotonic() < deadline:
        time.sleep(0.5)
    left = _processes_under(temp)
    _kill(left)
    shutil.rmtree(temp, ignore_errors=True)
    assert not left, f"Ray processes left running after shutdown: {left}"


def _same(a, b):
    assert [e.index for e in a] == [e.index for e in b]
    for e, f in zip(a, b):
        assert e.metrics() == f.metrics()
        assert np.array_equal(e.trajectory, f.trajectory)


def _tiny_sb3_run(tmp_path):
    """A PPO run folder trained for 64 steps (for evaluation through Ray)."""
    from accd_gym.learning import training

    cfg = training.validate_config({"algo": "ppo", "total_timesteps": 64, "num_envs": 4, "num_threads": 1, "seed": 1,
                                    "env": SHORT, "algo_kwargs": {"n_steps": 16, "batch_size": 32, "n_epochs": 1},
                                    "policy_kwargs": {"net_arch": [16, 16]}, "checkpoint_every": 10_000})
    run = tmp_path / "ppo"
    training.train(cfg, run, progress=False)
    return run


def test_distributed_evaluation_equals_local_whatever_the_tasks(cluster, tmp_path):
    policies = {"guidance": GuidancePolicy(), "random": RandomPolicy(0), "ppo": load_policy(str(_tiny_sb3_run(tmp_path)))}
    local = {k: run_episodes(p, 10, wake_seeds=WAKE, num_envs=4, num_threads=1, config=SHORT) for k, p in policies.items()}
    for chunk in (4, 10, 7):
        runs, info = distributed.run_policies(policies, 10, seed=accd_gym.evals.episodes.EVAL_BASE_SEED, wake_seeds=WAKE,
                                              num_envs=4, config=SHORT, chunk=chunk)
        for k in policies:
            _same(local[k], runs[k])
        assert len(info["tasks"]) == 3 * -(-10 // chunk)


def test_a_lost_worker_is_retried_and_counted_once(cluster, tmp_path):
    marker = tmp_path / "crashed"
    local = run_episodes(GuidancePolicy(), 8, wake_seeds=WAKE, num_envs=4, num_threads=1, config=SHORT)
    runs, info = distributed.run_policies({"g": GuidancePolicy()}, 8, seed=accd_gym.evals.episodes.EVAL_BASE_SEED,
                                          wake_seeds=WAKE, num_envs=4, config=SHORT, chunk=4, crash_marker=str(marker))
    assert marker.is_file()  # one task's worker process died after running its episodes
    _same(local, runs["g"])
    assert sorted((t["start"], t["stop"]) for t in info["tasks"]) == [(0, 4), (4, 8)]


def test_evaluate_with_ray_writes_the_same_report(cluster, tmp_path):
    kw = dict(num_envs=4, num_threads=1, config=SHORT, progress=False)
    evaluate(["guidance", "zero"], 6, tmp_path / "local", **kw)
    evaluate(["guidance", "zero"], 6, tmp_path / "ray", ray_address="local", ray_chunk=2, **kw)
    for name in ("results.json", "summary.md"):
        assert (tmp_path / "local" / name).read_bytes() == (tmp_path / "ray" / name).read_bytes()
    tasks = json.loads((tmp_path / "ray" / "ray_tasks.json").read_text())
    assert len(tasks["tasks"]) == 6 and tasks["episodes_per_task"] == 2


def _tiny_rllib_cfg(**extra):
    cfg = rllib.load_config(ROOT / "training" / "rllib_ppo.json")
    cfg.update(num_envs_per_env_runner=4, rollout_fragment_length=32, env=SHORT, model={"fcnet_hiddens": [16, 16]},
               checkpoint_every=128, **extra)
    cfg["algo_kwargs"] = dict(cfg["algo_kwargs"], train_batch_size_per_learner=128, minibatch_size=64, num_epochs=1)
    return rllib.validate_config(cfg)


def test_runner_seeds_come_from_the_worker_index_and_never_overlap():
    from ray.rllib.env.env_context import EnvContext

    envs = []
    for w in (1, 2, 3):
        ctx = EnvContext({"env": SHORT, "num_threads": 1, "seed": 10}, worker_index=w, num_workers=3)
        env = rllib.make_runner_env(ctx | {"num_envs": 4})  # what RLlib's vector entry point passes
        rllib._on_environment_created(env=env, env_context=ctx)
        env.reset(seed=10 + w)  # RLlib's seed for runner w
        envs.append(env)
    seeds = [tuple(e.np_random_seed) for e in envs]
    assert seeds == [tuple(range(10 + 4 * k, 14 + 4 * k)) for k in range(3)]
    wakes = [w for e in envs for w in (e._core.episode_seeds(i)["wake"] for i in range(4))]
    assert len(set(wakes)) == 12 and max(wakes) < accd_gym.HELD_OUT_WAKE_SEEDS.start


def test_rllib_ppo_trains_two_iterations_then_evaluates_like_an_sb3_run(cluster, tmp_path, capsys):
    cfg = _tiny_rllib_cfg()
    meta = rllib.train(cfg, tmp_path / "rl", timesteps=256, progress=False)
    assert meta["status"] == "finished" and meta["timesteps"] == 256 and meta["iterations"] == 2
    assert meta["versions"]["ray"] == ray.__version__
    run = tmp_path / "rl"
    assert (run / "final_model" / "rllib_checkpoint.json").is_file()
    assert (run / "checkpoints" / "ckpt_128_steps" / "rllib_checkpoint.json").is_file()
    assert list((run / "tb").glob("events.out.tfevents.*"))
    policy = load_policy(str(run))
    assert isinstance(policy, rllib.RLlibPolicy)
    a = policy.predict(np.zeros((4, 25), np.float32))
    assert a.shape == (4, 4) and np.all(np.abs(a) <= 1)
    # Evaluated locally and through Ray: the same episodes.
    local = run_episodes(policy, 6, wake_seeds=WAKE, num_envs=4, num_threads=1, config=SHORT)
    runs, _ = distributed.run_policies({"rl": policy}, 6, seed=accd_gym.evals.episodes.EVAL_BASE_SEED, wake_seeds=WAKE,
                                       num_envs=4, config=SHORT, chunk=4)
    _same(local, runs["rl"])
    from accd_gym.cli import main

    assert main(["evaluate", "--policy", str(run), "--episodes", "4", "--num-envs", "4", "--num-threads", "1",
                 "--env", json.dumps(SHORT), "--out", str(tmp_path / "eval"), "--quiet"]) == 0
    assert "rl |" in capsys.readouterr().out


def test_rllib_train_from_the_command_line(cluster, tmp_path, capsys):
    from accd_gym.cli import main

    cfg = {k: v for k, v in _tiny_rllib_cfg().items()}
    path = tmp_path / "rl.json"
    path.write_text(json.dumps(cfg))
    assert main(["train", "--config", str(path), "--out", str(tmp_path / "run"), "--timesteps", "128", "--quiet"]) == 0
    assert "trained RLlib PPO for 128 steps" in capsys.readouterr().out
    assert json.loads((tmp_path / "run" / "run.json").read_text())["trainer"] == "rllib"
    assert main(["train", "--resume", str(tmp_path / "run")]) == 2
    bad = dict(cfg, num_env_runners=-1)
    path.write_text(json.dumps(bad))
    assert main(["train", "--config", str(path), "--out", str(tmp_path / "bad")]) == 2
    assert "`num_env_runners` = -1" in capsys.readouterr().err


def test_a_sweep_of_two_tiny_trials_writes_its_table(cluster, tmp_path):
    train = tmp_path / "ppo.json"
    train.write_text(json.dumps({"algo": "ppo", "total_timesteps": 64, "num_envs": 4, "env": SHORT,
                                 "algo_kwargs": {"n_steps": 16, "batch_size": 32, "n_epochs": 1},
                                 "policy_kwargs": {"net_arch": [16, 16]}, "checkpoint_every": 10_000}))
    cfg = sweep.validate_config({"train_config": str(train), "seeds": [0, 1], "episodes": 4, "num_envs": 4})
    sigint = signal.getsignal(signal.SIGINT)
    doc = sweep.run(cfg, tmp_path / "sweep", progress=False)
    # Regression: Tune leaves its own SIGINT handler behind (Ctrl+C then no longer raised
    # KeyboardInterrupt: the interrupt tests of test_reliability.py hung after this test).
    assert signal.getsignal(signal.SIGINT) is sigint
    assert not doc["failed"] and [t["seed"] for t in doc["trials"]] == [0, 1]
    rates = [t["capture_rate"] for t in doc["trials"]]
    (agg,) = doc["aggregates"]
    assert agg["iqm"] == pytest.approx(np.mean(rates)) and agg["seeds"] == [0, 1]
    assert agg["iqm_ci95_bootstrap"][0] <= agg["iqm"] <= agg["iqm_ci95_bootstrap"][1]
    table = (tmp_path / "sweep" / "summary.md").read_text()
    assert "| seed0 | 0 |" in table and "| seed1 | 1 |" in table and "IQM capture rate" in table
    # Each trial's evaluation is the local evaluation of its final model.
    run = tmp_path / "sweep" / "trials" / "seed1"
    eps = run_episodes(load_policy(str(run)), 4, wake_seeds=WAKE, num_envs=4, num_threads=1, config=SHORT)
    assert sum(e.captured for e in eps) == doc["trials"][1]["captures"]
    # Tuning evaluates on validation episodes (training wake seeds), never the held-out ones.
    val = sweep.validate_config({"train_config": str(train), "seeds": [1], "episodes": 4, "num_envs": 4,
                                 "eval_split": "validation", "baselines": ["zero"]})
    vdoc = sweep.run(val, tmp_path / "validation", progress=False)
    wake, base = sweep.eval_episodes("validation")
    eps = run_episodes(load_policy(str(tmp_path / "validation" / "trials" / "seed1")), 4, seed=base,
                       wake_seeds=list(wake[:4]), num_envs=4, num_threads=1, config=SHORT)
    assert sum(e.captured for e in eps) == vdoc["trials"][0]["captures"]
    assert all(e.wake_seed in accd_gym.TRAINING_WAKE_SEEDS for e in eps)
    vtable = (tmp_path / "validation" / "summary.md").read_text()
    assert "Validation: 4 episodes of training wake seeds" in vtable and "| baseline zero |" in vtable
    assert vdoc["baselines"]["zero"]["episodes"] == 4
    with pytest.raises(accd_gym.ConfigError, match="`seeds`"):
        sweep.validate_config({"train_config": str(train), "seeds": [1, 1]})
    with pytest.raises(accd_gym.ConfigError, match="learning_rat"):
        sweep.validate_config({"train_config": str(train), "grid": {"algo_kwargs.learning_rat": [1e-3]}})


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_nodes_on_one_machine_run_the_tasks_and_give_the_same_report(tmp_path):
    """``ray start --head --num-cpus 1`` plus a second node joining with ``--address``; a separate
    driver evaluates on that cluster. Everything started here is stopped here."""
    temp = tempfile.mkdtemp(prefix="accdray2_", dir="/tmp")
    ray_bin = str(Path(sys.executable).with_name("ray"))
    port = _free_port()
    address = f"127.0.0.1:{port}"
    common = ["--num-cpus", "1", "--node-ip-address", "127.0.0.1", "--temp-dir", temp, "--disable-usage-stats"]
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0")
    try:
        subprocess.run([ray_bin, "start", "--head", "--port", str(port), "--include-dashboard", "false", *common],
                       check=True, capture_output=True, env=env, timeout=120)
        subprocess.run([ray_bin, "start", "--address", address, *common], check=True, capture_output=True, env=env,
                       timeout=120)
        args = ["--policy", "guidance", "--policy", "random", "--episodes", "8", "--num-envs", "4",
                "--num-threads", "1", "--env", json.dumps(SHORT), "--quiet"]
        cmd = [sys.executable, "-m", "accd_gym", "evaluate", *args]
        subprocess.run([*cmd, "--out", str(tmp_path / "local")], check=True, capture_output=True, timeout=300)
        done = subprocess.run([*cmd, "--out", str(tmp_path / "ray"), "--ray", address, "--ray-chunk", "2"],
                              capture_output=True, text=True, env=env, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        for name in ("results.json", "summary.md"):
            assert (tmp_path / "local" / name).read_bytes() == (tmp_path / "ray" / name).read_bytes()
        tasks = json.loads((tmp_path / "ray" / "ray_tasks.json").read_text())
        assert tasks["cluster_cpus"] == 2 and len(tasks["nodes"]) == 2  # tasks ran on both nodes
    finally:
        _kill(_processes_under(temp))  # our nodes only: their command lines name our temp folder
        deadline = time.monotonic() + 10
        while _processes_under(temp) and time.monotonic() < deadline:
            time.sleep(0.2)
        left = _processes_under(temp)
        shutil.rmtree(temp, ignore_errors=True)
    assert not left, f"Ray processes left running: {left}"


def test_benchmark_training_jobs_as_ray_tasks_equal_the_local_run(cluster, tmp_path):
    """`accd-gym benchmark --ray`: the jobs run as Ray tasks (one CPU each) and give the local
    run's results episode for episode (training seeds, thread counts and placement change nothing)."""
    from accd_gym.evals import benchmark

    cfg = benchmark.validate_config(
        {"tiers": ["precision"], "learners": {"ppo": {"train_config": "training/ppo.json", "seeds": [0, 1], "timesteps": 512}},
         "baselines": ["zero"], "episodes": 4, "validation_episodes": 4, "num_envs": 4}, root=ROOT)
    quiet = lambda message: None  # noqa: E731
    local = benchmark.run(cfg, tmp_path / "local", progress=quiet)
    remote = benchmark.run(cfg, tmp_path / "ray", ray_address="local", progress=quiet)
    eps = {k: json.loads((tmp_path / k / "episodes.json").read_text()) for k in ("local", "ray")}
    assert eps["local"]["runs"] == eps["ray"]["runs"] and len(eps["local"]["runs"]) == 2
    timing = ("train_wall_s", "steps_per_s")
    rows = [{name: {k: v for k, v in row.items() if k not in timing} for name, row in doc["tiers"]["precision"]["policies"].items()}
            for doc in (local, remote)]
    assert rows[0] == rows[1] and set(rows[0]) == {"ppo", "zero"}
