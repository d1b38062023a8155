"""The dashboard's HTTP server (``http.server.ThreadingHTTPServer``, 127.0.0.1 by default) and the observer entry.

Routes: ``/`` the page, ``/api/state`` the numbers (JSON), ``/panel/<id>.png`` an image panel (404 when absent),
``/healthz``; for a replay, ``POST /api/replay?action=play|pause|step|seek[&value=N]`` drives it (step: N frames,
default 1; seek: to recorded frame N) and answers its position (404 for a live run, 400 for a bad action). A *source* supplies snapshots: :class:`~cosim.viewer.live.LiveSource` (a running segment) or
:class:`~cosim.viewer.replay.ReplaySource` (a recording); both have ``name``, ``frames_planned``,
``history``, ``snapshot(big=False)``, ``check_end()`` and ``close()``.

:func:`observe` is what ``launch(..., observers=[ObserverSpec("viewer", "cosim.viewer.server:observe", {...})])``
runs in its own process: it lowers its scheduling priority (the run's processes come first on a small machine),
attaches and serves until the launcher terminates it.

Stopping never cuts a response short. A response goes out as headers, then body; a process that simply died
on SIGTERM between the two (the launcher terminates its observers when the run ends) left a client with the
headers of a JSON document and none of its bytes (``http.client.IncompleteRead``). :func:`serve` turns SIGTERM
(and Ctrl-C) into a graceful stop: stop accepting, let the requests being answered finish (at most
DRAIN_S), then unmap and exit. A connection idle between requests is simply closed, which HTTP clients expect.
The signal only asks the serving loop to stop after its current turn: an exception raised from the handler could
land between ``accept()`` and the start of the request's thread, and that connection was closed unanswered
(``RemoteDisconnected`` on a page still watching a run that was about to show its end).

The end of a run (``observe``: the launcher sends SIGTERM once the ring has stopped) is shown, not cut off: the
viewer takes the segment's last frame as its final snapshot (``run ended``) and, if a page was watching, keeps
answering until that page has fetched the final state and image panels (at most LINGER_S), so the dashboard ends
on the run's last frame; the page then keeps it on screen when the viewer is gone.
"""
from __future__ import annotations

import collections
import contextlib
import json
import logging
import math
import os
import signal
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

from cosim.runtime.files import atomic_write

from .address import wait_until_answers
from .fill import bar_labels
from .page import page_html
from .panels import IMAGE_PANELS, PanelRenderer, panel_info
from .snapshot import fullness
from .viewinfo import ViewInfo, default_fill

__all__ = ["DashboardServer", "state_json", "fill_band_of", "observe", "serve", "DEFAULT_PORT",
           "DEFAULT_HOST", "NICE", "DRAIN_S", "LINGER_S", "WATCHED_S", "LINGER_MAX_S", "RUN_ENDED"]

log = logging.getLogger("cosim.viewer")

DEFAULT_PORT = 8765
DEFAULT_HOST = "127.0.0.1"
#: niceness increment of a viewer process: it yields the CPU to the run
NICE = 10
#: how often the server checks whether the run has ended (to unmap promptly), s
HOUSEKEEPING_S = 1.0
#: longest wait, when stopping, for the responses being sent to finish, s (the launcher allows its observers
#: cosim.runtime.teardown.OBSERVER_GRACE_S = 10 s after SIGTERM at the end of a completed run, 0.5 s after a
#: failed one, before it kills them)
DRAIN_S = 0.3
#: time the viewer keeps answering after the run ended, for a watching page to fetch its last frame, s (a page
#: polls the state every cosim.viewer.page.POLL_MS and then fetches the image panels of a new frame). It grows
#: with the gaps between the page's polls as the viewer saw them (a starved page on a busy machine polls late),
#: to at most LINGER_MAX_S; a page that has fetched the end ends it at once
LINGER_S = 1.0
#: a page counts as watching if it asked for the state this recently when the run ended, s (also scaled by the
#: page's own gaps, at most LINGER_MAX_S)
WATCHED_S = 1.0
#: the longest linger and watching window whatever the page's gaps, s (cosim.runtime.teardown.OBSERVER_GRACE_S
#: leaves the viewer this long, and its drain, after a completed run)
LINGER_MAX_S = 8.0
#: the linger and the watching window are this many of the page's longest recent gap between polls
GAPS = 3.0
#: how many of the latest gaps between the page's polls are kept
_RECENT_GAPS = 8
#: the status of a live source whose run has ended (cosim.viewer.live)
RUN_ENDED = "run ended"


