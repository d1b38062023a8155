"""The dashboard server stops without cutting a response short (SIGTERM at the end of a run, Ctrl-C)."""
from __future__ import annotations

import http.client
import json
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

from cosim.viewer.server import DRAIN_S
from cosim.viewer.snapshot import History, Snapshot

#: how long the stand-in source takes to produce a snapshot, s: SIGTERM arrives while a request is answered
SNAPSHOT_S = 0.15
#: fields of the stand-in's struct: a state document of some tens of kB, sent after its headers
FIELDS = 2000
STARTUP_S = 60.0


class SlowSource:
    """A viewer source whose snapshots take SNAPSHOT_S; touches ``marker`` when a request is being answered."""

    name, frames_planned = "slow", 10

    def __init__(self, marker: str):
        self.marker = Path(marker)
        self.history = History()

    def snapshot(self, big: bool = False) -> Snapshot:
        self.marker.touch()
        time.sleep(SNAPSHOT_S)
        structs = {"dyn_state": {"t_s": 0.5, **{f"x{k}_m": k * 0.25 for k in range(FIELDS)}}}
        return Snapshot(frame=5, structs=structs, frames={"dyn_state": 5}, stamps={"dyn_state": 5}, status="running")

    def check_end(self) -> bool:
        return False

    def close(self) -> None:
        pass


def serve_slow(announce: str, marker: str) -> None:
    """Entry of the server subprocess."""
    from cosim.viewer.server import serve

    serve(SlowSource(marker), port=0, announce=announce)


def _start(tmp_path: Path) -> tuple[subprocess.Popen, str, Path]:
    announce, marker = tmp_path / "viewer.json", tmp_path / "answering"
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import test_viewer_server as t; "
            f"t.serve_slow({str(announce)!r}, {str(marker)!r})")
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=Path(__file__).parent.parent)
    deadline = time.monotonic() + STARTUP_S
    while not announce.exists():
        assert proc.poll() is None, f"the server exited with {proc.returncode}"
        assert time.monotonic() < deadline, "the server did not start"
        time.sleep(0.02)
    return proc, json.loads(announce.read_text())["url"], marker


def test_sigterm_mid_response_still_sends_the_whole_document(tmp_path):
    """What the launcher does to its observers when a run ends: the request being answered gets its whole JSON
    (before, the process died between headers and body: IncompleteRead), then the server exits."""
    proc, url, marker = _start(tmp_path)
    got: dict = {}

    def client():
        try:
            with urllib.request.urlopen(url + "api/state", timeout=10) as r:
                got["doc"] = json.loads(r.read())
        except (OSError, http.client.HTTPException, ValueError) as exc:
            got["error"] = exc

    try:
        t = threading.Thread(target=client)
        t.start()
        deadline = time.monotonic() + 10
        while not marker.exists() and time.monotonic() < deadline:
            time.sleep(0.005)
        assert marker.exists(), "the request never reached the source"
        proc.send_signal(signal.SIGTERM)
        t.join(15)
        assert "error" not in got, f"the client got a broken response: {got.get('error')!r}"
        assert got["doc"]["frame"] == 5 and len(got["doc"]["frames"]) == 1
        assert proc.wait(5 + DRAIN_S) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_after_stopping_the_port_is_closed(tmp_path):
    proc, url, _ = _start(tmp_path)
    try:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
        try:
            urllib.request.urlopen(url + "healthz", timeout=5)
        except urllib.error.URLError as exc:
            assert isinstance(exc.reason, ConnectionRefusedError)
        else:
            raise AssertionError("the stopped server still answered")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
