"""Fault injection: nothing a user saved is lost and every bad input file gives a clean error.

Each case runs the command line as a user would and checks the exit code (2), the one-line
message naming the file and what is wrong, and that the files saved before are intact:

* damaged run files: truncated, empty or foreign checkpoints, statistics and run summaries
  given to ``train --resume`` (which takes the newest checkpoint that loads, saying which it
  skipped) and to ``evaluate``; a model of another environment;
* special files as tables and configs: ``/dev/zero``, ``/dev/urandom``, a FIFO (each in a child
  process with a time and memory limit, since the failure is a hang or a memory blow-up);
* a full disk (a small tmpfs filled up) during Ctrl+C of a training, during a training without
  one, and during an evaluation: a training loses at most one checkpoint interval, run.json says
  "interrupted" and names the last checkpoint written, and ``--resume`` continues from it;
* a read-only output folder (a read-only tmpfs as root, which ignores file permissions;
  ``chmod 0o500`` otherwise), refused before any episode runs.

The tmpfs cases need ``mount`` (root, as here and in CI); elsewhere they are skipped, saying so.
"""

import contextlib
import errno
import hashlib
import json
import os
import pickle
import resource
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from accd_gym import files
from accd_gym.learning import training
from accd_gym.cli import main

SHORT = {"capture_window": 5.0}
EVAL = ["--episodes", "1", "--num-envs", "1", "--num-threads", "1", "--env", json.dumps(SHORT), "--quiet"]