def _finite(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    return x


def fill_band_of(source) -> tuple[float, float]:
    """The fullness bars' band of ``source``: its run's (``source.view``), else the scenario defaults'."""
    view = getattr(source, "view", None)
    return view.fill_band if view is not None else default_fill()


def state_json(source, dropped_total: int = 0) -> dict:
    """The ``/api/state`` document for ``source``'s latest snapshot. ``fullness`` holds each section's value,
    label and status (cosim.viewer.fill: one rule for both) and the band at the target."""
    snap = source.snapshot()
    full = fullness(snap.structs)
    return _finite({
        "run": source.name, "status": snap.status, "frame": snap.frame, "frames_planned": source.frames_planned,
        "t_s": snap.t_s, "rtf": snap.rtf, "dropped_total": dropped_total,
        "panels": panel_info(snap),
        "auger": source.history.as_json(),
        "fullness": {"block": full[0], "values": full[1], **bar_labels(full[1], fill_band_of(source))}
        if full else None,
        "frames": snap.frames,
        "replay": source.position() if hasattr(source, "position") else None,
    })


class _Handler(BaseHTTPRequestHandler):
    server: "DashboardServer"
    protocol_version = "HTTP/1.1"

    def log_message(self, fmt, *args) -> None:  # http.server logs every request to stderr otherwise
        log.debug("viewer http: " + fmt, *args)

    def _send(self, code: int, body: bytes, ctype: str) -> None:
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def do_GET(self) -> None:  # noqa: N802 - http.server's naming
        with self.server.answering():
            self._answer()

    def _answer(self) -> None:
        path = urlsplit(self.path).path
        srv = self.server
        if srv.stopping:
            self.close_connection = True  # no next request on this connection: the server is going away
        try:
            if path in ("/", "/index.html"):
                self._send(200, srv.page, "text/html; charset=utf-8")
            elif path == "/api/state":
                body = json.dumps(srv.state()).encode()
                self._send(200, body, "application/json")
            elif path.startswith("/panel/") and path.endswith(".png"):
                pid = path[len("/panel/"):-len(".png")]
                if pid not in IMAGE_PANELS:
                    self._send(404, f"no image panel {pid!r}".encode(), "text/plain")
                    return
                png = srv.renderer.get(srv.source.snapshot(big=True), pid)
                if png is None:
                    self._send(404, f"panel {pid} is absent in this run".encode(), "text/plain")
                else:
                    self._send(200, png, "image/png")
                    srv.panel_sent(pid)
            elif path == "/healthz":
                self._send(200, b"ok", "text/plain")
            else:
                self._send(404, b"not found", "text/plain")
        except (BrokenPipeError, ConnectionResetError):
            pass
        except Exception as exc:  # noqa: BLE001 - one bad request must not stop the viewer
            log.exception("viewer request %s failed", path)
            try:
                self._send(HTTPStatus.INTERNAL_SERVER_ERROR, f"{type(exc).__name__}: {exc}".encode(), "text/plain")
            except OSError:
                pass

    do_HEAD = do_GET

    def do_POST(self) -> None:  # noqa: N802
        with self.server.answering():
            url = urlsplit(self.path)
            if int(self.headers.get("Content-Length") or 0):
                self.rfile.read(int(self.headers["Content-Length"]))
            source = self.server.source
            if url.path != "/api/replay" or not hasattr(source, "control"):
                self._send(404, b"not found (replay control exists in a replay only)", "text/plain")
                return
            q = parse_qs(url.query)
            try:
                raw = q.get("value", [None])[0]
                doc = source.control(q.get("action", [""])[0], None if raw in (None, "") else float(raw))
            except ValueError as exc:
                self._send(400, str(exc).encode(), "text/plain")
                return
            self._send(200, json.dumps(doc).encode(), "application/json")


class DashboardServer(ThreadingHTTPServer):
    """Serves one source's dashboard. ``port=0`` picks a free port (``server_port`` tells which)."""

    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, source, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT):
        # everything server_close touches exists before the socket is bound: socketserver calls server_close
        # itself when bind fails (a busy port), and the caller still owns (and closes) the source then
        self._stop = threading.Event()
        self.renderer = None
        self.source = None
        super().__init__((host, port), _Handler)
        self.source = source
        self.renderer = PanelRenderer(getattr(source, "size_m", None), getattr(source, "view", None))
        self.page = page_html(f"graincosim viewer: {source.name}",
                              replay=hasattr(source, "control")).encode()
        self._dropped = 0
        self._last_frame = -1
        self._lock = threading.Lock()
        #: when a page last asked for the state (monotonic s), and what it has had of the run's end: the final
        #: state, the image panels fetched after it (guarded by _end_seen)
        self._t_state = -math.inf
        self._gaps: collections.deque[float] = collections.deque(maxlen=_RECENT_GAPS)
        self._end_state_sent = False
        self._end_panels: set[str] = set()
        self._end_seen = threading.Condition()
        #: requests being answered (read, computed, sent), guarded by _idle
        self._answering = 0
        self._idle = threading.Condition()
        self.stopping = False
        self._keeper = threading.Thread(target=self._housekeeping, name="viewer-housekeeping", daemon=True)
        self._keeper.start()

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        return f"http://{host}:{port}/"

    def state(self) -> dict:
        doc = state_json(self.source)
        with self._lock:
            if doc["frame"] is not None and doc["frame"] > self._last_frame >= 0:
                self._dropped += doc["frame"] - self._last_frame - 1
            if doc["frame"] is not None:
                self._last_frame = max(self._last_frame, doc["frame"])
            doc["dropped_total"] = self._dropped
        with self._end_seen:
            now = time.monotonic()
            if math.isfinite(self._t_state):
                self._gaps.append(now - self._t_state)
            self._t_state = now
            if doc["status"] == RUN_ENDED:
                self._end_state_sent = True
                self._end_seen.notify_all()
        return doc

    def panel_sent(self, pid: str) -> None:
        """Note an image panel answered (after the run ended: part of what a page fetches of its end)."""
        with self._end_seen:
            if self._end_state_sent:
                self._end_panels.add(pid)
                self._end_seen.notify_all()

    def show_the_end(self, linger_s: float = LINGER_S) -> None:
        """The run has ended: take its last frame as the final snapshot (``run ended``) and, if a page was
        watching, keep answering until it has fetched that state and the image panels it shows (at most
        ``linger_s``). Call after :meth:`serve_forever` has returned."""
        finish = getattr(self.source, "finish", None)
        if finish is None:
            return
        finish()
        with self._end_seen:
            if time.monotonic() - self._t_state > self._scaled(WATCHED_S):
                return  # nobody is watching
            linger_s = self._scaled(linger_s)
        shown = {pid for pid, info in panel_info(self.source.snapshot()).items()
                 if pid in IMAGE_PANELS and info["available"] and info["frame"] is not None}
        server = threading.Thread(target=self.serve_forever, kwargs={"poll_interval": 0.05}, name="viewer-end",
                                  daemon=True)
        server.start()
        with self._end_seen:
            self._end_seen.wait_for(lambda: self._end_state_sent and shown <= self._end_panels, timeout=linger_s)
        self.shutdown()
        server.join()

    def _scaled(self, base_s: float) -> float:
        """``base_s``, or GAPS times the longest of the page's recent gaps between polls if longer, at most
        LINGER_MAX_S (call with ``_end_seen`` held)."""
        return min(LINGER_MAX_S, max(base_s, GAPS * max(self._gaps, default=0.0)))

    @contextlib.contextmanager
    def answering(self):
        """Count a request as being answered while its handler runs (see :meth:`drain`)."""
        with self._idle:
            self._answering += 1
        try:
            yield
        finally:
            with self._idle:
                self._answering -= 1
                self._idle.notify_all()

    def drain(self, timeout_s: float = DRAIN_S) -> bool:
        """Stop accepting and wait until no request is being answered (at most ``timeout_s``). Returns whether
        every response was finished."""
        self.stopping = True
        try:
            self.socket.close()
        except OSError:
            pass
        deadline = time.monotonic() + timeout_s
        with self._idle:
            while self._answering:
                left = deadline - time.monotonic()
                if left <= 0:
                    log.warning("viewer stopping with %d responses unfinished", self._answering)
                    return False
                self._idle.wait(left)
        return True

    def _housekeeping(self) -> None:
        while not self._stop.wait(HOUSEKEEPING_S):
            try:
                self.source.check_end()
            except Exception:  # noqa: BLE001
                log.exception("viewer housekeeping failed")

    def server_close(self) -> None:
        self._stop.set()
        super().server_close()
        if self.renderer is not None:
            self.renderer.close()
        if self.source is not None:
            self.source.close()


