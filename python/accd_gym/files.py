"""The files accd-gym writes and reads: atomic writes, writable-folder checks, bounded reads.

Nothing a user saved is lost: every file the package writes (checkpoints, statistics,
``run.json``, evaluation results, trajectories, benchmark outputs, recordings, replay pages and
videos) is written to a temporary file in the same folder, flushed to the disk (``fsync``) and
renamed over the target (:func:`atomic_path`, :func:`atomic_open`, :func:`write_text`,
:func:`write_bytes`). A crash, a Ctrl+C or a full disk therefore leaves either the previous good
file or the new complete one, never half a file; a failed write raises :class:`~accd_gym.errors.OutputError`
naming the file and removes its temporary file.

Commands check their output folder before they start (:func:`writable_folder`), so that a
read-only folder is refused before hours of work rather than after.

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
from typing import IO, Iterator

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


def _replace(tmp: Path, target: Path) -> None:
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


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path in ``path``'s folder (same suffix, for writers that choose the format by
    it) to write to; on a clean exit it is flushed to the disk and renamed over ``path``. On an
    error (or a KeyboardInterrupt) the temporary file is removed and ``path`` left as it was;
    an OSError becomes :class:`OutputError` naming ``path``."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
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


def writable_folder(path: str | Path, option: str = "--out") -> Path:
    """``path`` created if needed and checked writable by writing, flushing and removing a small
    probe file, so that a command refuses a read-only folder (or a full disk) before it starts;
    ConfigError naming ``option`` and the folder otherwise."""
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
    return p


def _kind(mode: int) -> str:
    """What a path that is not a regular file is, in words."""
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
        raise ConfigError(f"invalid config: {what} {str(path)!r} is not valid JSON ({e})") from None


__all__ = ["MAX_INPUT_FILE_BYTES", "REPLACE_RETRY_SECONDS", "atomic_open", "atomic_path", "check_regular_file", "read_user_file", "read_user_json", "save_figure", "save_npz",
           "write_bytes", "write_text", "writable_folder"]