def _config(total: int) -> dict:
    return {"algo": "ppo", "total_timesteps": total, "num_envs": 4, "num_threads": 1, "seed": 1, "env": SHORT,
            "algo_kwargs": {"n_steps": 32, "batch_size": 64, "n_epochs": 2},
            "policy_kwargs": {"net_arch": [16, 16]}, "checkpoint_every": 128}


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished 512-step PPO run: final model, statistics, run.json, checkpoints at 128..512 steps."""
    run = tmp_path_factory.mktemp("fault") / "run"
    training.train(training.validate_config(_config(512)), run, progress=False)
    assert [c["steps"] for c in _checkpoints(run)] == [512, 384, 256, 128]
    return run


def _checkpoints(run: Path) -> list[dict]:
    """The checkpoints in a run folder, newest first: steps, model zip and statistics paths."""
    found = []
    for model in (run / "checkpoints").glob("ppo_accd_*_steps.zip"):
        steps = int(model.stem.split("_")[-2])
        found.append({"steps": steps, "model": model,
                      "vecnormalize": model.with_name(f"ppo_accd_vecnormalize_{steps}_steps.pkl")})
    return sorted(found, key=lambda c: c["steps"], reverse=True)


def _copy(run: Path, dest: Path) -> Path:
    shutil.copytree(run, dest)
    return dest


def _unfinished(run: Path, dest: Path) -> Path:
    """A copy of ``run`` as a run interrupted at 512 of 640 steps."""
    out = _copy(run, dest)
    (out / "final_model.zip").unlink()
    (out / "vecnormalize.pkl").unlink()
    meta = json.loads((out / "run.json").read_text())
    meta["status"] = "interrupted"
    meta["config"]["total_timesteps"] = 640
    (out / "run.json").write_text(json.dumps(meta))
    return out


def _digests(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (TensorBoard logs aside) -> its SHA-256."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and "tb" not in p.relative_to(folder).parts}


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _error_line(err: str) -> str:
    """The one error line of a failed command (asserting there is exactly one, and no traceback)."""
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith("accd-gym: error:")]
    assert len(lines) == 1, err
    return lines[0]


def _no_temp_files(folder: Path) -> None:
    left = [p for p in folder.rglob(f"{files.TEMP_PREFIX}*")]
    assert not left, left


# -- damaged run files given to train --resume ------------------------------------------------


def _damage_statistics(path: Path, how: str) -> None:
    if how == "truncated":
        _truncate(path)
    elif how == "empty":
        path.write_bytes(b"")
    else:  # a pickled dict, as a hand-made statistics file might be
        path.write_bytes(pickle.dumps({"obs_rms": [0.0] * 25}))


@pytest.mark.parametrize("damage", ["truncated zip", "truncated statistics", "empty statistics", "pickled dict statistics"])
def test_resume_skips_damaged_newest_checkpoints_and_says_so(finished_run, tmp_path, capsys, damage):
    run = _unfinished(finished_run, tmp_path / "run")
    newest, second = _checkpoints(run)[:2]
    if damage == "truncated zip":
        _truncate(newest["model"])
    else:
        _damage_statistics(newest["vecnormalize"], damage.split()[0])
    # (the resumed run writes its own checkpoint at 512 steps over the damaged one)
    kept = {k: v for k, v in _digests(run).items() if k.startswith("checkpoints/") and "_512_steps" not in k}
    assert main(["train", "--resume", str(run), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err
    skipped = [line for line in err.splitlines() if "skipped checkpoint" in line]
    assert len(skipped) == 1 and newest["model"].name in skipped[0], err
    assert ("truncated" in skipped[0] or "empty" in skipped[0] or "dict" in skipped[0]), skipped[0]
    meta = json.loads((run / "run.json").read_text())
    assert meta["status"] == "done" and meta["resumed"][-1]["from_steps"] == second["steps"] == 384
    assert newest["model"].name in meta["resumed"][-1]["skipped"][0]
    # the older checkpoints are untouched
    now = _digests(run)
    assert all(now[k] == v for k, v in kept.items())


def test_resume_with_no_loadable_checkpoint_fails_in_one_line(finished_run, tmp_path, capsys):
    run = _unfinished(finished_run, tmp_path / "run")
    for c in _checkpoints(run):
        _truncate(c["model"])
    before = _digests(run)
    assert main(["train", "--resume", str(run), "--quiet"]) == 2
    line = _error_line(capsys.readouterr().err)
    assert "none of its 4 checkpoints loads" in line and "ppo_accd_512_steps.zip" in line and "truncated" in line
    assert _digests(run) == before


@pytest.mark.parametrize("damage", ["not JSON", "a JSON list", "algo sac on a PPO model"])
def test_resume_with_a_damaged_run_json_fails_in_one_line(finished_run, tmp_path, capsys, damage):
    run = _unfinished(finished_run, tmp_path / "run")
    meta = json.loads((run / "run.json").read_text())
    if damage == "not JSON":
        (run / "run.json").write_text(json.dumps(meta)[:50])
    elif damage == "a JSON list":
        (run / "run.json").write_text("[1, 2]")
    else:
        meta["algo"] = meta["config"]["algo"] = "sac"
        meta["config"]["algo_kwargs"] = {"batch_size": 64}
        (run / "run.json").write_text(json.dumps(meta))
    before = _digests(run)
    assert main(["train", "--resume", str(run), "--quiet"]) == 2
    line = _error_line(capsys.readouterr().err)
    if damage == "algo sac on a PPO model":
        assert "holds a PPO model" in line and "run.json says" in line and "sac" in line
    else:
        assert str(run / "run.json") in line and ("JSON" in line or "run summary" in line)
    assert _digests(run) == before


# -- damaged or foreign files given to evaluate -----------------------------------------------


@pytest.mark.parametrize("damage", ["truncated model", "truncated statistics", "empty statistics",
                                    "pickled dict statistics", "statistics of another env", "run.json not JSON",
                                    "run.json algo sac"])
def test_evaluate_of_a_damaged_run_fails_in_one_line_naming_the_file(finished_run, tmp_path, capsys, damage):
    run = _copy(finished_run, tmp_path / "run")
    named = {"truncated model": "final_model.zip", "run.json not JSON": "run.json", "run.json algo sac": "final_model.zip"}
    if damage == "truncated model":
        _truncate(run / "final_model.zip")
    elif damage == "statistics of another env":
        import gymnasium as gym
        from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

        other = VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1")]))
        (run / "vecnormalize.pkl").write_bytes(pickle.dumps(other))
    elif damage.endswith("statistics"):
        _damage_statistics(run / "vecnormalize.pkl", damage.split()[0])
    elif damage == "run.json not JSON":
        (run / "run.json").write_text("{\"algo\": ")
    else:
        meta = json.loads((run / "run.json").read_text())
        meta["algo"] = "sac"
        (run / "run.json").write_text(json.dumps(meta))
    before = _digests(run)
    out = tmp_path / "eval"
    assert main(["evaluate", "--policy", str(run), "--out", str(out), *EVAL]) == 2
    line = _error_line(capsys.readouterr().err)
    assert named.get(damage, "vecnormalize.pkl") in line, line
    assert _digests(run) == before
    assert not (out / "results.json").exists()


def test_evaluate_of_a_model_of_another_env_fails_in_one_line(tmp_path, capsys):
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", "Pendulum-v1", n_steps=64, batch_size=64, policy_kwargs={"net_arch": [8]})
    path = tmp_path / "pendulum.zip"
    model.save(str(path))
    assert main(["evaluate", "--policy", str(path), "--allow-unnormalized", "--out", str(tmp_path / "eval"), *EVAL]) == 2
    line = _error_line(capsys.readouterr().err)
    assert "pendulum.zip" in line and "another environment" in line and "(25,)" in line


# -- special files as tables and configs --------------------------------------------------------


def _limited_cli(args: list[str], timeout: float = 120.0) -> subprocess.CompletedProcess:
    """``accd-gym ARGS`` in a child process with at most 4 GiB of address space
    (a table read without a bound fails instead of filling the machine's memory) and
    ``timeout`` seconds (a FIFO opened for reading blocks for ever)."""

    def limit() -> None:
        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        cap = 4 * 1024**3
        resource.setrlimit(resource.RLIMIT_AS, (cap if hard == resource.RLIM_INFINITY else min(cap, hard), hard))

    try:
        return subprocess.run([sys.executable, "-m", "accd_gym", *args], capture_output=True, text=True,
                              timeout=timeout, preexec_fn=limit)
    except subprocess.TimeoutExpired:
        pytest.fail(f"accd-gym {' '.join(args)} still ran after {timeout} s (a hang)")


@pytest.fixture
def fifo(tmp_path) -> Path:
    path = tmp_path / "table.json"
    os.mkfifo(path)
    return path


@pytest.mark.parametrize("special", ["/dev/zero", "/dev/urandom", "fifo"])
@pytest.mark.parametrize("field", ["wake.tables.low", "accd.aero_table"])
def test_a_table_path_that_is_not_a_regular_file_is_refused_at_once(special, field, tmp_path, request):
    path = str(request.getfixturevalue("fifo")) if special == "fifo" else special
    env = ({"wake": {"tables": {"low": path, "high": path}}} if field.startswith("wake")
           else {"accd": {"aero_table": path}})
    t0 = time.monotonic()
    done = _limited_cli(["rollout", "--policy", "zero", "--episodes", "1", "--num-envs", "1", "--quiet",
                         "--env", json.dumps({**SHORT, **env})])
    assert done.returncode == 2, done.stderr[-2000:]
    line = _error_line(done.stderr)
    assert field in line and path in line and "regular file" in line and "64 MiB" in line, line
    assert time.monotonic() - t0 < 60


@pytest.mark.parametrize("special", ["/dev/zero", "fifo"])
def test_a_config_file_that_is_not_a_regular_file_is_refused_at_once(special, tmp_path, request):
    path = str(request.getfixturevalue("fifo")) if special == "fifo" else special
    done = _limited_cli(["train", "--config", path, "--out", str(tmp_path / "run"), "--quiet"])
    assert done.returncode == 2, done.stderr[-2000:]
    line = _error_line(done.stderr)
    assert path in line and "regular file" in line, line


def test_a_failed_write_leaves_the_previous_file_and_no_temporary_file(tmp_path, monkeypatch):
    """The atomic write itself, without a mount: the flush to the disk fails as on a full disk."""
    target = tmp_path / "results.json"
    target.write_text("previous")

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(files.os, "fsync", full)
    with pytest.raises(OSError, match="cannot write .*results.json.*No space left on device"):
        files.write_text(target, "new" * 1000)
    assert target.read_text() == "previous"
    _no_temp_files(tmp_path)


# -- a full disk and a read-only folder (tmpfs mounts) ------------------------------------------


@contextlib.contextmanager
def _tmpfs(path: Path, size: str, read_only: bool = False):
    """A tmpfs of ``size`` mounted at ``path`` while active (skips the test where mounting is not
    permitted)."""
    path.mkdir(parents=True, exist_ok=True)
    options = f"size={size}" + (",ro" if read_only else "")
    try:
        subprocess.run(["mount", "-t", "tmpfs", "-o", options, f"accd-test-{uuid.uuid4().hex[:8]}", str(path)],
                       check=True, capture_output=True, text=True)
    except (OSError, subprocess.CalledProcessError) as e:
        pytest.skip(f"needs a tmpfs mount (root): {getattr(e, 'stderr', None) or e}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False, capture_output=True)


def _fill(disk: Path) -> Path:
    """Fills the file system of ``disk`` with a filler file; returns it."""
    filler = disk / "filler"
    chunk = b"\0" * (1 << 20)
    with open(filler, "wb") as f:
        try:
            while True:
                f.write(chunk)
                f.flush()
        except OSError as e:
            assert e.errno == errno.ENOSPC, e
    # the last partial chunk is left in the buffer: fill the remaining bytes one page at a time
    with open(filler, "ab", buffering=0) as f:
        with contextlib.suppress(OSError):
            while True:
                f.write(b"\0" * 4096)
    return filler


def test_ctrl_c_on_a_full_disk_keeps_the_checkpoints_and_resumes_after_space_is_freed(tmp_path, capsys):
    with _tmpfs(tmp_path / "disk", "64m") as disk:
        run = disk / "run"
        cfg = tmp_path / "cfg.json"
        cfg.write_text(json.dumps(_config(10**7)))
        child = subprocess.Popen([sys.executable, "-m", "accd_gym", "train", "--config", str(cfg), "--out", str(run),
                                  "--quiet"], stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 300
            while len(_checkpoints(run)) < 2 and time.monotonic() < deadline:
                assert child.poll() is None, child.stderr.read()
                time.sleep(0.1)
            child.send_signal(signal.SIGSTOP)  # hold it while the disk fills up
            # the files in place (a checkpoint being written when the child stopped is a temporary
            # file; the run folder's reserve is freed for run.json)
            saved = {k: v for k, v in _digests(run).items()
                     if not Path(k).name.startswith(files.TEMP_PREFIX) and k != files.RESERVE_NAME}
            filler = _fill(disk)
            child.send_signal(signal.SIGCONT)
            child.send_signal(signal.SIGINT)
            _, err = child.communicate(timeout=300)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait()
        assert child.returncode == 2, err
        line = _error_line(err)
        assert "No space left on device" in line and "keeps its checkpoint" in line and "--resume" in line, line
        now = _digests(run)
        assert all(now.get(k) == v for k, v in saved.items() if k != "run.json"), "a saved file changed"
        assert all((run / k).stat().st_size > 0 for k in now)
        _no_temp_files(run)
        # (the signal, or the write the stopped child was in the middle of, stops it first)
        _names_its_last_checkpoint(run, ("SIGINT", "a failed write"))
        _resumes_from_its_last_checkpoint(run, filler)


def _names_its_last_checkpoint(run: Path, interrupted_by: tuple[str, ...]) -> None:
    """run.json of a run stopped by a full disk: interrupted, naming its newest checkpoint (the
    one ``--resume`` takes), its reserve freed."""
    meta = json.loads((run / "run.json").read_text())  # whole JSON
    newest = training.latest_checkpoint(run)
    assert newest is not None
    assert meta["status"] == "interrupted" and any(w in meta["interrupted_by"] for w in interrupted_by), meta
    assert meta["checkpoint"] == str(newest["model"]) and meta["checkpoint_steps"] == newest["steps"]
    assert meta["timesteps"] == newest["steps"]
    assert not (run / files.RESERVE_NAME).exists()


def _resumes_from_its_last_checkpoint(run: Path, filler: Path) -> None:
    """Space freed: ``--resume`` continues from the checkpoint run.json names (the total cut to
    128 steps beyond it, to keep the test short)."""
    filler.unlink()
    meta = json.loads((run / "run.json").read_text())
    meta["config"]["total_timesteps"] = meta["checkpoint_steps"] + 128
    (run / "run.json").write_text(json.dumps(meta))
    assert main(["train", "--resume", str(run), "--quiet"]) == 0
    done = json.loads((run / "run.json").read_text())
    assert done["status"] == "done" and done["resumed"][-1]["from_steps"] == meta["checkpoint_steps"]
    assert done["resumed"][-1]["checkpoint"] == meta["checkpoint"]


def test_a_disk_that_fills_up_while_training_costs_at_most_one_checkpoint_interval(tmp_path, capsys):
    """The disk fills up between two periodic checkpoints, no signal: the next checkpoint fails,
    the training stops by itself, run.json names the last checkpoint written. (About 20 s, like
    the Ctrl+C case above: a training process has to start and write two checkpoints first.)"""
    with _tmpfs(tmp_path / "disk", "64m") as disk:
        run = disk / "run"
        cfg = tmp_path / "cfg.json"
        cfg.write_text(json.dumps(_config(10**7)))
        child = subprocess.Popen([sys.executable, "-m", "accd_gym", "train", "--config", str(cfg), "--out", str(run),
                                  "--quiet"], stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 300
            while len(_checkpoints(run)) < 2 and time.monotonic() < deadline:
                assert child.poll() is None, child.stderr.read()
                time.sleep(0.1)
            filler = _fill(disk)  # the next checkpoint cannot be written: the training stops by itself
            _, err = child.communicate(timeout=300)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait()
        assert child.returncode == 2, err
        line = _error_line(err)
        assert "No space left on device" in line and "keeps its checkpoint" in line and "--resume" in line, line
        _no_temp_files(run)
        _names_its_last_checkpoint(run, ("a failed write",))
        _resumes_from_its_last_checkpoint(run, filler)


def test_a_run_stopped_before_its_first_checkpoint_starts_over_on_resume(finished_run, tmp_path, capsys):
    run = _copy(finished_run, tmp_path / "run")
    shutil.rmtree(run / "checkpoints")
    for name in ("final_model.zip", "vecnormalize.pkl"):
        (run / name).unlink()
    meta = json.loads((run / "run.json").read_text())
    meta.update(status="interrupted", interrupted_by="a failed write", timesteps=0)
    for key in ("checkpoint", "vecnormalize", "checkpoint_steps"):
        meta.pop(key, None)
    meta["config"]["total_timesteps"] = 128
    (run / "run.json").write_text(json.dumps(meta))
    assert main(["train", "--resume", str(run), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "no checkpoint" in err and "starts over from step 0" in err, err
    done = json.loads((run / "run.json").read_text())
    assert done["status"] == "done" and done["timesteps"] == 128 and done["resumed"][-1]["from_steps"] == 0
    assert (run / "final_model.zip").is_file()


def test_run_json_names_each_checkpoint_as_it_is_written(tmp_path, monkeypatch):
    """A run killed at any moment (no handler runs) has a run.json naming its newest checkpoint:
    run.json is written after every periodic checkpoint."""
    written = []
    write = training._write_meta

    def spy(out, meta):
        write(out, meta)
        written.append((meta["status"], meta.get("checkpoint_steps"), (out / files.RESERVE_NAME).exists()))

    monkeypatch.setattr(training, "_write_meta", spy)
    run = tmp_path / "run"
    training.train(training.validate_config(_config(256)), run, progress=False)
    assert written == [("training", None, False), ("training", 128, True), ("training", 256, True), ("done", None, True)]
    meta = json.loads((run / "run.json").read_text())
    assert meta["status"] == "done" and "checkpoint" not in meta and not (run / files.RESERVE_NAME).exists()


def test_evaluate_on_a_full_disk_keeps_the_previous_results(tmp_path, capsys, monkeypatch):
    from accd_gym.evals import evaluation

    with _tmpfs(tmp_path / "disk", "8m") as disk:
        out = disk / "eval"
        assert main(["evaluate", "--policy", "zero", "--out", str(out), *EVAL]) == 0
        saved = _digests(out)
        capsys.readouterr()
        # a disk full before the start: refused before any episode
        filler = _fill(disk)
        assert main(["evaluate", "--policy", "guidance", "--out", str(out), *EVAL]) == 2
        line = _error_line(capsys.readouterr().err)
        assert "not a writable folder" in line and "No space left on device" in line, line
        filler.unlink()
        # a disk that fills up while the episodes run: the previous results stay whole
        run_episodes = evaluation.run_episodes

        def filling(*args, **kwargs):
            episodes = run_episodes(*args, **kwargs)
            _fill(disk)
            return episodes

        monkeypatch.setattr(evaluation, "run_episodes", filling)
        assert main(["evaluate", "--policy", "guidance", "--out", str(out), *EVAL]) == 2
        line = _error_line(capsys.readouterr().err)
        assert "No space left on device" in line and "unchanged" in line and "results.json" in line, line
        assert _digests(out) == saved
        _no_temp_files(out)


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder no file can be written in: a read-only tmpfs as root (root ignores permissions),
    else a folder with mode 0o500."""
    folder = tmp_path / "ro"
    if os.geteuid() == 0:
        with _tmpfs(folder, "1m", read_only=True):
            yield folder
    else:
        folder.mkdir()
        folder.chmod(0o500)
        yield folder
        folder.chmod(0o700)


@pytest.mark.parametrize("command", ["evaluate", "replay", "train"])
def test_a_read_only_output_folder_is_refused_before_any_episode(command, read_only_folder, tmp_path, capsys,
                                                                  monkeypatch):
    from accd_gym.evals import evaluation
    from accd_gym.replays import replay

    def ran(*args, **kwargs):
        raise AssertionError("episodes ran before the output folder was checked")

    monkeypatch.setattr(evaluation, "run_episodes", ran)
    monkeypatch.setattr(replay, "iter_recordings", ran)
    out = str(read_only_folder / "out")
    if command == "train":
        cfg = tmp_path / "cfg.json"
        cfg.write_text(json.dumps(_config(256)))
        args = ["train", "--config", str(cfg), "--out", out, "--quiet"]
    elif command == "evaluate":
        args = ["evaluate", "--policy", "zero", "--out", out, *EVAL]
    else:
        args = ["replay", "--policy", "zero", "--out", out, "--num-envs", "1", "--num-threads", "1",
                "--env", json.dumps(SHORT), "--quiet"]
    assert main(args) == 2
    line = _error_line(capsys.readouterr().err)
    assert "--out" in line and "not a writable folder" in line and out in line, line
