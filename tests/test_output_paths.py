"""Outputs that respect the path: nothing a user points us at is replaced.

Every file the package writes goes through one function, :func:`accd_gym.files.atomic_path`,
which replaces only a regular file or creates a new one: a symbolic link is followed and the
file it names is replaced in its own folder; a FIFO, a device, a socket or a folder where a file
is expected is refused before any work (one line, exit 2 from the command line), and so is an
empty path. The special files here are made in a temporary folder (``os.mkfifo``,
``os.mknod``, a bound Unix socket), never the system's; ``mknod`` needs root and is skipped
without it. A scan of the package's source finds no other rename or open-for-write.
"""

from __future__ import annotations

import ast
import json
import os
import socket
import stat
from pathlib import Path

import numpy as np
import pytest

import accd_gym
from accd_gym import files
from accd_gym.cli import main
from accd_gym.errors import ConfigError, OutputError

PACKAGE_DIR = Path(accd_gym.__file__).parent
KINDS = ["fifo", "device", "socket", "folder"]


def _make(path: Path, kind: str) -> Path:
    """A special file of ``kind`` at ``path`` (skips the test where it cannot be made)."""
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "device":
        try:  # a character device with /dev/null's numbers, in the temporary folder
            os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, 3))
        except PermissionError as e:
            pytest.skip(f"mknod needs root: {e}")
    elif kind == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(path))
        s.close()
    else:
        path.mkdir()
    return path


def _still(path: Path, kind: str) -> bool:
    """Whether ``path`` is still the special file ``_make`` made."""
    mode = os.lstat(path).st_mode
    return {"fifo": stat.S_ISFIFO, "device": stat.S_ISCHR, "socket": stat.S_ISSOCK, "folder": stat.S_ISDIR}[kind](mode)


def _error_line(err: str) -> str:
    """The one error line of a failed command (no traceback)."""
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith("accd-gym: error:")]
    assert len(lines) == 1, err
    return lines[0]


def _no_temp_files(*folders: Path) -> None:
    for folder in folders:
        left = [p for p in folder.iterdir() if p.name.startswith(files.TEMP_PREFIX)]
        assert not left, left


@pytest.mark.parametrize("kind", KINDS)
def test_export_aero_refuses_a_special_file_and_leaves_it_as_it_was(kind, tmp_path, capsys):
    target = _make(tmp_path / "tables.json", kind)
    assert main(["export-aero", "--out", str(target)]) == 2
    line = _error_line(capsys.readouterr().err)
    words = {"fifo": "a FIFO", "device": "a device", "socket": "a socket", "folder": "a folder"}[kind]
    assert "--out" in line and str(target) in line and words in line, line
    assert _still(target, kind)
    _no_temp_files(tmp_path)


