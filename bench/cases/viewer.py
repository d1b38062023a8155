"""What observers cost a run: the live viewer, MCAP recording and the Foxglove server, to the real-time factor.

Configurations (``configs``; ``plain`` is always measured, the reference), each sample runs them all, the order
rotated with the round (the first run after start-up, or after a recording's files were deleted, is often the
slowest), after one discarded warm-up run of ``plain``: ``viewer`` (the observer process attached, with a client
polling the dashboard as the page does: state every 250 ms, each changed image panel at most every 500 ms),
``viewer-idle`` (attached, nobody polling), ``record`` (the MCAP sink, images every frame), ``record-img5`` (images
every 5th frame), ``viewer+record``, ``foxglove`` (the live Foxglove server with a WebSocket client subscribed to every
topic) and ``foxglove-idle``. Viewer runs report the viewer's (and its client's) CPU per second of run; recording
runs the supervisor's time in the recording sink per frame (the copy into a frame slot plus any wait for a free
one), the recorder's CPU per frame (its process CPU from the file's ``recorder`` metadata), the file size per frame
and the waits for a free frame slot. Workloads:

* ``payload``: a CPU-bound stand-in ring with the real runs' payload sizes (2 cameras of 640 x 480 depth-encoded and
  RGB images, 32,768 LiDAR rows, 60 x 30 and 30 x 15 height maps, a 60-field dyn_state); each step burns ``work_ms``
  of thread CPU time, so contention shows as lost real time;
* ``dynamics``: the real dynamics participant alone (ground-truth feedback, no renderer).

The real-time factor is taken in steady state by a timing sink: frames completed more than ``settle_s`` after frame
0 (the children's and the viewer's start-up does not count), to the end. ``paired vs plain %`` is each config's
change against the same sample's plain run.
"""
from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from harness import Context, case, rotating
from harness.proctree import process_cpu_s

__all__ = ["ObserverCpu", "Payload", "TimedSink", "Timing", "blocks_dynamics", "blocks_perception", "blocks_renderer",
           "depth_image", "make", "one_run", "payload_specs", "recorder_metadata", "viewer", "workload"]

CAMS, H, W = 2, 480, 640
BEAMS = 32768
CONFIGS = ("plain", "viewer", "viewer-idle", "record", "record-img5", "viewer+record", "foxglove", "foxglove-idle")
#: frame period of both workloads, s
PERIOD_S = 0.1

#: the polling client; a response cut off (the viewer stopped at the run's end) or refused is skipped, not fatal
CLIENT = """
import http.client, json, sys, time, urllib.request
url = sys.argv[1]
shown, fetched = {}, {}
while True:
    try:
        s = json.load(urllib.request.urlopen(url + "api/state", timeout=5))
        for pid, info in s["panels"].items():
            if info["available"] and info["frame"] is not None and pid in ("rgb", "depth", "lidar_top",
                    "lidar_side", "heightmaps") and shown.get(pid) != info["frame"] \\
                    and time.monotonic() - fetched.get(pid, 0) >= 0.5:
                urllib.request.urlopen(f"{url}panel/{pid}.png?frame={info['frame']}", timeout=5).read()
                shown[pid], fetched[pid] = info["frame"], time.monotonic()
    except (OSError, http.client.HTTPException, ValueError):
        pass
    time.sleep(0.25)
"""

#: the Foxglove client: subscribes to every advertised channel and reads every message (like the app's 3D panel)
FOX_CLIENT = """
import asyncio, json, sys, websockets
async def main(url):
    async with websockets.connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        subscribed = set()
        while True:
            m = await ws.recv()
            if isinstance(m, str):
                m = json.loads(m)
                if m["op"] == "advertise":
                    new = [c["id"] for c in m["channels"] if c["id"] not in subscribed]
                    subscribed.update(new)
                    await ws.send(json.dumps({"op": "subscribe",
                                              "subscriptions": [{"id": i, "channelId": i} for i in new]}))
try:
    asyncio.run(main(sys.argv[1]))
except Exception:
    pass
"""


