"""Writing files safely: atomic replacement and named write errors (the run directory itself: cosim.runtime.rundir).

* :func:`atomic_write` replaces a file whole or not at all (a temporary file in the same directory, flushed,
  then renamed over the target), so a reader or a killed launcher never sees half a file; :func:`atomic_replace`
  is the same for a writer that wants a path of its own (numpy, pyarrow, csv).
* :func:`write_error` turns an ``OSError`` into an :class:`cosim.errors.OutputError` that names the path and the
  cause in words ("no space left on device writing runs/x/timeseries.csv"), for a message without a traceback.
"""
from __future__ import annotations

import errno
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from cosim.errors import OutputError

__all__ = ["TMP_PREFIX", "TMP_SUFFIX", "atomic_replace", "atomic_write", "write_error", "overwrite_in_place"]

#: how :func:`atomic_write` names the temporary file of ``NAME``: ``.NAME.tmp`` beside it
TMP_PREFIX, TMP_SUFFIX = ".", ".tmp"


def write_error(exc: OSError, path: Path | str, what: str = "writing") -> OutputError:
    """An :class:`OutputError` naming ``path`` and the cause of ``exc`` (ENOSPC: "no space left on device")."""
    cause = {errno.ENOSPC: "no space left on device", errno.EDQUOT: "disk quota exceeded",
             errno.EACCES: "permission denied", errno.EROFS: "read-only file system"}.get(
        exc.errno, exc.strerror or type(exc).__name__)
    return OutputError(f"{cause} {what} {path}")


@contextmanager
def atomic_replace(path: Path | str) -> Iterator[Path]:
    """The temporary file (``.NAME.tmp`` beside ``path``) to write ``path``'s new content into, by any writer (a
    CSV writer, numpy, pyarrow); renamed over ``path`` when the block ends, removed whatever interrupts it (an
    error, a stop signal raised meanwhile). An ``OSError`` comes out as :class:`OutputError` naming ``path``."""
    path = Path(path)
    tmp = path.with_name(f"{TMP_PREFIX}{path.name}{TMP_SUFFIX}")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise write_error(exc, path) from None
        raise


def atomic_write(path: Path | str, data: bytes | str) -> None:
    """Replace ``path`` with ``data`` atomically (:func:`atomic_replace`: temporary file, flush, rename). Raises
    :class:`OutputError`."""
    raw = data.encode() if isinstance(data, str) else data
    with atomic_replace(path) as tmp, open(tmp, "wb") as f:
        f.write(raw)
        f.flush()


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
