"""What the package assumes of Windows and macOS, tested here on Linux by simulating their
behaviour: atomic writes flush through a descriptor open for writing (Windows' ``fsync`` needs
one) and retry a rename over a file that another process holds open (Windows refuses it for a
moment); the signal handling of a sweep does without SIGUSR1 (Windows has none); the core install
pulls no PyTorch (the extras do)."""

from __future__ import annotations

import importlib.metadata
import os
import re
import signal
import stat
import tomllib
from pathlib import Path

import pytest

from accd_gym import OutputError, files

ROOT = Path(__file__).resolve().parents[1]


def test_an_atomic_write_flushes_the_file_through_a_descriptor_open_for_writing(tmp_path, monkeypatch):
    fcntl = pytest.importorskip("fcntl")  # reads the descriptor's mode (POSIX)
    real_fsync = os.fsync
    modes = []

    def fsync(fd):
        if stat.S_ISREG(os.fstat(fd).st_mode):  # the folder's flush (POSIX only) opens it read-only
            modes.append(fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE)
        real_fsync(fd)

    monkeypatch.setattr(files.os, "fsync", fsync)
    files.write_text(tmp_path / "a.json", "{}")
    assert modes and os.O_RDONLY not in modes, "Windows' fsync (FlushFileBuffers) fails on a read-only descriptor"
    assert (tmp_path / "a.json").read_text() == "{}"


def _held_for(attempts: int, monkeypatch) -> list[int]:
    """``os.replace`` in accd_gym.files failing with PermissionError (as Windows does while another
    process holds the target open) ``attempts`` times, then renaming; returns the call count."""
    real_replace = os.replace
    calls = [0]

    def replace(src, dst):
        calls[0] += 1
        if calls[0] <= attempts:
            raise PermissionError(13, "The process cannot access the file because it is being used by another process")
        real_replace(src, dst)

    monkeypatch.setattr(files.os, "replace", replace)
    return calls


def test_a_rename_over_a_file_held_open_is_retried_and_replaces_it(tmp_path, monkeypatch):
    target = tmp_path / "results.json"
    target.write_text("old")
    monkeypatch.setattr(files, "REPLACE_RETRY_SECONDS", 1.0)
    calls = _held_for(3, monkeypatch)
    files.write_text(target, "new")
    assert calls[0] == 4
    assert target.read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["results.json"], "a temporary file was left behind"


def test_a_file_held_past_the_retry_bound_fails_naming_it_and_keeps_the_previous_file(tmp_path, monkeypatch):
    target = tmp_path / "results.json"
    target.write_text("old")
    monkeypatch.setattr(files, "REPLACE_RETRY_SECONDS", 0.05)
    calls = _held_for(10**6, monkeypatch)
    with pytest.raises(OutputError, match="results.json"):
        files.write_text(target, "new")
    assert 2 <= calls[0] < 20
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["results.json"], "a temporary file was left behind"


def test_off_windows_a_failed_rename_fails_at_once():
    if os.name == "nt":
        pytest.skip("Windows retries")
    assert files.REPLACE_RETRY_SECONDS == 0.0


def test_a_sweep_keeps_its_signal_handlers_on_a_platform_without_sigusr1(monkeypatch):
    from accd_gym.evals import sweep

    monkeypatch.delattr(signal, "SIGUSR1")
    kept = sweep._signal_handlers()
    assert set(kept) == {signal.SIGINT, signal.SIGTERM}
    sweep._restore_signal_handlers(kept)


def _name(requirement: str) -> str:
    """The normalised distribution name of a requirement string."""
    return re.split(r"[\s;\[<>=!~(]", requirement.strip(), maxsplit=1)[0].lower().replace("_", "-")


def test_the_core_install_pulls_no_pytorch():
    """The core dependencies and everything they require in turn (on any platform: a requirement
    for another platform is named, though not installed here to follow) hold no torch: only the
    extras bring it."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    todo = [_name(r) for r in project["dependencies"]]
    seen: set[str] = set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        try:
            requires = importlib.metadata.requires(name) or []
        except importlib.metadata.PackageNotFoundError:  # e.g. tqdm's colorama, Windows only
            continue
        for req in requires:
            if "extra ==" not in req.replace('"', "").replace("'", ""):
                todo.append(_name(req))
    assert "numpy" in seen and "gymnasium" in seen
    assert not seen & {"torch", "stable-baselines3", "ray"}, sorted(seen)
    extras = project["optional-dependencies"]
    assert any(_name(r) == "stable-baselines3" for r in extras["sb3"])
