"""The files accd-gym writes and reads: atomic writes, output-path checks, bounded reads.

Nothing a user saved is lost, and nothing a user points us at is replaced: every file the
package writes (models, checkpoints, statistics, ``run.json``, evaluation results,
trajectories, reports, benchmark outputs, recordings, replay pages and videos, tables) goes
through one function, :func:`atomic_path` (:func:`atomic_open`, :func:`write_text`,
:func:`write_bytes`, :func:`save_figure` and :func:`save_npz` are built on it; a library that
writes only to a path or a file object, such as stable-baselines3's ``save``, writes to a
buffer handed to :func:`write_bytes`). It writes a temporary file in the target's folder,
flushes it to the disk (``fsync``) and renames it over the target, only where the target is a
regular file or does not exist yet (:func:`output_target`):

* a symbolic link is followed: the file it names is replaced, atomically, in that file's own
  folder, and the link stays a link;
* a FIFO, a device, a socket or a folder where a file is expected, an empty path or a path
  with a NUL character is refused (:class:`~accd_gym.errors.ConfigError` from
  :func:`check_output_file`, :class:`~accd_gym.errors.OutputError` from the writers), so that
  ``--out /dev/null`` never replaces the system's device node. Printing to the standard output
  is not an output path: ``-`` and ``/dev/stdout`` are refused like any other special file.

A crash, a Ctrl+C or a full disk therefore leaves either the previous good file or the new
complete one, never half a file; a failed write raises :class:`~accd_gym.errors.OutputError`
naming the file and removes its temporary file.

Commands check their output paths before they start (:func:`check_output_file` for a file,
:func:`writable_folder` for a folder and the files they will write in it), so that a
read-only folder or a special file is refused before hours of work rather than after.

Every file the user names as an input (configs, tuning files, ``run.json``, tables) is read
with :func:`read_user_file`: a regular file (checked before it is opened: opening a FIFO blocks)
of at most :data:`MAX_INPUT_FILE_BYTES`, the bound enforced while reading.

Platforms. On Linux and macOS the rename is atomic (POSIX ``rename``) and the folder is flushed
after it. On Windows ``os.replace`` (``MoveFileEx`` with ``MOVEFILE_REPLACE_EXISTING``) also
replaces an existing file in one step, but fails while another process holds the target open
without sharing deletion (a virus scanner, an indexer or a viewer, briefly): the rename is then
retried for up to :data:`REPLACE_RETRY_SECONDS` before the write fails. ``fsync`` needs a
descriptor open for writing there (``FlushFileBuffers``), so the temporary file is reopened
read-write; a folder cannot be opened to flush its entries, which NTFS journals itself. The
Windows behaviour is assumed from its documentation: the test suite runs on Linux, where it
simulates the Windows failures (a held target, a read-only descriptor) to test the retry and the
reopen.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import stat
import tempfile
import time
from pathlib import Path
from typing import IO, Iterator, Optional, Sequence

from accd_gym.errors import ConfigError, OutputError

#: The largest config, tuning, run summary or table file read, bytes (64 MiB; the same limit as
#: the core's table reader, ``accd_sim::table_file::MAX_TABLE_FILE_BYTES``).
MAX_INPUT_FILE_BYTES: int = 64 * 1024 * 1024

#: The prefix of temporary files (hidden; never matched by the package's own file patterns).
TEMP_PREFIX = ".accd-tmp-"

#: How long a rename over a file that another process holds open is retried, s (Windows only:
#: elsewhere a rename never fails for that reason, and a failed one fails at once).
REPLACE_RETRY_SECONDS: float = 1.0 if os.name == "nt" else 0.0


def _fsync_folder(folder: Path) -> None:
    """Flushes a folder's entries (the rename) to the disk; a file system or platform that cannot
    (Windows opens no folder as a file) is left be."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _rename_retrying(tmp: Path, target: Path) -> None:
    """Renames ``tmp`` over ``target``; a PermissionError (Windows: the target is held open by
    another process) is retried with a growing pause for up to :data:`REPLACE_RETRY_SECONDS`."""
    deadline = time.monotonic() + REPLACE_RETRY_SECONDS
    pause = 0.01
    while True:
        try:
            os.replace(tmp, target)
            return
        except PermissionError:
            if time.monotonic() + pause > deadline:
                raise
            time.sleep(pause)
            pause = min(2 * pause, 0.2)


