"""Where a dashboard listens: a busy port found before anything starts, and its address told only once it answers.

``run --viewer`` checks the port with :func:`check_port` before the run starts (a busy port is a one-line error,
exit 2, nothing started), then a :class:`ViewerAnnouncer` waits in a background thread for the viewer observer
to write its announce file (``{"url": ...}``, written once its socket listens), asks ``/healthz`` until it
answers, and only then prints ``viewer: URL``: the URL printed is the one that answers (port 0 included).
"""
from __future__ import annotations

import json
import socket
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import TextIO

__all__ = ["PortBusy", "check_port", "wait_until_answers", "ViewerAnnouncer", "ANNOUNCE_TIMEOUT_S"]

#: longest wait for the viewer to answer before the announcer gives up (and says so), s
ANNOUNCE_TIMEOUT_S = 60.0
#: pause between two looks at the announce file or /healthz, s
POLL_S = 0.05


class PortBusy(OSError):
    """The port asked for is taken (or the host is not an address of this machine)."""


def check_port(host: str, port: int) -> None:
    """Raise :class:`PortBusy` (a one-line message) when a server could not listen on ``host:port`` now.

    Binds and closes a socket with the options the dashboard uses (SO_REUSEADDR, as http.server does): a port
    in TIME_WAIT is free, a port with a listener is busy. Port 0 (any free port) always passes."""
    if port == 0:
        return
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as exc:
            raise PortBusy(f"viewer cannot listen on {host}:{port}: {exc.strerror or exc}") from None


def wait_until_answers(url: str, timeout_s: float = ANNOUNCE_TIMEOUT_S, stop: threading.Event | None = None) -> bool:
    """Poll ``url`` + ``healthz`` until it answers 200 (True) or ``timeout_s`` passes or ``stop`` is set (False)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not (stop is not None and stop.is_set()):
        try:
            with urllib.request.urlopen(url.rstrip("/") + "/healthz", timeout=1.0) as r:
                if r.status == 200:
                    return True
        except OSError:
            pass
        time.sleep(POLL_S)
    return False


class ViewerAnnouncer:
    """Prints ``viewer: URL (while the run lasts)`` to ``stream`` once the viewer at the URL its announce file
    names answers. ``path`` is the announce file to hand the observer; :meth:`close` stops waiting and removes
    it. ``url`` holds the address once printed. ``timeout_s`` None (the default) waits as long as the run lasts:
    on a busy machine the viewer's start may take minutes, and its address is still worth printing."""

    def __init__(self, stream: TextIO, timeout_s: float | None = None):
        self._dir = tempfile.TemporaryDirectory(prefix="cosim-viewer-")
        self.path = Path(self._dir.name) / "viewer.json"
        self.url: str | None = None
        self._stream, self._timeout = stream, timeout_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._wait, name="viewer-announce", daemon=True)
        self._thread.start()

    def _wait(self) -> None:
        deadline = time.monotonic() + (self._timeout if self._timeout is not None else float("inf"))
        while not self.path.exists():
            if self._stop.wait(POLL_S) or time.monotonic() > deadline:
                return
        url = json.loads(self.path.read_text())["url"]
        if wait_until_answers(url, max(0.0, deadline - time.monotonic()), self._stop) and not self._stop.is_set():
            self.url = url
            self._stream.write(f"viewer: {url} (while the run lasts)\n")
            self._stream.flush()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._dir.cleanup()