@pytest.mark.parametrize("path", ["", "-", "a\0b"], ids=["empty", "dash", "nul"])
def test_export_aero_refuses_an_empty_dash_or_nul_path(path, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:  # the empty and NUL paths fail at parsing
        code = main(["export-aero", "--out", path])
        raise SystemExit(code)
    assert e.value.code == 2
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--out" in line and "Traceback" not in line, line
    assert list(tmp_path.iterdir()) == []


def test_export_aero_follows_a_symbolic_link_and_replaces_the_file_it_names(tmp_path, capsys):
    real_dir, link_dir = tmp_path / "real", tmp_path / "links"
    real_dir.mkdir(), link_dir.mkdir()
    real = real_dir / "tables.json"
    real.write_text("previous")
    link = link_dir / "tables.json"
    link.symlink_to(real)
    second = link_dir / "again.json"  # a link to the link
    second.symlink_to(link)
    assert main(["export-aero", "--out", str(second)]) == 0
    assert link.is_symlink() and second.is_symlink() and os.readlink(second) == str(link)
    assert json.loads(real.read_text()) == json.loads(accd_gym.default_aero_table_json())
    assert sorted(p.name for p in link_dir.iterdir()) == ["again.json", "tables.json"]
    assert sorted(p.name for p in real_dir.iterdir()) == ["tables.json"]
    _no_temp_files(real_dir, link_dir)
    # a dangling link: the file it names is created
    dangling = link_dir / "new.json"
    dangling.symlink_to(real_dir / "new.json")
    assert main(["export-aero", "--out", str(dangling)]) == 0
    assert dangling.is_symlink() and (real_dir / "new.json").is_file()


def test_a_link_to_a_special_file_is_refused(tmp_path, capsys):
    fifo = _make(tmp_path / "fifo", "fifo")
    link = tmp_path / "out.json"
    link.symlink_to(fifo)
    assert main(["export-aero", "--out", str(link)]) == 2
    assert "a FIFO" in _error_line(capsys.readouterr().err)
    assert link.is_symlink() and _still(fifo, "fifo")


WRITERS = {
    "write_text": lambda p: files.write_text(p, "x"),
    "write_bytes": lambda p: files.write_bytes(p, b"x"),
    "save_npz": lambda p: files.save_npz(p, a=np.zeros(2)),
    "atomic_open": lambda p: files.atomic_open(p, "w").__enter__(),
    "atomic_path": lambda p: files.atomic_path(p).__enter__(),
}


@pytest.mark.parametrize("writer", WRITERS)
@pytest.mark.parametrize("kind", KINDS)
def test_every_writer_refuses_a_special_file_before_writing(writer, kind, tmp_path):
    target = _make(tmp_path / "out.npz", kind)
    with pytest.raises(OutputError, match=r"out\.npz.*(FIFO|device|socket|folder)"):
        WRITERS[writer](target)
    assert _still(target, kind)
    _no_temp_files(tmp_path)


def test_a_target_that_becomes_special_during_the_write_is_not_replaced(tmp_path):
    target = tmp_path / "results.json"
    with pytest.raises(OutputError, match="FIFO now"):
        with files.atomic_open(target, "w") as f:
            f.write("new")
            os.mkfifo(target)
    assert _still(target, "fifo")
    _no_temp_files(tmp_path)


def test_check_output_file_names_the_option(tmp_path):
    fifo = _make(tmp_path / "f", "fifo")
    with pytest.raises(ConfigError, match=r"--table .*is a FIFO; it must be a regular file or a new one"):
        files.check_output_file(fifo, "--table")
    with pytest.raises(ConfigError, match="--table '' is empty"):
        files.check_output_file("", "--table")
    assert files.check_output_file(tmp_path / "sub" / "new.json", "--table") == tmp_path / "sub" / "new.json"


@pytest.mark.parametrize("kind", ["fifo", "device", "folder"])
def test_evaluate_refuses_a_special_file_among_its_outputs_before_any_episode(kind, tmp_path, capsys, monkeypatch):
    from accd_gym.evals import evaluation

    def ran(*args, **kwargs):
        raise AssertionError("episodes ran before the output files were checked")

    monkeypatch.setattr(evaluation, "run_episodes", ran)
    out = tmp_path / "eval"
    out.mkdir()
    target = _make(out / "results.json", kind)
    assert main(["evaluate", "--policy", "zero", "--episodes", "1", "--out", str(out), "--quiet"]) == 2
    line = _error_line(capsys.readouterr().err)
    assert "--out" in line and "results.json" in line, line
    assert _still(target, kind)


@pytest.mark.parametrize("command", [["settle"], ["study", "fig9"], ["evaluate", "--policy", "zero"],
                                     ["replay", "--policy", "zero"], ["train"]], ids=lambda c: c[0])
def test_an_output_folder_that_is_a_fifo_is_refused_in_one_line(command, tmp_path, capsys):
    fifo = _make(tmp_path / "out", "fifo")
    if command == ["train"]:
        cfg = tmp_path / "cfg.json"
        cfg.write_text(json.dumps({"algo": "ppo", "total_timesteps": 64, "num_envs": 2}))
        command = ["train", "--config", str(cfg)]
    assert main([*command, "--out", str(fifo), "--quiet"]) == 2
    line = _error_line(capsys.readouterr().err)
    assert "--out" in line and "a FIFO" in line and "must be a folder" in line, line
    assert _still(fifo, "fifo")


def test_train_refuses_a_special_run_json_before_training(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    _make(out / "run.json", "fifo")
    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps({"algo": "ppo", "total_timesteps": 64, "num_envs": 2}))
    assert main(["train", "--config", str(cfg), "--out", str(out), "--quiet"]) == 2
    line = _error_line(capsys.readouterr().err)
    assert "run.json" in line and "a FIFO" in line, line
    assert not (out / "tb").exists()


# -- one writer: the package's source has no other rename or open-for-write ----------------------

#: Calls that move or copy files over a path.
_RENAMES = {("os", "replace"), ("os", "rename"), ("os", "renames"), ("os", "link"), ("shutil", "move"),
            ("shutil", "copy"), ("shutil", "copy2"), ("shutil", "copyfile"), ("shutil", "copytree")}
#: Methods that write to a path given as their first argument (a file object is fine).
_PATH_SAVERS = {"save", "savefig", "save_replay_buffer", "to_csv", "to_json", "to_parquet", "savez",
                "savez_compressed", "imwrite", "write_html", "write_image", "dump"}


def _is_path_like(node: ast.AST, joined: bool = True) -> bool:
    """Whether an argument is evidently a path: ``str(...)``, a string, an f-string or (with
    ``joined``) ``a / b``."""
    return (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "str") or (
        isinstance(node, (ast.Constant, ast.JoinedStr)) and not isinstance(getattr(node, "value", ""), bytes)) or (
        joined and isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div))