def depth_image():
    """(H, W, 4) uint8 depth-encoded image (the renderer's codec) of undulating ground seen from 3 m, pitched 20 deg
    down, 60 deg field of view: rows near the horizon are out of the codec's range (A = 0), like a real frame."""
    import numpy as np

    from cosim.scenario.config.sensing import Codec
    from renderer_proc.codec import encode_depth

    f_px = (W / 2) / np.tan(np.radians(30.0))
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    ray = np.stack([(xx - W / 2) / f_px, (yy - H / 2) / f_px, np.ones_like(xx)], axis=-1)
    pitch = np.radians(20.0)
    down = ray[..., 1] * np.cos(pitch) + ray[..., 2] * np.sin(pitch)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth_m = np.where(down > 1e-6, 3.0 / down, np.inf)
    depth_m *= 1.0 + 0.05 * np.sin(xx / 23.0) * np.cos(yy / 17.0)
    return encode_depth(depth_m, Codec())


def blocks_dynamics(scenario):
    from shm_schema import ArrayBlock, Field, StructBlock

    fields = [Field("t_s", "s")] + [Field(f"f{k}_m", "m") for k in range(40)]
    fields += [Field("desired_auger_x_m", "m"), Field("actual_auger_x_m", "m")]
    fields += [Field(f"section{k}_fullness") for k in range(1, 10)]
    return [StructBlock("dyn_state", "dynamics", tuple(fields)), ArrayBlock("heightmap_truth", "dynamics", "f4", (60, 30))]


def blocks_renderer(scenario):
    from shm_schema import image_block

    return [image_block(f"cam{c}_{kind}", "renderer", H, W) for c in range(CAMS) for kind in ("depth", "rgb")]


def blocks_perception(scenario):
    from shm_schema import ArrayBlock

    return [ArrayBlock("lidar_points", "perception", "f4", (BEAMS, 4)),
            ArrayBlock("heightmap_perceived", "perception", "f4", (30, 15))]


