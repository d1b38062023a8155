"""The live viewer as an observer: attach mid-run without changing the run, attach/detach cycles, run end, errors."""
from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import test_viewer_standins as standins

from cosim.runtime.launcher import ObserverSpec, launch
from cosim.viewer import LiveSource, RunEnded, RunNotFound, resolve_run
from cosim.viewer.live import SHM_DIR
from cosim.viewer.viewinfo import ViewInfo

DURATION_S = 6.0
#: per-step compute time of each stand-in: the run lasts long enough (~2 s) to attach to it mid-way
PACE_S = 0.01
STARTUP_S = 60.0


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """timeseries.csv of the same run without any viewer."""
    out = tmp_path_factory.mktemp("base") / "run"
    res = launch(standins.scenario(DURATION_S), out, specs=standins.specs(), console_log=False)
    assert res.completed
    return (out / "timeseries.csv").read_bytes()


def get(url: str, timeout: float = 10.0) -> tuple[int, str, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:
            return r.status, r.headers.get("Content-Type", ""), r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.headers.get("Content-Type", ""), e.read()


def start_viewer(run: Path, announce: Path) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "cosim.viewer", "--attach", str(run), "--port", "0",
                             "--announce", str(announce)], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + STARTUP_S
    while not announce.exists():
        if proc.poll() is not None:
            raise AssertionError(f"viewer exited {proc.returncode}: {proc.stderr.read()}")
        if time.monotonic() > deadline:
            proc.kill()
            raise AssertionError("viewer did not start")
        time.sleep(0.05)
    return proc, json.loads(announce.read_text())["url"]


class ViewerAt:
    """Sink factory: at frame ``at`` start the viewer CLI on this run and hold the frame until it serves, then
    poll it from a client thread for the rest of the run (the run's content never depends on wall time)."""

    def __init__(self, at: int, tmp: Path):
        self.at, self.tmp = at, tmp
        self.proc = None
        self.url = ""
        self.seen: list[dict] = []
        self.pngs: list[tuple[str, int, str]] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._client, daemon=True)

    def __call__(self, scenario, run_dir, segment):
        def sink(seg, frame):
            if frame == self.at:
                self.proc, self.url = start_viewer(run_dir, self.tmp / "viewer.json")
                self.thread.start()
        return sink

    def _client(self):
        while not self.stop.is_set():
            code, _, body = get(self.url + "api/state")
            state = json.loads(body)
            self.seen.append(state)
            for pid in ("rgb", "lidar_top", "heightmaps"):
                c, ctype, _ = get(f"{self.url}panel/{pid}.png?frame={state['frame']}")
                self.pngs.append((pid, c, ctype))
            self.stop.wait(0.05)


def test_attach_mid_run_leaves_the_timeseries_byte_identical(tmp_path, shm_clean, baseline):
    sc = standins.scenario(DURATION_S)
    viewer = ViewerAt(5, tmp_path)
    try:
        res = launch(sc, tmp_path / "run", specs=standins.specs(pace_s=PACE_S), console_log=False, sinks=[viewer])
        viewer.stop.set()
        viewer.thread.join(10)
        assert res.completed
        assert (tmp_path / "run" / "timeseries.csv").read_bytes() == baseline
        live = [s["frame"] for s in viewer.seen if s["status"] in ("running", "finished")]
        assert live and min(live) >= 5 and any(5 < f < sc.frames for f in live), live
        assert live == sorted(live), "frames go forward"
        ok = [p for p in viewer.pngs if p[1] == 200]
        assert ok and all(ctype == "image/png" for _, _, ctype in ok)
        state = viewer.seen[-1]
        assert state["panels"]["rgb"]["available"] and state["panels"]["fullness"]["available"]
        assert len(state["fullness"]["values"]) == standins.SECTIONS
        # the run is over: the viewer says so, keeps the last frame, and is still alive
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            state = json.loads(get(viewer.url + "api/state")[2])
            if state["status"] == "run ended":
                break
            time.sleep(0.1)
        assert state["status"] == "run ended" and state["frame"] == sc.frames
        assert get(viewer.url + "panel/heightmaps.png")[0] == 200
        assert viewer.proc.poll() is None
    finally:
        if viewer.proc is not None:
            viewer.proc.terminate()
            viewer.proc.wait(10)


