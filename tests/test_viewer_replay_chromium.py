"""The dashboard of a replay in headless Chromium, driven through the DevTools protocol as a user would: the
replay bar's pause, step and seek buttons move the shown frame; the panels fill the page's width with no empty
column; the height maps are drawn large; a full-page screenshot is kept (``VIEWER_SCREENSHOT_REPLAY``).

Also the server's replay endpoints without a browser (always run): play / pause / step / seek and their errors.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import tempfile
import threading
import time
import urllib.error
import urllib.request

import cv2
import numpy as np
import pytest
import test_viewer_standins as standins

from cosim.recording import mcap_sink
from cosim.runtime.launcher import launch
from cosim.viewer.replay import ReplaySource
from cosim.viewer.server import DashboardServer

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
SECONDS = 1.0


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("replay") / "run"
    res = launch(standins.scenario(SECONDS), out, specs=standins.specs(), console_log=False, sinks=[mcap_sink()])
    assert res.completed
    return out / "recording.mcap"


@pytest.fixture
def server(recording):
    srv = DashboardServer(ReplaySource(recording, speed=1.0), port=0)
    t = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)
    t.start()
    yield srv
    srv.shutdown()
    srv.server_close()


def post(url: str) -> dict:
    with urllib.request.urlopen(urllib.request.Request(url, method="POST"), timeout=10) as r:
        return json.loads(r.read())


def test_replay_endpoints_pause_step_seek_play(server):
    base = server.url + "api/replay?action="
    frames = server.source.frames
    p = post(base + "pause")
    assert p["playing"] is False and p["first"] == frames[0] and p["last"] == frames[-1]
    at = p["frame"]
    time.sleep(0.3)
    assert post(base + "step&value=0")["frame"] == at, "paused: the frame holds"
    assert post(base + "seek&value=3")["frame"] == 3
    assert post(base + "step")["frame"] == 4 and post(base + "step&value=-2")["frame"] == 2
    assert post(base + "step&value=-100")["frame"] == frames[0]
    assert post(base + "seek&value=100000")["frame"] == frames[-1]
    state = json.loads(urllib.request.urlopen(server.url + "api/state", timeout=10).read())
    assert state["frame"] == frames[-1] and state["replay"]["playing"] is False and state["status"] == "replay ended"
    p = post(base + "play")  # play at the end starts over
    assert p["playing"] is True and p["frame"] < frames[-1]
    with pytest.raises(urllib.error.HTTPError, match="400") as exc:
        post(base + "rewind")
    assert b"unknown replay action 'rewind'" in exc.value.read()
    with pytest.raises(urllib.error.HTTPError, match="400"):
        post(base + "seek")


class Page:
    """One Chromium tab over the DevTools protocol (websockets' sync client)."""

    def __init__(self, url: str, width: int, height: int):
        from websockets.sync.client import connect

        self._profile = tempfile.TemporaryDirectory()
        self.proc = subprocess.Popen(
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-sync",
             "--disable-background-networking", "--disable-component-update", "--disable-dev-shm-usage",
             f"--window-size={width},{height}", "--remote-debugging-port=0",
             f"--user-data-dir={self._profile.name}", url], stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        port = None
        while port is None and time.monotonic() < deadline:
            line = self.proc.stderr.readline()
            m = re.search(r"DevTools listening on ws://127\.0\.0\.1:(\d+)/", line)
            port = m and int(m.group(1))
        assert port, "chromium did not open its DevTools port"
        targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10).read())
        ws = next(t["webSocketDebuggerUrl"] for t in targets if t["type"] == "page")
        self._conn = connect(ws, max_size=None, open_timeout=30)
        self.ws = self._conn.__enter__()
        self._id = 0

    def call(self, method: str, **params) -> dict:
        self._id += 1
        self.ws.send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=60))
            if msg.get("id") == self._id:
                assert "error" not in msg, msg
                return msg["result"]

    def js(self, expr: str):
        r = self.call("Runtime.evaluate", expression=expr, returnByValue=True, awaitPromise=True)
        return r["result"].get("value")

    def wait(self, expr: str, timeout_s: float = 20.0):
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            v = self.js(expr)
            if v:
                return v
            time.sleep(0.1)
        raise AssertionError(f"page never gave {expr}; replay bar: "
                             f"{self.js('document.getElementById(' + chr(39) + 'replay' + chr(39) + ').outerHTML')}")

    def close(self) -> None:
        self._conn.__exit__(None, None, None)
        self.proc.terminate()
        self.proc.wait(30)
        self._profile.cleanup()


