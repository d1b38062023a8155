"""SIGINT/SIGTERM in the launcher: counted, never raised mid-step, so any number at any moment ends a run cleanly.

:class:`StopSignals` is installed first thing in ``launch()`` and restored last. Its handler only records the
signal (idempotent: the second, third... Ctrl-C change nothing), and the launcher checks it between steps of its
set-up, between wait slices of the ring, and before its optional last steps (figures). While figures are drawn
(:meth:`StopSignals.raising`) a first signal raises :class:`cosim.errors.RunInterrupted` to cut them short; later
ones are only counted. :func:`no_sigint_in_children` makes the processes spawned inside it start with SIGINT
ignored (an ignored disposition survives exec), so a Ctrl-C on the terminal during their interpreter start-up
prints no KeyboardInterrupt traceback from them: the launcher alone stops the run.

Outside the main thread (a Dask worker thread) signals cannot be handled; both are then no-ops, and a run there
is stopped by :func:`request_stop` instead (the sweep does so on every worker when it is interrupted): it acts as
a signal would, for the runs it names. :func:`sigint_blocked_in_new_threads` keeps a terminal's Ctrl-C away from
the processes of an embedded Dask cluster, so that the sweep stops them in order.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

from cosim.errors import RunInterrupted

__all__ = ["StopSignals", "no_sigint_in_children", "sigint_blocked_in_new_threads", "request_stop", "STOP_SIGNALS"]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

#: the runs of this process that a stop can be requested for: run directory (absolute) -> its StopSignals
_RUNS: dict[str, "StopSignals"] = {}
_RUNS_LOCK = threading.Lock()
#: notified when a registered run ends
_RUN_ENDED = threading.Condition(_RUNS_LOCK)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


class StopSignals:
    """The launcher's SIGINT/SIGTERM handler: records the first signal, counts the rest."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self.count = 0
        self._raise = False
        self._old: dict = {}

    def install(self) -> "StopSignals":
        if _main_thread():
            self._old = {s: signal.signal(s, self) for s in STOP_SIGNALS}
        return self

    def register(self, run_dir) -> None:
        """Let :func:`request_stop` reach this run by its run directory (until :meth:`restore`)."""
        self._run = str(Path(run_dir).absolute())
        with _RUNS_LOCK:
            _RUNS[self._run] = self

    def restore(self) -> None:
        """Put the previous handlers back and forget the registration (idempotent)."""
        old, self._old = self._old, {}
        for s, h in old.items():
            signal.signal(s, h)
        with _RUNS_LOCK:
            if _RUNS.get(getattr(self, "_run", None)) is self:
                del _RUNS[self._run]
                _RUN_ENDED.notify_all()

    def request(self, signum: int) -> None:
        """Record ``signum`` as if it had come (from another thread: never raises)."""
        self.count += 1
        if self.signum is None:
            self.signum = signum

    def __call__(self, signum, frame) -> None:
        self.count += 1
        first = self.signum is None
        if first:
            self.signum = signum
        if first and self._raise:
            self._raise = False
            raise self._cut()

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name if self.signum is not None else ""

    def error(self, frame: int, process: str = "supervisor") -> RunInterrupted:
        where = f"at frame {frame}" if frame >= 0 else "before frame 0"
        return RunInterrupted(f"stopped by {self.name} {where}", process=process, frame=frame)

    def check(self, frame: int) -> None:
        """Raise :class:`RunInterrupted` if a stop signal has come."""
        if self.signum is not None:
            raise self.error(frame)

    def _cut(self) -> RunInterrupted:
        return RunInterrupted(f"stopped by {self.name}", process="supervisor")

    @contextmanager
    def raising(self) -> Iterator[None]:
        """Inside, the first signal raises RunInterrupted at once (to cut optional work short); entering it after
        a signal came raises at once."""
        if self.signum is not None:
            raise self._cut()
        self._raise = True
        try:
            yield
        finally:
            self._raise = False


@contextmanager
def no_sigint_in_children() -> Iterator[None]:
    """Processes started inside begin with SIGINT ignored; a SIGINT meanwhile reaches the launcher afterwards."""
    if not _main_thread():
        yield
        return
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)


@contextmanager
def sigint_blocked_in_new_threads() -> Iterator[None]:
    """Threads started inside are born with SIGINT blocked, for good, and so is every process they start (a signal
    mask survives fork and exec): a terminal's Ctrl-C then reaches only this process's main thread, which is
    unblocked again on the way out (a SIGINT meanwhile is delivered then). For a Dask LocalCluster, whose event
    loop thread starts the worker processes."""
    if not _main_thread():
        yield
        return
    # multiprocessing's resource tracker is started by the first process spawned, in whichever thread, and that
    # start unblocks SIGINT in its thread: start it here first, so that it never runs in the cluster's threads
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)


def request_stop(run_dirs: Iterable[str], signum: int = signal.SIGINT, wait_s: float = 0.0) -> int:
    """Stop the runs of this process whose run directory is one of ``run_dirs`` as ``signum`` would (they end
    cleanly, interrupted); wait up to ``wait_s`` for them to end. Returns how many were running. A Dask worker
    runs it with ``client.run``."""
    wanted = {str(Path(d).absolute()) for d in run_dirs}
    with _RUNS_LOCK:
        stops = [st for d, st in _RUNS.items() if d in wanted]
    for st in stops:
        st.request(signum)
    with _RUN_ENDED:
        _RUN_ENDED.wait_for(lambda: not wanted & _RUNS.keys(), timeout=wait_s)
    return len(stops)