def test_fifty_attach_detach_cycles_during_a_run(tmp_path, shm_clean, baseline):
    sc = standins.scenario(DURATION_S)
    out = tmp_path / "run"
    cycles: list[tuple[int, bool]] = []
    views: list = []
    errors: list[BaseException] = []

    def cycle():
        try:
            for _ in range(50):
                src = LiveSource(out, min_interval_s=0.0)
                snap = src.snapshot()
                src.close()
                cycles.append((snap.frames.get("dyn_state", -1), (SHM_DIR / src.segment_name).exists()))
                views.append(src.view)
        except BaseException as exc:  # noqa: BLE001 - reported by the test thread
            errors.append(exc)

    worker = threading.Thread(target=cycle)

    def factory(scenario, run_dir, segment):
        def sink(seg, frame):
            if frame == 2:
                worker.start()
            if frame == sc.frames - 1:  # a busy machine slows the cycles: the run's content never depends on it
                worker.join()
        return sink

    res = launch(sc, out, specs=standins.specs(pace_s=PACE_S), console_log=False, sinks=[factory])
    assert not errors, errors
    assert res.completed and res.exit_code == 0
    assert (out / "timeseries.csv").read_bytes() == baseline
    assert views and all(v == ViewInfo.of(sc) for v in views), "the run directory's scenario.yaml gives the view"
    assert len(cycles) == 50
    assert all(alive for _, alive in cycles), "a detach must never delete the segment"
    frames = [f for f, _ in cycles]
    assert frames == sorted(frames) and frames[0] >= 1 and frames[-1] < sc.frames, frames


def test_a_source_sees_the_run_end_and_keeps_the_last_frame(tmp_path, shm_clean):
    sc = standins.scenario(1.0)
    sources: list[LiveSource] = []
    states = []

    def factory(scenario, run_dir, segment):
        def sink(seg, frame):
            if frame == 0:
                sources.append(LiveSource(run_dir, min_interval_s=0.0))
            states.append(sources[0].snapshot())
        return sink

    res = launch(sc, tmp_path / "run", specs=standins.specs(), console_log=False, sinks=[factory])
    assert res.completed
    src = sources[0]
    state = states[-1]
    assert state.stamps["cam0_rgb"] == sc.frames and not state.images, "a state snapshot copies no image"
    assert "lidar_points" not in state.arrays and state.structs["dyn_state"]["frame"] == sc.frames
    assert src.check_end() is True
    snap = src.snapshot()
    assert snap.status == "run ended" and snap.frame == sc.frames
    assert snap.arrays["heightmap_truth"].max() == pytest.approx(standins.truth(sc.frames).max())
    src.close()
    with pytest.raises(RunEnded, match="has ended"):
        LiveSource(tmp_path / "run")
    with pytest.raises(RunNotFound, match="no running co-simulation with segment"):
        LiveSource(res.segment_name)


def test_missing_runs_are_named(tmp_path):
    with pytest.raises(RunNotFound, match="has no run.json"):
        resolve_run(tmp_path)
    with pytest.raises(RunNotFound, match="no running co-simulation with segment 'cosim-none-000000'"):
        LiveSource("cosim-none-000000")
    with pytest.raises(RunNotFound, match="no such run directory"):
        resolve_run(tmp_path / "nope" / "deeper")
    assert resolve_run("/dev/shm/cosim-1-abc") == ("cosim-1-abc", None)
    (tmp_path / "run.json").write_text("{half written")
    with pytest.raises(RunNotFound, match="does not name a segment"):
        resolve_run(tmp_path)


