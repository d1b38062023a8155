"""Run progress: a one-line bar on a terminal (sim time, frames, real-time factor), log lines otherwise."""
from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["ProgressPrinter"]

#: seconds between plain progress lines when not on a terminal
PLAIN_INTERVAL_S = 5.0
#: seconds between bar redraws on a terminal
BAR_INTERVAL_S = 0.1
BAR_WIDTH = 30


class ProgressPrinter:
    """Callable ``(frame, frames, sim_time_s, wall_s)`` for :func:`cosim.runtime.launcher.launch`."""

    def __init__(self, stream: TextIO = sys.stderr, tty: bool | None = None):
        self.stream = stream
        self.tty = stream.isatty() if tty is None else tty
        self._last = -1e9

    def __call__(self, frame: int, frames: int, sim_s: float, wall_s: float) -> None:
        now = time.monotonic()
        done = frame >= frames
        if not done and now - self._last < (BAR_INTERVAL_S if self.tty else PLAIN_INTERVAL_S):
            return
        self._last = now
        rtf = sim_s / wall_s if wall_s > 0 else 0.0
        if self.tty:
            k = int(BAR_WIDTH * frame / max(frames, 1))
            bar = "#" * k + "-" * (BAR_WIDTH - k)
            self.stream.write(f"\r[{bar}] frame {frame}/{frames}  sim {sim_s:7.1f} s  {rtf:6.1f}x real time")
            if done:
                self.stream.write("\n")
        else:
            self.stream.write(f"frame {frame}/{frames}  sim {sim_s:.1f} s  wall {wall_s:.1f} s  {rtf:.1f}x real time\n")
        self.stream.flush()