def _write_mode(call: ast.Call, position: int) -> bool:
    """Whether an ``open``-like call has a write mode (``w``, ``a``, ``x`` or ``+``)."""
    mode = call.args[position] if len(call.args) > position else next(
        (k.value for k in call.keywords if k.arg == "mode"), None)
    return isinstance(mode, ast.Constant) and isinstance(mode.value, str) and any(c in mode.value for c in "wax+")


def writes_outside_the_writer(source: str, name: str) -> list[str]:
    """Every place in ``source`` that renames a file or opens, writes or saves one by path
    without :mod:`accd_gym.files`."""
    found = []
    for node in ast.walk(ast.parse(source, name)):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        where = f"{name}:{node.lineno}"
        if isinstance(f, ast.Attribute):
            owner = f.value.id if isinstance(f.value, ast.Name) else None
            if (owner, f.attr) in _RENAMES:
                found.append(f"{where} {owner}.{f.attr}")
            elif f.attr in ("rename", "replace") and len(node.args) == 1 and not node.keywords:
                found.append(f"{where} .{f.attr}() (Path.{f.attr})")
            elif f.attr in ("write_text", "write_bytes", "touch", "symlink_to", "hardlink_to") and owner not in ("files", "_files"):
                found.append(f"{where} .{f.attr}()")
            elif f.attr == "open" and owner in ("io", "os", "gzip", "bz2", "lzma", "tarfile", "zipfile") and \
                    not any(k.arg == "fileobj" for k in node.keywords) and _write_mode(node, 1):
                found.append(f"{where} {owner}.open for writing")
            elif f.attr == "open" and owner not in ("io", "os", "gzip", "bz2", "lzma", "tarfile", "zipfile") and \
                    _write_mode(node, 0):
                found.append(f"{where} .open for writing")
            elif f.attr in _PATH_SAVERS and node.args and _is_path_like(node.args[0], joined=f.attr != "save"):
                # (a ``save(folder / name)`` is the package's own Recording.save, which writes
                # through accd_gym.files; a library's ``save`` given ``str(path)`` is not)
                found.append(f"{where} .{f.attr}(path)")
            elif owner in ("np", "numpy") and f.attr in ("save", "savetxt", "savez", "savez_compressed") and node.args \
                    and not isinstance(node.args[0], ast.Name):
                found.append(f"{where} {owner}.{f.attr}(path)")
        elif isinstance(f, ast.Name):
            if f.id == "open" and _write_mode(node, 1):
                found.append(f"{where} open for writing")
            elif f.id in ("mkstemp", "NamedTemporaryFile"):
                found.append(f"{where} {f.id}")
    return found


def test_the_one_writer_is_the_only_one_in_the_package():
    found = []
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        if path == PACKAGE_DIR / "files.py":
            continue
        found += writes_outside_the_writer(path.read_text(), str(path.relative_to(PACKAGE_DIR)))
    assert not found, "writes outside accd_gym.files:\n" + "\n".join(found)


def test_the_scan_finds_each_kind_of_write():
    source = """
import os, shutil
os.replace(a, b)
shutil.move(a, b)
tmp.rename(target)
Path(p).write_text("x")
open(p, "w")
open(p, mode="ab")
gzip.open(p, "wt")
model.save(str(tmp))
fig.savefig(out / "a.png")
np.savez(out / "a.npz", x=1)
"""
    assert len(writes_outside_the_writer(source, "example")) == 10
    fine = """
text.replace("a", "b")
dataclasses.replace(case, x=1)
files.write_text(p, "x")
open(p)
open(p, "rb")
tarfile.open(fileobj=buf, mode="w")
model.save(f)
rec.save(path)
fig.savefig(f, format="png")
"""
    assert writes_outside_the_writer(fine, "example") == []


#: Library calls that write their own files, each allowed in one module only, with the reason.
#: The module checks the output folder (``files.writable_folder``) before any work.
LIBRARY_WRITERS = {
    # Minari writes a dataset's files (its HDF5 episodes and metadata) into its dataset root
    # itself: the Farama format is Minari's to write, not ours to reimplement.
    "create_dataset_from_buffers": "evals/datasets.py",
}


def test_library_writers_are_called_only_where_allowed_after_the_folder_check():
    for call, allowed in LIBRARY_WRITERS.items():
        users = sorted(str(p.relative_to(PACKAGE_DIR)) for p in PACKAGE_DIR.rglob("*.py") if f"{call}(" in p.read_text())
        assert users == [allowed], f"{call} called in {users}, allowed only in {allowed}"
        source = (PACKAGE_DIR / allowed).read_text()
        assert source.index("files.writable_folder(") < source.index(f"{call}("), f"{allowed} checks its folder first"
