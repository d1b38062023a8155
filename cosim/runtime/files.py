"""Writing files safely: atomic replacement and named write errors (the run directory itself: cosim.runtime.rundir).

* :func:`atomic_write` replaces a file whole or not at all (a temporary file in the same directory, flushed,
  then renamed over the target), so a reader or a killed launcher never sees half a file.
* :func:`write_error` turns an ``OSError`` into an :class:`cosim.errors.OutputError` that names the path and the
  cause in words ("no space left on device writing runs/x/timeseries.csv"), for a message without a traceback.
"""
from __future__ import annotations

import errno
import os
from pathlib import Path

from cosim.errors import OutputError

__all__ = ["TMP_PREFIX", "TMP_SUFFIX", "atomic_write", "write_error", "overwrite_in_place"]

#: how :func:`atomic_write` names the temporary file of ``NAME``: ``.NAME.tmp`` beside it
TMP_PREFIX, TMP_SUFFIX = ".", ".tmp"


def write_error(exc: OSError, path: Path | str, what: str = "writing") -> OutputError:
    """An :class:`OutputError` naming ``path`` and the cause of ``exc`` (ENOSPC: "no space left on device")."""
    cause = {errno.ENOSPC: "no space left on device", errno.EDQUOT: "disk quota exceeded",
             errno.EACCES: "permission denied", errno.EROFS: "read-only file system"}.get(
        exc.errno, exc.strerror or type(exc).__name__)
    return OutputError(f"{cause} {what} {path}")


def atomic_write(path: Path, data: bytes | str) -> None:
    """Replace ``path`` with ``data`` atomically (temporary file, flush, rename). Raises :class:`OutputError`; the
    temporary file is removed whatever interrupts the write (an error, a stop signal raised meanwhile)."""
    path = Path(path)
    raw = data.encode() if isinstance(data, str) else data
    tmp = path.with_name(f"{TMP_PREFIX}{path.name}{TMP_SUFFIX}")
    try:
        with open(tmp, "wb") as f:
            f.write(raw)
            f.flush()
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise write_error(exc, path) from None
        raise


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
