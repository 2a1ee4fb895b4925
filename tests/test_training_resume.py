"""Training survives interruption. SIGINT or SIGTERM during ``accd-gym train``
writes a checkpoint with the normalization statistics and the envs' state and marks the run
interrupted; ``--resume`` continues to the same total; evaluating the unfinished run uses the
latest checkpoint and says so; a model without its statistics is refused unless asked for."""

import json
import shutil
import signal
import subprocess
import sys
import time

import pytest

import accd_gym
from accd_gym.learning import training
from accd_gym.cli import main
from accd_gym.evals.evaluation import SB3Policy

SHORT = {"capture_window": 5.0}
TOTAL = 1024


def _config(tmp_path, total):
    cfg = {"algo": "ppo", "total_timesteps": total, "num_envs": 4, "num_threads": 1, "seed": 1, "env": SHORT,
           "algo_kwargs": {"n_steps": 32, "batch_size": 64, "n_epochs": 2},
           "policy_kwargs": {"net_arch": [16, 16]}, "checkpoint_every": 128}
    path = tmp_path / "cfg.json"
    path.write_text(json.dumps(cfg))
    return path


def _train_until_first_checkpoint_then(sig, tmp_path):
    """Runs ``accd-gym train`` in a child process, sends ``sig`` once a checkpoint exists;
    returns (exit code, stderr, run folder)."""
    run = tmp_path / "run"
    cfg = _config(tmp_path, 10**7)
    child = subprocess.Popen([sys.executable, "-m", "accd_gym", "train", "--config", str(cfg), "--out", str(run),
                              "--quiet"], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not list((run / "checkpoints").glob("*.zip")) and time.monotonic() < deadline:
        assert child.poll() is None, child.stderr.read()
        time.sleep(0.1)
    child.send_signal(sig)
    _, err = child.communicate(timeout=120)
    return child.returncode, err, run


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupted_training_checkpoints_and_resumes_to_the_same_total(sig, tmp_path, capsys):
    rc, err, run = _train_until_first_checkpoint_then(sig, tmp_path)
    assert rc == 130, err
    assert "interrupted" in err and "--resume" in err and "Traceback" not in err
    meta = json.loads((run / "run.json").read_text())
    assert meta["status"] == "interrupted" and meta["timesteps"] > 0
    ckpt = training.latest_checkpoint(run)
    assert ckpt["steps"] == meta["timesteps"] and ckpt["vecnormalize"] is not None and ckpt["env_state"] is not None
    assert not (run / "final_model.zip").exists()

    # evaluating the unfinished run uses its latest checkpoint and says so
    with pytest.warns(UserWarning, match="latest checkpoint"):
        policy = SB3Policy(run)
    assert "latest checkpoint" in policy.note and policy.normalizer is not None

    # resume to a total just above the interruption (the test's budget), with the same config
    meta["config"]["total_timesteps"] = meta["timesteps"] + 256
    (run / "run.json").write_text(json.dumps(meta))
    assert main(["train", "--resume", str(run), "--quiet"]) == 0
    done = json.loads((run / "run.json").read_text())
    assert done["status"] == "done" and done["timesteps"] >= meta["timesteps"] + 256
    assert done["resumed"][0]["from_steps"] == meta["timesteps"]
    assert (run / "final_model.zip").is_file() and (run / "vecnormalize.pkl").is_file()
    assert main(["train", "--resume", str(run), "--quiet"]) == 2  # a finished run has nothing to resume
    assert "complete" in capsys.readouterr().err


def test_evaluate_of_an_interrupted_run_says_so_in_the_report(tmp_path, capsys):
    rc, err, run = _train_until_first_checkpoint_then(signal.SIGINT, tmp_path)
    assert rc == 130, err
    out = tmp_path / "eval"
    with pytest.warns(UserWarning):
        assert main(["evaluate", "--policy", str(run), "--episodes", "2", "--num-envs", "2", "--num-threads", "1",
                     "--env", json.dumps(SHORT), "--out", str(out), "--quiet"]) == 0
    assert "latest checkpoint" in capsys.readouterr().err
    assert "latest checkpoint" in (out / "summary.md").read_text()
    assert "latest checkpoint" in json.loads((out / "results.json").read_text())["policies"][str(run)]["note"]


def test_a_model_without_its_statistics_is_refused_unless_asked_for(tmp_path):
    cfg = training.load_config(str(_config(tmp_path, 256)))
    run = tmp_path / "ppo"
    training.train(cfg, run, progress=False)
    lone = tmp_path / "lone"
    lone.mkdir()
    shutil.copy(run / "final_model.zip", lone / "final_model.zip")
    shutil.copy(run / "run.json", lone / "run.json")
    with pytest.raises(accd_gym.ConfigError, match="VecNormalize statistics"):
        SB3Policy(lone)
    assert main(["rollout", "--policy", str(lone), "--episodes", "1", "--num-envs", "1", "--quiet"]) == 2
    with pytest.warns(UserWarning, match="unnormalised"):
        policy = SB3Policy(lone, allow_unnormalized=True)
    assert policy.normalizer is None
    assert SB3Policy(run).normalizer is not None


def test_the_first_signal_stops_at_the_next_env_step_and_a_second_one_at_once():
    # Regression: a SIGTERM raised inside Adam's first step left its state half initialised, and
    # the checkpoint written then could not be resumed (KeyError 'exp_avg' in a fresh-clone run).
    stop = training._StopRequest()
    callback = stop.callback()
    assert callback._on_step() is True
    stop.handler(signal.SIGTERM, None)
    assert stop.signal_name == "signal SIGTERM" and callback._on_step() is False
    with pytest.raises(KeyboardInterrupt):
        stop.handler(signal.SIGINT, None)


def test_a_sweep_trial_rerun_reuses_its_training_and_continues_a_stopped_one(tmp_path):
    from accd_gym.evals import sweep

    cfg = training.validate_config(json.loads(_config(tmp_path, 256).read_text()))
    run = tmp_path / "trials" / "trial"  # as a sweep lays out its trials: OUT/trials/<name>
    meta, seconds = sweep.train_trial(cfg, run)
    assert meta["status"] == "done" and meta["timesteps"] == 256 and seconds == meta["wall_time_s"]
    model = run / "final_model.zip"
    stamp = model.stat().st_mtime_ns
    # The sweep rerun: nothing is trained again; the trial keeps its own training time.
    again, seconds_again = sweep.train_trial(cfg, run)
    assert model.stat().st_mtime_ns == stamp and again == meta and seconds_again == seconds
    # A trial stopped after its last checkpoint (the machine went down before the final save)
    # continues from that checkpoint instead of starting over.
    stopped = json.loads((run / "run.json").read_text())
    (run / "run.json").write_text(json.dumps({**stopped, "status": "interrupted"}))
    model.unlink()
    resumed, _ = sweep.train_trial(cfg, run)
    assert resumed["status"] == "done" and resumed["timesteps"] == 256 and model.is_file()
    # Another config in the folder is not this trial's training: it trains afresh, the earlier
    # run kept whole beside the trials.
    other = dict(cfg, seed=2)
    fresh, _ = sweep.train_trial(other, run)
    assert fresh["status"] == "done" and json.loads((run / "run.json").read_text())["config"]["seed"] == 2
    kept = tmp_path / "superseded" / "trial-1"
    assert json.loads((kept / "run.json").read_text())["config"]["seed"] == 1 and (kept / "final_model.zip").is_file()


def test_training_into_a_folder_that_holds_a_run_is_refused(tmp_path, capsys):
    cfg = _config(tmp_path, 128)
    run = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--out", str(run), "--quiet"]) == 0
    model = (run / "final_model.zip").read_bytes()
    capsys.readouterr()
    assert main(["train", "--config", str(cfg), "--out", str(run), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "already holds a training run" in err and "--resume" in err, err
    assert (run / "final_model.zip").read_bytes() == model
    (run / "final_model.zip").unlink()
    (run / "run.json").unlink()
    (run / "vecnormalize.pkl").unlink()
    with pytest.raises(accd_gym.ConfigError, match="checkpoints"):  # its checkpoints alone count too
        training.train(json.loads(cfg.read_text()), run, progress=False)