SHOWN = "document.getElementById('replay').dataset.frame"


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium)")
def test_replay_dashboard_in_chromium_play_pause_step_seek_and_layout(server, tmp_path):
    pytest.importorskip("websockets", reason="the DevTools client needs websockets (pip install websockets)")
    page = Page(server.url, 1400, 1000)
    try:
        page.wait("document.getElementById('replay').classList.contains('on') && " + SHOWN)
        page.js("document.getElementById('rp-play').click()")  # playing from the start: pause
        page.wait("document.getElementById('rp-play').textContent === 'play'")
        page.js("{ const s = document.getElementById('rp-seek'); s.value = '3'; "
                "s.dispatchEvent(new Event('change')); }")  # the slider
        page.wait(f"{SHOWN} === '3'")
        time.sleep(0.6)
        assert page.js(SHOWN) == "3", "paused: the shown frame holds"
        page.js("document.getElementById('rp-fwd').click()")
        page.wait(f"{SHOWN} === '4'")
        page.js("document.getElementById('rp-back').click()")
        page.js("document.getElementById('rp-back').click()")
        page.wait(f"{SHOWN} === '2'")
        page.js("document.getElementById('rp-play').click()")  # play: the frame moves on (0.1 s a frame)
        page.wait(f"Number({SHOWN}) >= 5")
        page.js("document.getElementById('rp-play').click()")
        page.wait("document.getElementById('rp-play').textContent === 'play'")
        page.js("{ const s = document.getElementById('rp-seek'); s.value = '4'; "
                "s.dispatchEvent(new Event('change')); }")
        page.wait(f"{SHOWN} === '4'")
        page.wait("document.getElementById('p-heightmaps').dataset.frame === '4'")
        # the panels fill the page: every row's panels span the main area's width, nothing is empty
        rects = page.js("""(() => { const m = document.querySelector('main').getBoundingClientRect();
            return {main: [m.left, m.right], panels: [...document.querySelectorAll('section.panel')].map((s) => {
              const r = s.getBoundingClientRect(); return [s.id, r.left, r.top, r.right, r.bottom]; })}; })()""")
        left, right = rects["main"]
        rows = {}
        for _pid, x0, y0, x1, _y1 in rects["panels"]:
            rows.setdefault(round(y0), []).append((x0, x1))
        for y, spans in rows.items():
            covered = sum(x1 - x0 for x0, x1 in spans)
            assert covered > 0.95 * (right - left) - 40, (y, spans, left, right)
        maps = page.js("(() => { const i = document.querySelector('#p-heightmaps img'); "
                       "return [i.clientWidth, i.clientHeight]; })()")
        assert maps[0] > 0.9 * (right - left) and maps[1] > 250, f"height maps drawn {maps} px"
        # a full-page screenshot: the page's whole height
        height = int(page.js("document.documentElement.scrollHeight"))
        page.call("Emulation.setDeviceMetricsOverride", width=1400, height=height, deviceScaleFactor=1, mobile=False)
        time.sleep(0.8)
        shot = page.call("Page.captureScreenshot", format="png", captureBeyondViewport=True)["data"]
    finally:
        page.close()
    import base64

    png = base64.b64decode(shot)
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None and img.shape[1] > 1300 and img.shape[0] >= height - 20 and img.std() > 10
    if os.environ.get("VIEWER_SCREENSHOT_REPLAY"):
        with open(os.environ["VIEWER_SCREENSHOT_REPLAY"], "wb") as f:
            f.write(png)