def _output_error(path: Path, e: OSError) -> OutputError:
    """An :class:`OutputError` for a failed write of ``path``."""
    return OutputError(f"cannot write {str(path)!r}: {e.strerror or e}; the previous file, if any, is unchanged",
                       e.errno, str(path))


def _path_refusal(path: str | Path) -> tuple[Optional[str], Optional[Path]]:
    """``(why, target)``: why ``path`` cannot be an output file (None when it can) and the
    regular file a write replaces or creates (symbolic links followed to the file they name)."""
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if text == "":
        return "is empty; it must name a file", None
    if "\0" in text:
        return "contains a NUL character; it must name a file", None
    if text == "-":
        return "is '-' (the standard output); it must name a file", None
    try:
        mode = os.stat(text).st_mode  # follows symbolic links
    except FileNotFoundError:
        mode = None  # a new file (or a link to one not yet written)
    except OSError as e:
        return f"cannot be used ({e.strerror or e})", None
    if mode is not None and not stat.S_ISREG(mode):
        return f"is {_kind(mode)}; it must be a regular file or a new one", None
    return None, Path(os.path.realpath(text))


def output_target(path: str | Path) -> Path:
    """The regular file a write of ``path`` replaces or creates: ``path`` itself, or with symbolic
    links followed, the file they name (which is then replaced in its own folder). OutputError
    naming ``path`` when it is empty, holds a NUL character, is ``-`` or names something that
    is not a regular file (a FIFO, a device, a socket, a folder): such a path is never replaced."""
    why, target = _path_refusal(path)
    if why is not None or target is None:
        raise OutputError(f"cannot write {os.fspath(path)!r}: the output path {why}", errno.EINVAL, str(path))
    return target


