"""Run progress: one labelled bar per run (tqdm) with frames, simulated time, real-time factor and an ETA.

The launcher calls a ``progress(frame, frames, sim_s, wall_s)`` callable after each frame; :func:`run_progress`
makes one for a named run. On a terminal it is a tqdm bar redrawn in place; elsewhere (a log file, a pipe) it
writes the same line, formatted by tqdm, every PLAIN_INTERVAL_S and once at the end, so logs stay readable.
Commands that run several runs (compare, study, sweep) make one per run, each with the run's name, one after the
other: lines of two runs are never mixed. ``quiet=True`` gives None, which the launcher takes as "no progress".
"""
from __future__ import annotations

import sys
import time
from typing import Callable, TextIO

from tqdm import tqdm

__all__ = ["ProgressPrinter", "run_progress", "Progress", "PLAIN_INTERVAL_S", "BAR_INTERVAL_S"]

#: seconds between plain progress lines when not on a terminal
PLAIN_INTERVAL_S = 5.0
#: seconds between bar redraws on a terminal
BAR_INTERVAL_S = 0.1

#: what the launcher calls after each frame: (frame, frames, simulated time s, wall time since start s)
Progress = Callable[[int, int, float, float], None]


class ProgressPrinter:
    """Callable ``(frame, frames, sim_s, wall_s)`` for :func:`cosim.runtime.launcher.launch`: the progress of
    one run named ``name`` (the bar's label) on ``stream``. ``tty`` forces bar (True) or line (False) mode.
    The bar ends (newline) at the last frame, or at :meth:`close`."""

    def __init__(self, stream: TextIO = sys.stderr, tty: bool | None = None, name: str = "run"):
        self.stream = stream
        self.name = name
        self.tty = _isatty(stream) if tty is None else tty
        self._bar: tqdm | None = None
        self._last = -1e9
        self._done = False

    def __call__(self, frame: int, frames: int, sim_s: float, wall_s: float) -> None:
        if self._done:
            return
        done = frame >= frames
        rtf = sim_s / wall_s if wall_s > 0 else 0.0
        post = f"sim {sim_s:.1f} s, {rtf:.1f}x real time"
        if self.tty:
            if self._bar is None:
                self._bar = tqdm(total=frames, desc=self.name, unit="frame", file=self.stream, leave=True,
                                 mininterval=BAR_INTERVAL_S, dynamic_ncols=True)
            self._bar.n = min(frame, frames)
            self._bar.set_postfix_str(post, refresh=False)
            self._bar.refresh() if done else self._bar.update(0)
            if done:
                self.close()
            return
        now = time.monotonic()
        if not done and now - self._last < PLAIN_INTERVAL_S:
            return
        self._last = now
        line = tqdm.format_meter(min(frame, frames), frames, wall_s, prefix=self.name, unit="frame", postfix=post,
                                 ncols=0)
        self.stream.write(line.strip() + "\n")
        self.stream.flush()
        if done:
            self._done = True

    def close(self) -> None:
        """End the bar (a run that stopped early leaves it where it was)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        self._done = True


def run_progress(name: str, quiet: bool = False, stream: TextIO | None = None) -> ProgressPrinter | None:
    """The progress callable for one run labelled ``name`` (None when ``quiet``): what ``run``, ``compare``,
    ``study`` and ``sweep`` pass to the launcher (or call themselves), one per run."""
    if quiet:
        return None
    return ProgressPrinter(sys.stderr if stream is None else stream, name=name)


def _isatty(stream: TextIO) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False
