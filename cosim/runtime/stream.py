"""The run directory written as the run goes (docs/architecture.md): nothing lives only in the launcher's memory.

* summary.json is written first, small, with ``status: "running"`` and ``completed: false`` and padded to
  ``SUMMARY_RESERVE`` bytes: a launcher killed with SIGKILL leaves a summary that says the run did not finish,
  and the final summary (atomically replaced at the end) can still be written over it on a full disk.
* timeseries.csv (deterministic columns) and timing.csv (wall-clock columns) get their header at once and their
  rows appended in blocks, flushed to the kernel, every ``BLOCK_S`` seconds of the run: SIGKILL of the launcher
  loses at most the frames of the last ``BLOCK_S`` (plus the one a deferred member still owes). The supervisor
  appends after it has handed the token on, off the ring's critical path.
* A write error stops the streaming, cuts the file back to its last whole row (so no half row stays), and is
  raised as an :class:`cosim.errors.OutputError` naming the path ("no space left on device writing ...").
"""
from __future__ import annotations

import json
import os
import time
from datetime import datetime, timezone
from pathlib import Path

from cosim.errors import OutputError

from .files import atomic_write, overwrite_in_place, write_error
from .recorder import Recorder

__all__ = ["BLOCK_S", "SUMMARY_RESERVE", "RunFiles", "write_running_summary", "write_final_summary"]

#: seconds of run between two appended blocks of rows
BLOCK_S = 0.5
#: bytes summary.json takes from the start (JSON padded with spaces), so the final one fits on a full disk
SUMMARY_RESERVE = 16 << 10


def write_running_summary(run_dir: Path, head: dict) -> None:
    """summary.json before the first frame: ``head`` plus ``status: running``, padded to SUMMARY_RESERVE."""
    body = {**head, "status": "running", "completed": False, "frames": 0,
            "started_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    text = json.dumps(body, indent=2) + "\n"
    atomic_write(Path(run_dir) / "summary.json", text + " " * max(0, SUMMARY_RESERVE - len(text)))


def write_final_summary(run_dir: Path, summary: dict, *, reserve: bool = False) -> None:
    """Replace summary.json atomically; on a full disk, write it over the reserved one instead (a traceback that
    does not fit is cut). ``reserve``: pad it to SUMMARY_RESERVE again (a summary that will be rewritten: the run's
    figures are drawn after it). Raises :class:`OutputError` only when neither works."""
    path = Path(run_dir) / "summary.json"
    text = json.dumps(summary, indent=2) + "\n"
    try:
        atomic_write(path, text + " " * max(0, SUMMARY_RESERVE - len(text)) if reserve else text)
        return
    except OutputError:
        if not path.exists():
            raise
    if len(text) > SUMMARY_RESERVE and summary.get("error", {}).get("traceback"):
        cut = {**summary, "error": {**summary["error"], "traceback": "(cut: no space left to write it)"}}
        text = json.dumps(cut, indent=2) + "\n"
    overwrite_in_place(path, text)


class _Appender:
    """One CSV file appended in whole rows; a failed write cuts it back to the last whole row."""

    def __init__(self, path: Path, header: str):
        self.path = path
        try:
            self._f = open(path, "w", encoding="utf-8", newline="")
            self._f.write(header)
            self._f.flush()
        except OSError as exc:
            raise write_error(exc, path) from None
        self._good = self._f.tell()

    def append(self, text: str) -> None:
        if not text:
            return
        try:
            self._f.write(text)
            self._f.flush()
            self._good = self._f.tell()
        except OSError as exc:
            self._abandon()
            raise write_error(exc, self.path) from None

    def _abandon(self) -> None:
        f, self._f = self._f, None
        try:
            f.close()  # may retry the buffered rest: it fails again, or writes part of a row
        except OSError:
            pass
        try:
            # then cut back to the last whole row (after the close, so nothing it wrote survives; cutting frees
            # space, so it works on a full disk)
            os.truncate(self.path, self._good)
        except OSError:
            pass

    def close(self) -> None:
        if self._f is not None:
            try:
                self._f.close()
            except OSError as exc:
                self._abandon()
                raise write_error(exc, self.path) from None
            self._f = None


class RunFiles:
    """timeseries.csv and timing.csv appended as ``recorder`` records frames.

    ``lag``: how many of the newest recorded frames may still change (1 with a deferred member: its rows of
    frame k arrive with frame k + 1), held back until :meth:`finish`.
    """

    def __init__(self, run_dir: Path, recorder: Recorder, *, lag: int = 0, block_s: float | None = None):
        self.recorder, self.lag = recorder, lag
        self.block_s = BLOCK_S if block_s is None else block_s
        self._carry: dict = {}
        self._written = 0
        self._t_last = time.monotonic()
        self.failed: OutputError | None = None
        self._files = [_Appender(Path(run_dir) / "timeseries.csv", Recorder.csv_header(recorder.series_columns))]
        timing = Path(run_dir) / "timing.csv"
        if len(recorder.timing_columns) > 1:
            self._files.append(_Appender(timing, Recorder.csv_header(recorder.timing_columns)))
        else:
            try:
                timing.unlink(missing_ok=True)  # an earlier run's, in a reused --out: not this run's timings
            except OSError:
                pass

    @property
    def written(self) -> int:
        """Recorded frames whose rows are in the files."""
        return self._written

    def maybe_append(self) -> None:
        """Append the settled rows if ``block_s`` has passed since the last block (call once per frame)."""
        if self.failed is None and time.monotonic() - self._t_last >= self.block_s:
            self.append(len(self.recorder.frames) - self.lag)

    def append(self, upto: int) -> None:
        """Append the rows of recorded frames [written, upto). Raises :class:`OutputError` (once)."""
        self._t_last = time.monotonic()
        if self.failed is not None or upto <= self._written:
            return
        texts = self.recorder.csv_rows(self._written, upto, self._carry)
        try:
            for f, text in zip(self._files, texts):
                f.append(text)
        except OutputError as exc:
            self.failed = exc
            raise
        self._written = upto

    def finish(self) -> None:
        """Append every remaining row and close the files. Raises :class:`OutputError` on a write error."""
        try:
            self.append(len(self.recorder.frames))
        finally:
            for f in self._files:
                f.close()