def check_output_file(path: str | Path, option: str = "--out") -> Path:
    """Checks, before any work, that ``path`` (given as ``option``) can be written as a file:
    :func:`output_target`'s rules, and its folder writable (:func:`writable_folder`). Returns
    ``path``; ConfigError naming ``option``, the path and the reason otherwise."""
    why, target = _path_refusal(path)
    if why is not None or target is None:
        raise ConfigError(f"invalid config: {option} {os.fspath(path)!r} {why}")
    writable_folder(target.parent, option)
    return Path(path)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """The one writer of the package: a temporary path in the folder of ``path``'s target
    (:func:`output_target`: a regular file, a new one or the file a symbolic link names; same
    suffix, for writers that choose the format by it) to write to; on a clean exit it is flushed
    to the disk and renamed over the target. On an error (or a KeyboardInterrupt) the temporary
    file is removed and the target left as it was; an OSError becomes :class:`OutputError`
    naming ``path``. A target that is not a regular file is refused before anything is written
    and checked again just before the rename."""
    target = output_target(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise _output_error(target, e) from None
    tmp = target.parent / f"{TEMP_PREFIX}{target.name}.{secrets.token_hex(4)}{target.suffix}"
    try:  # created like open() would (mode 0o666 less the umask), unlike mkstemp's 0o600
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    except OSError as e:
        raise _output_error(target, e) from None
    try:
        yield tmp
        # Read-write: Windows flushes only a descriptor open for writing.
        fd = os.open(tmp, os.O_RDWR | getattr(os, "O_BINARY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        _replace(tmp, target)
    except BaseException as e:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(e, OSError) and not isinstance(e, OutputError):
            raise _output_error(target, e) from None
        raise
    _fsync_folder(target.parent)


def _replace(tmp: Path, target: Path) -> None:
    """Renames ``tmp`` over ``target`` unless ``target`` has become something other than a
    regular file since the write started (then OutputError; the caller removes ``tmp``)."""
    try:
        mode = os.lstat(target).st_mode
    except FileNotFoundError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode):
        raise OutputError(f"cannot write {str(target)!r}: it is {_kind(mode)} now; it must be a regular file or a new one",
                          errno.EINVAL, str(target))
    _rename_retrying(tmp, target)


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "wb", **kwargs) -> Iterator[IO]:
    """An open temporary file (``mode`` ``"wb"`` or ``"w"``) that replaces ``path`` when the block
    ends cleanly (see :func:`atomic_path`)."""
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_open: mode {mode!r} is outside the allowed set ['w', 'wb']")
    with atomic_path(path) as tmp:
        with open(tmp, mode, **kwargs) as f:
            yield f
            f.flush()


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Writes ``data`` to ``path`` atomically; returns ``path``."""
    with atomic_open(path, "wb") as f:
        f.write(data)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    """Writes ``text`` (UTF-8) to ``path`` atomically; returns ``path``."""
    return write_bytes(path, text.encode("utf-8"))


def save_figure(fig, path: str | Path, **kwargs) -> Path:
    """Saves a matplotlib figure to ``path`` atomically (format from the suffix); returns ``path``."""
    p = Path(path)
    with atomic_open(p, "wb") as f:
        fig.savefig(f, format=p.suffix.lstrip(".") or "png", **kwargs)
    return p


def save_npz(path: str | Path, **arrays) -> Path:
    """Writes ``numpy.savez_compressed`` of ``arrays`` to ``path`` atomically; returns ``path``."""
    import numpy as np

    with atomic_open(path, "wb") as f:
        np.savez_compressed(f, **arrays)
    return Path(path)


#: The name of a run folder's reserve file (:func:`reserve_space`).
RESERVE_NAME = ".accd-reserve"
#: The bytes a run folder keeps in reserve: room for its run summary on a full disk.
RESERVE_BYTES = 256 * 1024


def shelve_folder(folder: str | Path, shelf: str | Path) -> Path:
    """Moves ``folder`` whole into ``shelf`` (created if needed) as ``<name>-<k>``, ``k`` the first
    number whose name is free, and returns its new path: what a command sets aside instead of
    deleting or overwriting it. A rename on one file system (nothing copied, nothing lost
    half-way); OutputError naming the folder when it cannot be moved."""
    src, shelf = Path(folder), Path(shelf)
    try:
        shelf.mkdir(parents=True, exist_ok=True)
        k = 1
        while os.path.lexists(shelf / f"{src.name}-{k}"):
            k += 1
        target = shelf / f"{src.name}-{k}"
        os.rename(src, target)
    except OSError as e:
        raise _output_error(src, e) from None
    _fsync_folder(shelf)
    _fsync_folder(src.parent)
    return target


def reserve_space(folder: str | Path, nbytes: int = RESERVE_BYTES) -> bool:
    """Writes a reserve file of ``nbytes`` zeros into ``folder`` (:data:`RESERVE_NAME`), so that a
    small file (a run summary) can still be written once the disk has filled up: the writer
    frees the reserve (:func:`release_space`) and writes again. Returns whether it could (a disk
    already full has no room for it)."""
    try:
        write_bytes(Path(folder) / RESERVE_NAME, bytes(nbytes))
    except OutputError:
        return False
    return True


def release_space(folder: str | Path) -> bool:
    """Removes ``folder``'s reserve file (:func:`reserve_space`); returns whether there was one."""
    try:
        os.unlink(Path(folder) / RESERVE_NAME)
    except OSError:
        return False
    return True


def writable_folder(path: str | Path, option: str = "--out", files: Sequence[str] = ()) -> Path:
    """``path`` created if needed and checked writable by writing, flushing and removing a small
    probe file, so that a command refuses a read-only folder (or a full disk) before it starts,
    and each of ``files`` (names in it the command will write) checked by the rules of
    :func:`output_target`; ConfigError naming ``option`` and the folder or file otherwise
    (an empty path, a NUL character, a FIFO, a device or a file where the folder should be)."""
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if text == "" or "\0" in text:
        what = "is empty" if text == "" else "contains a NUL character"
        raise ConfigError(f"invalid config: {option} {text!r} {what}; it must name a folder")
    try:
        mode = os.stat(text).st_mode
    except OSError:
        mode = None
    if mode is not None and not stat.S_ISDIR(mode):
        raise ConfigError(f"invalid config: {option} {text!r} is {_kind(mode)}; it must be a folder")
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
        if not p.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, "not a folder", str(p))
        with tempfile.NamedTemporaryFile(prefix=f"{TEMP_PREFIX}probe.", dir=p) as f:
            f.write(b"accd-gym write test\n")
            f.flush()
            os.fsync(f.fileno())
    except OSError as e:
        raise ConfigError(f"invalid config: {option} {str(path)!r} is not a writable folder ({e.strerror or e})") from None
    for name in files:  # (one stat each: the folder is probed once)
        why, _ = _path_refusal(p / name)
        if why is not None:
            raise ConfigError(f"invalid config: {option} {str(p / name)!r} {why}")
    return p


