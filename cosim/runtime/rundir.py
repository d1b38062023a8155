"""The run directory (``--out``): checked, claimed and locked before anything starts (README, "Run directory").

:func:`open_run_dir` refuses, with a :class:`RunDirError` naming the path and the reason (the CLI: one line, exit
2), a run directory that:

* is not a directory, or cannot be made: only its last level is created unless ``parents`` (``--parents``), so a
  mistyped parent (``--out /nonexistent/dir``) is refused instead of growing a tree;
* this user cannot write to;
* another run is writing to: ``.lock`` is held with ``fcntl.flock`` while a run writes (the message names the
  first launcher's pid);
* holds an earlier run (its summary.json or run.json), unless ``overwrite`` (``--overwrite``), which
  first removes that run's own files (:data:`RUN_FILES` and their temporary files) and nothing else: the old
  run's maps, figures or log never mix with the new run's;
* holds a file a run would replace (a :data:`RUN_FILES` name) but no earlier run (the user's own scenario.yaml):
  refused even with ``overwrite``, since a user's file is never removed.

A new file a run writes joins :data:`RUN_FILES` (a test checks the outputs' names against it).
"""
from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path

from cosim.errors import RunRefused, shown_path

from .files import TMP_PREFIX, TMP_SUFFIX

__all__ = ["LOCK_NAME", "RUN_FILES", "RunDirError", "RunDirLock", "open_run_dir", "make_out_dir", "earlier_run",
           "clear_run_files"]

#: the lock file inside a run directory (held with flock while a run writes there)
LOCK_NAME = ".lock"
#: every file a run writes into its run directory (names; each also as its temporary ``.NAME.tmp``)
RUN_FILES = ("summary.json", "run.json", "scenario.yaml", "log.txt", "timeseries.csv", "timing.csv",
             "heightmap_truth.npy", "heightmap_perceived.npy", "fig7_fullness.png", "fig8_heightmaps.png",
             "fig9_auger.png", "fig10_profile.png", "recording.mcap")


class RunDirError(RunRefused):
    """The run directory cannot be used (see the module docstring); nothing was started."""


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


def _read_json(path: Path) -> dict | None:
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def earlier_run(run_dir: Path) -> str | None:
    """A description of the run ``run_dir`` holds ("a run of 'default' (completed, <when>)"), or None when it
    holds none. A run is known by its summary.json (with a ``status``, written first thing) or its run.json (with
    a ``segment``)."""
    summary = _read_json(run_dir / "summary.json")
    if summary is not None and "status" in summary:
        when = summary.get("written_utc") or summary.get("started_utc")
        return (f"a run of {summary.get('scenario', '?')!r} ({summary['status']}"
                + (f", {when}" if when else "") + ")")
    info = _read_json(run_dir / "run.json")
    if info is not None and "segment" in info:
        return "a run (its run.json)"
    return None


def clear_run_files(run_dir: Path) -> list[str]:
    """Remove the run's own files from ``run_dir`` (:data:`RUN_FILES` and their temporary files); returns the
    names removed. Any other file stays."""
    removed = []
    for name in RUN_FILES:
        for path in (run_dir / name, run_dir / f"{TMP_PREFIX}{name}{TMP_SUFFIX}"):
            try:
                path.unlink()
            except FileNotFoundError:
                continue
            except OSError as exc:
                raise RunDirError(f"--out {shown_path(run_dir)}: cannot remove the earlier run's {path.name}: "
                                  f"{exc.strerror or exc}") from None
            removed.append(path.name)
    return removed


def make_out_dir(run_dir: Path, parents: bool = False) -> None:
    """Make the directory ``run_dir`` names (``--out``): only its last level unless ``parents``. Raises
    :class:`RunDirError` when it is not a directory, cannot be made, or cannot be written."""
    run_dir = Path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise RunDirError(f"--out {shown_path(run_dir)}: exists and is not a directory")
    try:
        run_dir.mkdir(parents=parents, exist_ok=True)
    except FileNotFoundError:
        raise RunDirError(f"--out {shown_path(run_dir)}: its parent folder {shown_path(run_dir.parent)} does not exist; create it, or add "
                          "--parents to create every missing folder") from None
    except OSError as exc:
        raise RunDirError(f"--out {shown_path(run_dir)}: cannot create the directory: {exc.strerror or exc}") from None
    if not os.access(run_dir, os.W_OK | os.X_OK):
        raise RunDirError(f"--out {shown_path(run_dir)}: permission denied (the directory is not writable)")


def _lock(run_dir: Path) -> RunDirLock:
    lock = run_dir / LOCK_NAME
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise RunDirError(f"--out {shown_path(run_dir)}: cannot create {LOCK_NAME}: {exc.strerror or exc}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        holder = ""
        try:
            holder = os.read(fd, 64).decode(errors="replace").strip()
        except OSError:
            pass
        os.close(fd)
        raise RunDirError(f"--out {shown_path(run_dir)}: another run is writing there"
                          + (f" (launcher pid {holder})" if holder else "") + "; choose another --out") from None
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
    except OSError:
        pass  # the pid is only a courtesy for the message above
    return RunDirLock(lock, fd)


def _claim(run_dir: Path, overwrite: bool) -> None:
    """Refuse or clear an earlier run; refuse to replace a file that is not a run's."""
    earlier = earlier_run(run_dir)
    if earlier is not None:
        if not overwrite:
            raise RunDirError(f"--out {shown_path(run_dir)}: holds {earlier}; choose another --out, or add --overwrite to "
                              "replace that run's files")
        clear_run_files(run_dir)
        return
    clash = [n for n in RUN_FILES if (run_dir / n).exists()]
    if clash:
        raise RunDirError(f"--out {shown_path(run_dir)}: holds {', '.join(clash)}, which a run would replace, but no earlier "
                          "run (no summary.json or run.json); choose another --out (files that are not a run's "
                          "are never replaced, --overwrite or not)")


def open_run_dir(run_dir: Path, *, overwrite: bool = False, parents: bool = False) -> RunDirLock:
    """Make ``run_dir`` (its parents too with ``parents``), check that it can be written, lock it for this run and
    claim it (an earlier run's files removed with ``overwrite``, refused without). Raises :class:`RunDirError`
    naming the path and the reason; nothing is started before this."""
    run_dir = Path(run_dir)
    make_out_dir(run_dir, parents)
    lock = _lock(run_dir)
    try:
        _claim(run_dir, overwrite)
    except BaseException:
        lock.release()
        raise
    return lock