def test_cli_says_clearly_when_the_run_is_gone(tmp_path):
    (tmp_path / "run.json").write_text(json.dumps({"segment": "cosim-1-dead", "ended": True}))
    r = subprocess.run([sys.executable, "-m", "cosim.viewer", "--attach", str(tmp_path), "--once"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "has ended" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "cosim.viewer", "--attach", "cosim-none-1", "--once"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "not started, or it has ended" in r.stderr and "Traceback" not in r.stderr


def _hold_until_the_viewer_ended(scenario, run_dir, segment):
    """Sink factory: at frame 2 wait (at most STARTUP_S) for the viewer process to end, so that the run sees it end
    however slowly a busy machine starts it."""
    import multiprocessing

    def sink(seg, frame):
        if frame == 2:
            deadline = time.monotonic() + STARTUP_S
            viewers = [p for p in multiprocessing.active_children() if p.name == "cosim-viewer"]
            while viewers and viewers[0].exitcode is None and time.monotonic() < deadline:
                viewers[0].join(0.05)
    return sink


def test_a_failing_viewer_is_a_warning_to_the_run(tmp_path, shm_clean):
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    port = busy.getsockname()[1]
    try:
        res = launch(standins.scenario(4.0), tmp_path / "run", specs=standins.specs(pace_s=0.02), console_log=False,
                     observers=[ObserverSpec("viewer", "cosim.viewer.server:observe", {"port": port})],
                     sinks=[_hold_until_the_viewer_ended])
    finally:
        busy.close()
    assert res.completed and res.exit_code == 0
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "observer viewer ended" in log and "the run goes on without it" in log


def test_run_flags_wire_the_viewer_and_the_recorder(tmp_path):
    from cosim.cli import build_parser, run_extras

    args = build_parser().parse_args(["run", "default", "--viewer", "--viewer-port", "9001", "--record"])
    observers, sinks = run_extras(args)
    assert observers == [ObserverSpec("viewer", "cosim.viewer.server:observe",
                                      {"port": 9001, "host": "127.0.0.1", "announce": None, "view": None})]
    assert len(sinks) == 1 and args.record is True
    args = build_parser().parse_args(["run", "--record", str(tmp_path / "x.mcap"), "--record-image-every", "0"])
    with pytest.raises(ValueError, match="image_every must be >= 1"):
        run_extras(args)
    assert run_extras(build_parser().parse_args(["run"])) == ([], [])


class Page:
    """A client doing what the dashboard page does: wait for the viewer's address, poll ``/api/state``, fetch each
    image panel whose frame changed; it stops at its first failed request once the run has ended."""

    def __init__(self, announce: Path, poll_s: float | None = None):
        self.announce, self.url, self.poll_s = announce, "", poll_s
        self.states: list[dict] = []
        self.panels: dict[str, list[int]] = {}
        self.failures: list[tuple[int, str]] = []  # (states seen before it, what failed)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        from cosim.viewer.page import POLL_MS
        from cosim.viewer.panels import IMAGE_PANELS

        while not self.announce.exists() and not self.stop.is_set():
            time.sleep(0.05)
        self.url = json.loads(self.announce.read_text())["url"]
        while not self.stop.is_set():
            try:
                state = json.loads(get(self.url + "api/state", timeout=5)[2])
                self.states.append(state)
                for pid, info in state["panels"].items():
                    seen = self.panels.setdefault(pid, [])
                    if pid in IMAGE_PANELS and info["available"] and info["frame"] is not None and \
                            (not seen or seen[-1] != info["frame"]):
                        code = get(f"{self.url}panel/{pid}.png?frame={info['frame']}", timeout=5)[0]
                        assert code == 200, (pid, code)
                        seen.append(info["frame"])
            except (OSError, ValueError) as exc:
                self.failures.append((len(self.states), repr(exc)))
                if self.states and self.states[-1]["status"] == "run ended":
                    return
            self.stop.wait(POLL_MS / 1000 if self.poll_s is None else self.poll_s)


@pytest.mark.parametrize("poll_s", [None, 2.5], ids=["page", "late page"])
def test_the_dashboard_ends_on_the_last_frame_with_run_ended(poll_s, tmp_path, shm_clean):
    """run --viewer: the page's last state is the run's last frame, "run ended", with that frame's image panels;
    the viewer never went unreachable before (it used to be killed a few frames before the end). A page that polls
    late (every 2.5 s, as a browser starved on a busy machine: longer than the viewer's 1 s linger) still gets
    the end: the viewer waits on the page's own cadence."""
    page = Page(tmp_path / "viewer.json", poll_s)

    def hold_until_watched(scenario, run_dir, segment):  # the run's content never depends on wall time
        def sink(seg, frame):
            if frame == 3:
                page.thread.start()
                deadline = time.monotonic() + STARTUP_S
                while len(page.states) < 2 and time.monotonic() < deadline:   # the page watches a while
                    time.sleep(0.02)
        return sink

    obs = ObserverSpec("viewer", "cosim.viewer.server:observe", {"port": 0, "announce": str(tmp_path / "viewer.json")})
    sc = standins.scenario(2.0)
    try:
        res = launch(sc, tmp_path / "run", specs=standins.specs(pace_s=PACE_S), console_log=False,
                     observers=[obs], sinks=[hold_until_watched])
        page.thread.join(10)
    finally:
        page.stop.set()
    assert res.completed and page.states
    last = page.states[-1]
    assert last["status"] == "run ended" and last["frame"] == sc.frames, (last["status"], last["frame"])
    for pid in ("rgb", "depth", "heightmaps", "lidar_top"):
        assert page.panels[pid][-1] == last["panels"][pid]["frame"] == sc.frames, pid
    assert all(before == len(page.states) for before, _ in page.failures), page.failures  # only after the end