def _kind(mode: int) -> str:
    """What a path that is not a regular file is, in words."""
    if stat.S_ISREG(mode):
        return "a file"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_regular_file(path: str | Path, what: str, allowed: str = "a regular file") -> None:
    """ConfigError naming ``what`` and the path when ``path`` is missing or is not a regular file
    (a folder, a FIFO, a device), checked without opening it (opening a FIFO blocks)."""
    try:
        mode = os.stat(path).st_mode
    except OSError as e:
        raise ConfigError(f"invalid config: {what} {str(path)!r} cannot be read ({e.strerror or e})") from None
    except ValueError as e:  # a NUL character in the path
        raise ConfigError(f"invalid config: {what} {str(path)!r} is not a file name ({e})") from None
    if not stat.S_ISREG(mode):
        raise ConfigError(f"invalid config: {what} {str(path)!r} is {_kind(mode)}; it must be {allowed}")


def read_user_file(path: str | Path, what: str, limit: int = MAX_INPUT_FILE_BYTES) -> bytes:
    """The bytes of the file a user named as ``what`` (e.g. ``"training config"``,
    ``"accd.aero_table"``): ConfigError naming ``what``, the path and the limit when it is
    missing, not a regular file (checked before it is opened: opening a FIFO blocks, a device
    never ends) or larger than ``limit`` bytes (enforced while reading: the file may grow)."""
    p = Path(path)
    allowed = f"a regular file of at most {limit // (1024 * 1024)} MiB"
    check_regular_file(p, what, allowed)
    chunks: list[bytes] = []
    size = 0
    try:
        with open(p, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):  # replaced since the check
                raise ConfigError(f"invalid config: {what} {str(path)!r} is not a regular file; it must be {allowed}")
            while size <= limit:
                chunk = f.read(min(1 << 20, limit + 1 - size))
                if not chunk:
                    break
                chunks.append(chunk)
                size += len(chunk)
    except OSError as e:
        raise ConfigError(f"invalid config: {what} {str(path)!r} cannot be read ({e.strerror or e})") from None
    data = b"".join(chunks)
    if len(data) > limit:
        raise ConfigError(f"invalid config: {what} {str(path)!r} is larger than {limit} bytes; it must be {allowed}")
    return data


def read_user_json(path: str | Path, what: str):
    """The JSON value in the file a user named as ``what`` (:func:`read_user_file`); ConfigError
    naming the file when it is not UTF-8 JSON."""
    import json

    data = read_user_file(path, what)
    try:
        return json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise ConfigError(f"invalid config: {what} {str(path)!r} is not valid JSON ({str(e)[:200]})") from None
    except RecursionError:
        raise ConfigError(f"invalid config: {what} {str(path)!r} is nested too deeply to read") from None


__all__ = ["MAX_INPUT_FILE_BYTES", "REPLACE_RETRY_SECONDS", "RESERVE_BYTES", "RESERVE_NAME", "atomic_open", "atomic_path", "check_output_file",
           "check_regular_file", "output_target", "read_user_file", "read_user_json", "release_space", "reserve_space", "save_figure",
           "save_npz", "write_bytes", "write_text", "writable_folder"]
