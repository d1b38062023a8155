"""Logging set-up shared by the launcher and its children: one log.txt per run, appended by every process."""
from __future__ import annotations

import logging
import sys

__all__ = ["configure_logging", "LOG_FORMAT", "QuietFileHandler"]

LOG_FORMAT = "%(asctime)s.%(msecs)03d %(processName)-18s %(levelname)-7s %(name)s: %(message)s"


class QuietFileHandler(logging.FileHandler):
    """A FileHandler that stops writing at its first OSError (a full disk) instead of printing a traceback for
    every record (logging's default); the run names the write error itself (cosim.runtime.files)."""

    failed: OSError | None = None

    def emit(self, record: logging.LogRecord) -> None:
        if self.failed is None:
            super().emit(record)

    def handleError(self, record: logging.LogRecord) -> None:
        exc = sys.exc_info()[1]
        if isinstance(exc, OSError):
            self.failed = exc
            return
        super().handleError(record)


def configure_logging(log_path: str | None, *, console: bool, level: int = logging.INFO) -> None:
    """Send every ``cosim``/package logger to ``log_path`` (append) and, if ``console``, to stderr."""
    root = logging.getLogger()
    for h in list(root.handlers):
        root.removeHandler(h)
        h.close()
    fmt = logging.Formatter(LOG_FORMAT, datefmt="%H:%M:%S")
    if log_path:
        fh = QuietFileHandler(log_path, mode="a", encoding="utf-8")
        fh.setFormatter(fmt)
        root.addHandler(fh)
    if console:
        ch = logging.StreamHandler(sys.stderr)
        ch.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
        ch.setLevel(logging.WARNING)
        root.addHandler(ch)
    root.setLevel(level)
