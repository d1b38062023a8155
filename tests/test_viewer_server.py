"""The dashboard server stops without cutting a response short (SIGTERM at the end of a run, Ctrl-C)."""
from __future__ import annotations

import http.client
import json
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import pytest

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


PAGE_HARNESS = r"""
const els = {};
const anything = new Proxy(function () {}, {get: (t, k) => (k === "measureText" ? () => ({width: 10}) : anything),
                                            apply: () => anything});
function el(id) {
  return els[id] ||= {id, textContent: "", className: "", title: "", dataset: {}, style: {}, clientWidth: 400,
                      clientHeight: 200, width: 400, height: 200, classList: {add() {}, toggle() {}},
                      querySelector: (q) => el(id + " " + q), getContext: () => anything};
}
globalThis.document = {getElementById: el};
const timers = [];
globalThis.setTimeout = (fn) => timers.push(fn);
const answers = JSON.parse(process.argv[process.argv.length - 1]);  // a state document, or null: the viewer does not answer
globalThis.fetch = async () => {
  const a = answers.shift();
  if (a === null) throw new TypeError("Failed to fetch");
  return {ok: true, json: async () => a};
};
const flush = () => new Promise((r) => setImmediate(r));
(async () => {
  %(script)s
  const seen = [];
  for (let i = 0; i < 6; i++) {
    await flush(); await flush();
    seen.push([els.status.textContent, els.status.className]);
    const next = timers.shift();
    if (!next) break;
    next();
  }
  await flush(); await flush();
  console.log(JSON.stringify({seen, polling: timers.length > 0}));
})();
"""


def _page_script() -> str:
    from cosim.viewer.page import page_html

    return page_html().split("<script>", 1)[1].split("</script>", 1)[0]


def _state(status: str, frame: int) -> dict:
    return {"run": "r", "status": status, "frame": frame, "frames_planned": 21, "t_s": frame * 0.1, "rtf": 1.0,
            "dropped_total": 0, "panels": {}, "auger": None, "fullness": None, "frames": {}, "replay": None}


@pytest.mark.skipif(shutil.which("node") is None, reason="needs node to run the page's script")
def test_the_page_keeps_run_ended_when_the_viewer_goes_after_the_end():
    def page(answers) -> dict:
        js = PAGE_HARNESS.replace("%(script)s", _page_script())
        r = subprocess.run(["node", "-e", js, json.dumps(answers)], capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout)

    ended = page([_state("running", 19), _state("run ended", 20), None, None])
    assert ended["seen"] == [["running", "running"], ["run ended", "ended"], ["run ended", "ended"]]
    assert not ended["polling"]  # the viewer has gone with the run: nothing more to ask
    cut = page([_state("running", 19), None, _state("running", 20), None])
    assert cut["seen"][:3] == [["running", "running"], ["viewer unreachable", "error"], ["running", "running"]]
    assert cut["polling"]
