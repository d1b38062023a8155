"""The dashboard in headless Chromium during a run: panels update with the run's frame numbers; a screenshot.

Skipped where Debian's ``chromium`` is not installed (.ci/run installs it where apt works). The run is a
launcher subprocess with the viewer as its observer; it is stopped with SIGTERM once the page has been checked.
The page records the frames each panel has shown (``data-seen``); one DOM dump after a few seconds of page time
shows every panel moving forward through the run's frames.
Set ``VIEWER_SCREENSHOT`` to a path to keep the screenshot.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import cv2
import pytest
import test_viewer_standins as standins

from cosim.viewer.fill import STATUSES, section_status
from cosim.viewer.panels import PANELS
from cosim.viewer.viewinfo import default_fill

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium)")

RUN_SCRIPT = textwrap.dedent("""
    import sys
    sys.path[:0] = [{root!r}, {tests!r}]  # this checkout's code, not another installed copy
    import test_viewer_standins as standins
    from cosim.runtime.launcher import ObserverSpec, launch
    from cosim.viewer.viewinfo import ViewInfo
    if __name__ == "__main__":
        sc = standins.scenario(600.0)
        obs = ObserverSpec("viewer", "cosim.viewer.server:observe",
                           {{"port": 0, "announce": {announce!r}, "view": ViewInfo.of(sc).to_dict()}})
        res = launch(sc, {out!r}, specs=standins.specs(pace_s=0.02), console_log=False, observers=[obs])
        sys.exit(res.exit_code)
""")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--virtual-time-budget=4000", "--window-size=1400,1000")


def chromium(url: str, *extra: str) -> str:
    with tempfile.TemporaryDirectory() as profile:
        r = subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *extra, url], capture_output=True,
                           text=True, timeout=90)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


def panels_in(dom: str) -> dict[str, list[int]]:
    """Panel id -> the frames it has shown (``data-seen``, oldest first); 'header' -> [the header's frame]."""
    out = {}
    for m in re.finditer(r'<section[^>]*id="p-([a-z_]+)"[^>]*>', dom):
        seen = re.search(r'data-seen="([\d ]*)"', m.group(0)).group(1)
        out[m.group(1)] = [int(f) for f in seen.split()]
    hdr = re.search(r'id="frame" data-frame="(-?\d*)"', dom)
    out["header"] = [int(hdr.group(1))] if hdr and hdr.group(1) else []
    return out


def fullness_bars(dom: str) -> list[tuple[str, str]]:
    """(label, status) of each fullness bar the page drew (the canvas's ``data-labels`` and ``data-status``)."""
    canvas = re.search(r'<canvas[^>]*id="c-fullness"[^>]*>', dom).group(0)
    labels = re.search(r'data-labels="([^"]*)"', canvas).group(1).split("|")
    status = re.search(r'data-status="([^"]*)"', canvas).group(1).split("|")
    return list(zip(labels, status))


def test_dashboard_updates_with_the_runs_frames(tmp_path):
    out, announce = tmp_path / "run", tmp_path / "viewer.json"
    script = tmp_path / "run_it.py"
    script.write_text(RUN_SCRIPT.format(root=str(Path(__file__).parent.parent), tests=str(Path(__file__).parent),
                                         out=str(out), announce=str(announce)))
    proc = subprocess.Popen([sys.executable, str(script)], cwd=Path(__file__).parent.parent)
    try:
        deadline = time.monotonic() + 60
        while not announce.exists() and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
        assert announce.exists(), "the viewer observer did not start"
        url = json.loads(announce.read_text())["url"]
        dom = chromium(url, "--dump-dom")
        panels = panels_in(dom)
        shot = tmp_path / "dashboard.png"
        chromium(url, f"--screenshot={shot}")
    finally:
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(30)
    assert code == 130
    assert set(PANELS) <= set(panels)
    frames_run = json.loads((out / "summary.json").read_text())["frames"]
    for pid in PANELS:
        seen = panels[pid]
        if pid == "cameras":                 # a LiDAR run: no camera sensor (tests/test_camera_observers.py)
            assert seen == [], seen
            continue
        assert len(seen) >= 2, (pid, seen)  # the panel updated while the page was open
        assert seen == sorted(set(seen)) and 0 <= seen[0] and seen[-1] < frames_run, (pid, seen)
    # each bar coloured as its label says (one rule, cosim.viewer.fill), in the default scenario's band
    bars = fullness_bars(dom)
    assert len(bars) == standins.SECTIONS and {s for _, s in bars} <= set(STATUSES) - {"unknown"}, bars
    band = default_fill()
    assert all(section_status(int(label.split()[0]) / 100, band) == (label, status) for label, status in bars), bars
    # block stamps may run one frame ahead of the supervisor's (the ring is mid-turn)
    assert panels["header"] and panels["header"][0] >= max(panels["rgb"]) - 1
    img = cv2.imread(str(shot))
    assert img is not None and img.shape[:2] == (1000, 1400)
    assert img.std() > 10, "the screenshot is blank"
    if os.environ.get("VIEWER_SCREENSHOT"):
        shutil.copy(shot, os.environ["VIEWER_SCREENSHOT"])
