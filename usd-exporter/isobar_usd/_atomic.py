"""Atomic file replacement: write beside the target under a hidden staging name, fsync,
rename into place. A write that fails or is killed leaves the previous file as it was;
staging files of processes that no longer run are swept by the next write."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import glob
import os
import re
import socket
from pathlib import Path
from typing import Iterator

_HOST = re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname() or "host")
# .NAME.HOST-PID.tmp.EXT
_STAGED = re.compile(r"^\.(?P<name>.+)\.(?P<host>[A-Za-z0-9_-]+)-(?P<pid>[0-9]+)\.tmp(?P<ext>\.[^.]+)?$")


def staging_path(final: Path, pid: int | None = None) -> Path:
    """A hidden sibling of `final` with the same extension (USD picks the file format
    from it), unique to this host and process."""
    final = Path(final)
    pid = os.getpid() if pid is None else pid
    return final.with_name(f".{final.name}.{_HOST}-{pid}.tmp{final.suffix}")


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def replace(staged: Path, final: Path) -> None:
    """Renames the finished staging file over `final` (after flushing it to disk). Tests
    monkeypatch this to interrupt a write at the last moment."""
    _fsync_file(staged)
    os.replace(staged, final)
    _fsync_dir(Path(final).parent)


def discard(path: Path) -> None:
    """Removes a staging file, if it is there, and the temporary siblings USD's own writer
    makes beside it (`<staged stem>.XXXXXX`), which a process killed mid-export leaves."""
    path = Path(path)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)
    stem = path.name[: -len(path.suffix)] if path.suffix else path.name
    if _STAGED.match(path.name):
        with contextlib.suppress(OSError):
            for sibling in path.parent.glob(glob.escape(stem) + ".*"):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(sibling)


@contextlib.contextmanager
def atomic_path(final: Path) -> Iterator[Path]:
    """Yields a staging path to write; renames it over `final` when the block succeeds,
    removes it when the block raises."""
    final = Path(final)
    staged = staging_path(final)
    discard(staged)
    try:
        yield staged
        if not staged.is_file():
            raise FileNotFoundError(errno.ENOENT, "the writer produced no file", str(staged))
        replace(staged, final)
    except BaseException:
        discard(staged)
        raise


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep(directory: Path) -> list:
    """Removes the staging files in `directory` left by dead processes of this host (a
    killed write); returns their paths."""
    removed = []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    for name in names:
        match = _STAGED.match(name)
        if not match or match.group("host") != _HOST:
            continue
        pid = int(match.group("pid"))
        if pid == os.getpid() or _alive(pid):
            continue
        path = Path(directory) / name
        with contextlib.suppress(OSError):
            os.unlink(path)
            removed.append(path)
    return removed


@contextlib.contextmanager
def locked(lock_file: Path) -> Iterator[None]:
    """An exclusive advisory lock (flock) on `lock_file`, created when missing; serialises
    the commit-and-stitch step of writers running side by side."""
    fd = os.open(lock_file, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        try:
            fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)