def _tell_when_answering(name: str, url: str) -> None:
    if wait_until_answers(url):
        log.info("viewer of %s at %s", name, url)


def serve(source, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, announce: str | None = None,
          show_end: bool = False) -> bool:
    """Serve ``source`` until SIGTERM or Ctrl-C, then stop gracefully (module docstring). ``announce``: a file to
    write ``{"url": ...}`` to once listening; ``show_end``: SIGTERM means the run has ended: show its end to a
    watching page first (:meth:`DashboardServer.show_the_end`). Returns whether a signal (Ctrl-C, SIGTERM) ended
    it (the command line's exit 130), False when it was shut down from within."""
    try:
        srv = DashboardServer(source, host, port)
    except BaseException:
        source.close()  # unmapped here: a source left to the garbage collector raised BufferError at exit
        raise
    # the address is told once it answers, not when the socket is bound (the page took ~1.5 s more then)
    threading.Thread(target=_tell_when_answering, args=(source.name, srv.url), name="viewer-address",
                     daemon=True).start()
    received: list[int] = []

    def on_signal(signum, frame) -> None:
        # the serving loop ends after its current turn (shutdown waits for that, so not from this thread): an
        # exception raised here could drop a connection accepted but not yet handed to its thread
        if not received:
            received.append(signum)
            threading.Thread(target=srv.shutdown, name="viewer-stop", daemon=True).start()

    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGTERM, signal.SIGINT)}
    if announce:
        atomic_write(Path(announce), json.dumps({"url": srv.url, "pid": os.getpid()}))
    try:
        try:
            srv.serve_forever(poll_interval=0.5)
        except KeyboardInterrupt:  # Ctrl-C where the handler could not be ours (serving off the main thread)
            received.append(signal.SIGINT)
        if received:
            log.info("viewer of %s stopping (%s)", source.name, signal.Signals(received[0]).name)
            for sig in previous:
                signal.signal(sig, signal.SIG_IGN)  # a second signal must not cut the end or the drain short
            if show_end and received[0] == signal.SIGTERM:
                srv.show_the_end()
    finally:
        srv.drain()
        srv.server_close()
        if not received:  # after a signal they stay ignored: the process is on its way out
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    return bool(received)


def observe(segment_name: str, port: int = DEFAULT_PORT, host: str = DEFAULT_HOST, announce: str | None = None,
            min_interval_s: float | None = None, size_m: tuple[float, float] | None = None,
            view: dict | None = None) -> None:
    """Observer entry (spawned by the launcher): attach to ``segment_name`` read-only and serve the dashboard.
    ``size_m``: the cart interior's (length, width), m, for the height maps' metre axes (``view``'s when None);
    ``view``: :meth:`cosim.viewer.viewinfo.ViewInfo.to_dict` of the run's scenario (the point clouds' cart frame,
    the fullness band)."""
    from .live import MIN_INTERVAL_S, LiveSource

    try:
        os.nice(NICE)
    except OSError:
        pass
    source = LiveSource(segment_name, MIN_INTERVAL_S if min_interval_s is None else min_interval_s)
    if view is not None:
        source.view = ViewInfo.from_dict(view)
        source.size_m = source.view.size_m
    if size_m is not None:
        source.size_m = (float(size_m[0]), float(size_m[1]))
    serve(source, host, port, announce, show_end=True)
