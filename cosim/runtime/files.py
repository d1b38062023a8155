"""Writing a run directory safely: atomic replacement, named write errors, the run directory's lock.

* :func:`atomic_write` replaces a file whole or not at all (a temporary file in the same directory, flushed,
  then renamed over the target), so a reader or a killed launcher never sees half a file.
* :func:`write_error` turns an ``OSError`` into an :class:`cosim.errors.OutputError` that names the path and the
  cause in words ("no space left on device writing runs/x/timeseries.csv"), for a message without a traceback.
* :func:`open_run_dir` checks ``--out`` before anything starts (it is, or can be made, a writable directory) and
  takes the run directory's lock (``fcntl.flock`` on ``.lock``), so a second run with the same ``--out`` is
  refused while the first one runs; :class:`RunDirError` says why (the CLI exits 2).
"""
from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

from cosim.errors import OutputError, RunRefused

__all__ = ["LOCK_NAME", "RunDirError", "RunDirLock", "atomic_write", "write_error", "open_run_dir",
           "overwrite_in_place"]

#: the lock file inside a run directory (held with flock while a run writes there)
LOCK_NAME = ".lock"


class RunDirError(RunRefused):
    """The run directory cannot be used (not a directory, not writable, another run holds it)."""


def write_error(exc: OSError, path: Path | str, what: str = "writing") -> OutputError:
    """An :class:`OutputError` naming ``path`` and the cause of ``exc`` (ENOSPC: "no space left on device")."""
    cause = {errno.ENOSPC: "no space left on device", errno.EDQUOT: "disk quota exceeded",
             errno.EACCES: "permission denied", errno.EROFS: "read-only file system"}.get(
        exc.errno, exc.strerror or type(exc).__name__)
    return OutputError(f"{cause} {what} {path}")


def atomic_write(path: Path, data: bytes | str) -> None:
    """Replace ``path`` with ``data`` atomically (temporary file, flush, rename). Raises :class:`OutputError`."""
    path = Path(path)
    raw = data.encode() if isinstance(data, str) else data
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(raw)
            f.flush()
        os.replace(tmp, path)
    except OSError as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise write_error(exc, path) from None


def overwrite_in_place(path: Path, data: bytes | str) -> None:
    """Write ``data`` over ``path``'s first bytes and cut the rest (no new blocks needed when ``data`` is no
    longer than the file: the fallback for a summary on a full disk). Raises :class:`OutputError`."""
    raw = data.encode() if isinstance(data, str) else data
    try:
        with open(path, "r+b") as f:
            f.write(raw)
            f.truncate(len(raw))
    except OSError as exc:
        raise write_error(exc, path) from None


class RunDirLock:
    """The held lock of one run directory; :meth:`release` (idempotent) drops it and removes the file."""

    def __init__(self, path: Path, fd: int):
        self.path, self._fd = path, fd

    def release(self) -> None:
        if self._fd < 0:
            return
        try:
            self.path.unlink()
        except OSError:
            pass
        os.close(self._fd)
        self._fd = -1


def open_run_dir(run_dir: Path) -> RunDirLock:
    """Make ``run_dir`` (parents included), check it is a writable directory and lock it for this run.

    Raises :class:`RunDirError` naming the path and the reason; nothing is started before this."""
    run_dir = Path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise RunDirError(f"--out {run_dir}: exists and is not a directory")
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunDirError(f"--out {run_dir}: cannot create the directory: {exc.strerror or exc}") from None
    if not os.access(run_dir, os.W_OK | os.X_OK):
        raise RunDirError(f"--out {run_dir}: permission denied (the directory is not writable)")
    lock = run_dir / LOCK_NAME
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise RunDirError(f"--out {run_dir}: cannot create {LOCK_NAME}: {exc.strerror or exc}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        holder = ""
        try:
            holder = os.read(fd, 64).decode(errors="replace").strip()
        except OSError:
            pass
        os.close(fd)
        raise RunDirError(f"--out {run_dir}: another run is writing there"
                          + (f" (launcher pid {holder})" if holder else "") + "; choose another --out") from None
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
    except OSError:
        pass  # the pid is only a courtesy for the message above
    return RunDirLock(lock, fd)
