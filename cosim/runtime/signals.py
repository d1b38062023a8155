"""SIGINT/SIGTERM in the launcher: counted, never raised mid-step, so any number at any moment ends a run cleanly.

:class:`StopSignals` is installed first thing in ``launch()`` and restored last. Its handler only records the
signal (idempotent: the second, third... Ctrl-C change nothing), and the launcher checks it between steps of its
set-up, between wait slices of the ring, and before its optional last steps (figures). While figures are drawn
(:meth:`StopSignals.raising`) a first signal raises :class:`cosim.errors.RunInterrupted` to cut them short; later
ones are only counted. :func:`no_sigint_in_children` makes the processes spawned inside it start with SIGINT
ignored (an ignored disposition survives exec), so a Ctrl-C on the terminal during their interpreter start-up
prints no KeyboardInterrupt traceback from them: the launcher alone stops the run.

Outside the main thread (a Dask worker thread) signals cannot be handled; both are then no-ops.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator

from cosim.errors import RunInterrupted

__all__ = ["StopSignals", "no_sigint_in_children", "STOP_SIGNALS"]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


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

    def restore(self) -> None:
        """Put the previous handlers back (idempotent)."""
        old, self._old = self._old, {}
        for s, h in old.items():
            signal.signal(s, h)

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