class Payload:
    """A ring member that burns ``work_ms`` of CPU per step and writes payloads of the real sizes."""

    def __init__(self, scenario, role, work_ms=10.0):
        import numpy as np

        self.name, self.scenario, self.work_s = role, scenario, work_ms / 1e3
        rng = np.random.default_rng(0)
        yy, xx = np.mgrid[0:H, 0:W]
        self.image = np.stack([(xx // 3) % 256, (yy // 2) % 256, (xx * 7 + yy * 3) % 256, np.full_like(xx, 255)],
                              axis=-1).astype(np.uint8)
        self.depth = depth_image()
        self.points = rng.normal(0, 5, (BEAMS, 4)).astype(np.float32)
        self.points[::10] = np.nan
        self.buf = rng.normal(size=20000)
        self.seg = None

    def start(self, segment):
        self.seg = segment

    def step(self, frame):
        import numpy as np

        t0 = time.thread_time()
        while time.thread_time() - t0 < self.work_s:
            np.sin(self.buf, out=self.buf)
        seg, t = self.seg, frame * self.scenario.timing.sensor_period_s
        if self.name == "dynamics":
            with seg.write("dyn_state", frame) as v:
                v.t_s = t
                v.desired_auger_x_m, v.actual_auger_x_m = 1.0 + 0.01 * frame, 0.99 + 0.01 * frame
                for k in range(1, 10):
                    setattr(v, f"section{k}_fullness", min(1.0, 0.005 * frame * k))
            with seg.write("heightmap_truth", frame) as h:
                h[...] = 0.01 * frame
        elif self.name == "renderer":
            for c in range(CAMS):
                for kind in ("depth", "rgb"):
                    with seg.write(f"cam{c}_{kind}", frame) as img:
                        np.copyto(img, self.depth if kind == "depth" else self.image)
                        band = slice((frame * 7) % H, (frame * 7) % H + 40)      # something moves every frame
                        img[band, :, :3] = 255 - img[band, :, :3]
        else:
            with seg.write("lidar_points", frame) as p:
                np.copyto(p, self.points)
            with seg.write("heightmap_perceived", frame) as h:
                h[...] = 0.01 * frame

    def close(self):
        self.seg = None


def make(scenario, role="dynamics", **kw):
    return Payload(scenario, role, **kw)


def payload_specs(work_ms: float) -> dict:
    from cosim.runtime.specs import ParticipantSpec

    return {r: ParticipantSpec(r, "cases.viewer:make", f"cases.viewer:blocks_{r}", kwargs={"role": r, "work_ms": work_ms})
            for r in ("dynamics", "renderer", "perception")}


class Timing:
    """Sink factory recording each completed frame's wall time."""

    def __init__(self, settle_s: float):
        self.stamps: list[float] = []
        self.settle_s = settle_s

    def __call__(self, scenario, run_dir, segment):
        self.stamps.clear()

        def sink(seg, frame):
            self.stamps.append(time.perf_counter())
        return sink

    def rtf(self, period_s: float) -> float:
        s = [t for t in self.stamps if t - self.stamps[0] > self.settle_s]
        if len(s) < 20:
            raise RuntimeError(f"only {len(s)} frames after the {self.settle_s} s settling time: run more frames")
        return (len(s) - 1) * period_s / (s[-1] - s[0])


class TimedSink:
    """Sink factory wrapper recording how long each call of the wrapped sink takes (supervisor time, s)."""

    def __init__(self, factory):
        self.factory, self.calls, self.inner = factory, [], None

    def __call__(self, scenario, run_dir, segment):
        inner = self.inner = self.factory(scenario, run_dir, segment)
        calls = self.calls

        class Sink:
            def __call__(self, seg, frame):
                t0 = time.perf_counter()
                inner(seg, frame)
                calls.append(time.perf_counter() - t0)

            def close(self):
                inner.close()
        return Sink()


class ObserverCpu:
    """Sink: starts the client once the observer has announced itself; at the run's end (sinks close before the
    launcher stops its observers) takes the observer's and the client's CPU time since then, ms per s."""

    def __init__(self, announce: Path, script: str | None):
        self.announce, self.script = announce, script
        self.t0 = self.cpu0 = self.client = None
        self.ms_per_s: float | None = None

    def sink(self, seg, frame):
        if self.t0 is None and self.announce.exists():
            info = json.loads(self.announce.read_text())
            self.pid, self.t0 = info["pid"], time.perf_counter()
            self.cpu0 = process_cpu_s(self.pid) or 0.0
            if self.script is not None:
                self.client = subprocess.Popen([sys.executable, "-c", self.script, info["url"]])
                self.cpu0 += process_cpu_s(self.client.pid) or 0.0

    def close(self):
        if self.t0 is None:
            return
        cpu = (process_cpu_s(self.pid) or 0.0) + ((process_cpu_s(self.client.pid) or 0.0) if self.client else 0.0)
        self.ms_per_s = 1e3 * (cpu - self.cpu0) / (time.perf_counter() - self.t0)

    def stop_client(self):
        if self.client is not None:
            self.client.terminate()
            self.client.wait(5)


def recorder_metadata(path: Path) -> dict:
    """The ``recorder`` metadata record of a finished recording ({} if it has none)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        for m in make_reader(f).iter_metadata():
            if m.name == "recorder":
                return dict(m.metadata)
    return {}


def one_run(scenario, specs, config: str, tmp: Path, settle_s: float) -> dict:
    """One run of ``config``: its real-time factor and the observer's figures."""
    from cosim.recording import RecordOptions, mcap_sink
    from cosim.runtime.launcher import ObserverSpec, launch

    timing = Timing(settle_s)
    record = TimedSink(mcap_sink(RecordOptions(image_every=5 if config.endswith("img5") else 1)))
    sinks = [timing] + ([record] if "record" in config else [])
    observers, watcher = [], None
    announce = tmp / "viewer.json"
    announce.unlink(missing_ok=True)
    if "viewer" in config or "foxglove" in config:
        observers = [ObserverSpec("viewer", "cosim.viewer.server:observe", {"port": 0, "announce": str(announce)})
                     if "viewer" in config else
                     ObserverSpec("foxglove", "cosim.foxglove.live:observe",
                                  {"port": 0, "announce": str(announce), "scenario_json": scenario.model_dump_json()})]
        script = None if config.endswith("idle") else (CLIENT if "viewer" in config else FOX_CLIENT)
        watcher = ObserverCpu(announce, script)

        class WatcherSink:
            def __call__(self, seg, frame):
                watcher.sink(seg, frame)

            def close(self):
                watcher.close()
        sinks.append(lambda sc, run_dir, seg: WatcherSink())
    out = tmp / f"run-{config}"
    try:
        res = launch(scenario, out, specs=specs, console_log=False, observers=observers, sinks=sinks)
    finally:
        if watcher is not None:
            watcher.stop_client()
    if not res.completed:
        raise RuntimeError(f"{config} run failed: {res.error}")
    if watcher is not None and watcher.script is not None and watcher.client is None:
        raise RuntimeError(f"the {config} observer never announced itself; no client polled it")
    row = {"real-time factor": timing.rtf(scenario.timing.sensor_period_s)}
    if watcher is not None:
        row["observer (+ client) CPU ms/s"] = watcher.ms_per_s
    if record.calls:
        problem = getattr(record.inner, "_problem", None)
        if problem:                                       # e.g. a recorder given up on by the sink's timeouts
            raise RuntimeError(f"{config}: the recording is not whole: {problem[0]} (from frame {problem[1]})")
        row["sink ms/frame"] = 1e3 * statistics.mean(record.calls)
        meta = recorder_metadata(out / "recording.mcap")
        if meta:
            row["recorder CPU ms/frame"] = 1e3 * float(meta["process_cpu_s"]) / int(meta["frames"])
        row["recording KiB/frame"] = (out / "recording.mcap").stat().st_size / 1024 / (len(timing.stamps) or 1)
        row["slot waits per 1000 frames"] = 1e3 * getattr(record.inner, "waits", 0) / len(record.calls)
    return row


def workload(scenario, specs, configs: tuple[str, ...], round_index: int, settle_s: float, warmup: bool) -> dict:
    """Every config once, rotated by the round, after a discarded plain run; paired change against plain."""
    rows = {}
    with tempfile.TemporaryDirectory(prefix="bench-viewer-") as tmp:
        if warmup:
            one_run(scenario, specs, "plain", Path(tmp), settle_s)
        for c in rotating(configs, round_index):
            rows[c] = one_run(scenario, specs, c, Path(tmp), settle_s)
    base = rows["plain"]["real-time factor"]
    for c in configs:
        rows[c]["paired vs plain %"] = None if c == "plain" else 100 * (rows[c]["real-time factor"] / base - 1)
    return {c: rows[c] for c in configs}


@case("viewer", "what the live viewer, MCAP recording and the Foxglove server cost a run's real-time factor",
      options={"configs": ",".join(CONFIGS), "workloads": "payload,dynamics", "frames": 250,
               "dynamics_frames": 12000, "work_ms": 10.0, "settle_s": 4.0, "warmup": True},
      quick={"configs": "plain,record", "workloads": "payload", "frames": 120, "work_ms": 2.0, "settle_s": 0.5,
             "warmup": False}, rounds=3, compare=("real-time factor",))
def viewer(ctx: Context) -> dict:
    """Each workload of ``workloads`` with every config of ``configs`` (module docstring)."""
    from cosim.scenario.config import Scenario

    configs = ("plain",) + tuple(c for c in ctx["configs"].split(",") if c and c != "plain")
    unknown = set(configs) - set(CONFIGS)
    if unknown:
        raise ValueError(f"unknown configs {sorted(unknown)}; choose from {', '.join(CONFIGS)}")
    out = {}
    for w in ctx["workloads"].split(","):
        if w == "payload":
            sc = Scenario(format_version=1, duration_s=ctx["frames"] * PERIOD_S, renderer="mock", viewer=True)
            specs = payload_specs(ctx["work_ms"])
            title = f"payload stand-ins, {ctx['frames']} frames, {ctx['work_ms']:g} ms CPU per step"
        elif w == "dynamics":
            sc = Scenario(format_version=1, duration_s=ctx["dynamics_frames"] * PERIOD_S, feedback="ground_truth",
                          renderer="none")
            specs, title = None, f"the dynamics participant, {ctx['dynamics_frames']} frames"
        else:
            raise ValueError(f"unknown workload {w!r}: payload or dynamics")
        out[title] = workload(sc, specs, configs, ctx.round, ctx["settle_s"], ctx["warmup"])
    return out
