"""Cost of the live viewer and of MCAP recording to a run's real-time factor.

Six configurations, interleaved and repeated (``--configs`` picks some): plain, ``viewer`` (the observer
process attached, with a client polling the dashboard like the page does: state every 250 ms, each changed
image panel at most every 500 ms), ``viewer-idle`` (the observer attached, nobody polling it), ``record`` (the
MCAP sink, images every frame), ``record-img5`` (images every 5th frame), ``viewer+record``, ``foxglove`` (the
live Foxglove server, with a WebSocket client subscribed to every topic and reading everything, like the app)
and ``foxglove-idle`` (the server, no client). Viewer runs
report the viewer's (and its client's) CPU time per second of run. Recording runs also report the supervisor's
time in the recording sink per frame (mean, ms: the copy into a frame slot plus any wait for a free slot), the
recorder's CPU time per frame (its process CPU time: encode, compress, write; from the file's ``recorder``
metadata; older recorders lack it) and the file size per frame. Two workloads:

* ``payload``: a CPU-bound stand-in ring with the real runs' payload sizes: 2 cameras of 640 x 480
  depth-encoded (the renderer's codec applied to a view of flat ground) and RGB images, 32768 LiDAR rows,
  60 x 30 and 30 x 15 height maps, a 60-field dyn_state; each step burns ``--work-ms`` of CPU time (thread
  time, so contention shows as lost real time).
* ``dynamics``: the real dynamics participant alone (ground-truth feedback, no renderer), if it runs.

The real-time factor is measured in steady state by a timing sink: frames completed more than ``SETTLE_S``
after frame 0 (so the children's and the viewer's start-up, imports included, does not count), to the end.
Usage: ``python bench/viewer_bench.py [--reps 3] [--frames 250] [--dynamics-frames 12000] [--work-ms 10]
[--skip-dynamics] [--skip-payload] [--configs plain,record]``; prints a Markdown table (with the 1-minute load
average before and after, and for recording runs how often the ring waited for a free frame slot). Figures:
bench/README.md.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from e2e import process_cpu_s  # noqa: E402  (bench/, this script's folder)

from cosim.recording import RecordOptions, mcap_sink  # noqa: E402
from cosim.runtime.launcher import ObserverSpec, launch  # noqa: E402
from cosim.runtime.specs import ParticipantSpec  # noqa: E402
from cosim.scenario.config import Scenario  # noqa: E402
from shm_schema import ArrayBlock, Field, StructBlock, image_block  # noqa: E402

#: wall time after frame 0 left out of the measurement (start-up of the viewer process and its client), s
SETTLE_S = 4.0
CAMS, H, W = 2, 480, 640
BEAMS = 32768
CONFIGS = ("plain", "viewer", "viewer-idle", "record", "record-img5", "viewer+record", "foxglove", "foxglove-idle")


def depth_image() -> np.ndarray:
    """(H, W, 4) uint8 depth-encoded image (the renderer's codec, docs/CONTRACTS.md) of what a camera 3 m above
    undulating ground (+-5 % in depth: a heap), pitched 20 degrees down, sees (60 degree field of view): rows
    near the horizon are out of the codec's range (invalid, A = 0), like a real frame."""
    from cosim.scenario.config.sensing import Codec
    from renderer_proc.codec import encode_depth

    f_px = (W / 2) / np.tan(np.radians(30.0))
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    # ray direction in camera axes (x right, y down, z forward), then pitched down about x
    ray = np.stack([(xx - W / 2) / f_px, (yy - H / 2) / f_px, np.ones_like(xx)], axis=-1)
    pitch = np.radians(20.0)
    down = ray[..., 1] * np.cos(pitch) + ray[..., 2] * np.sin(pitch)  # world-down component per unit forward z
    with np.errstate(divide="ignore", invalid="ignore"):
        depth_m = np.where(down > 1e-6, 3.0 / down, np.inf)  # planar depth (along z) to the ground
    depth_m *= 1.0 + 0.05 * np.sin(xx / 23.0) * np.cos(yy / 17.0)
    return encode_depth(depth_m, Codec())


def blocks_dynamics(scenario):
    fields = [Field("t_s", "s")] + [Field(f"f{k}_m", "m") for k in range(40)]
    fields += [Field("desired_auger_x_m", "m"), Field("actual_auger_x_m", "m")]
    fields += [Field(f"section{k}_fullness") for k in range(1, 10)]
    return [StructBlock("dyn_state", "dynamics", tuple(fields)), ArrayBlock("heightmap_truth", "dynamics", "f4",
                                                                            (60, 30))]


def blocks_renderer(scenario):
    out = []
    for c in range(CAMS):
        out += [image_block(f"cam{c}_depth", "renderer", H, W), image_block(f"cam{c}_rgb", "renderer", H, W)]
    return out


def blocks_perception(scenario):
    return [ArrayBlock("lidar_points", "perception", "f4", (BEAMS, 4)),
            ArrayBlock("heightmap_perceived", "perception", "f4", (30, 15))]


class Payload:
    """A ring member that burns ``work_ms`` of CPU per step and writes payloads of the real sizes."""

    def __init__(self, scenario, role, work_ms=10.0):
        self.name, self.scenario, self.work_s = role, scenario, work_ms / 1e3
        rng = np.random.default_rng(0)
        yy, xx = np.mgrid[0:H, 0:W]
        # RGB: smooth like a rendered scene, not noise
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
                        band = slice((frame * 7) % H, (frame * 7) % H + 40)  # something moves every frame
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
    return {r: ParticipantSpec(r, "viewer_bench:make", f"viewer_bench:blocks_{r}",
                               kwargs={"role": r, "work_ms": work_ms}) for r in ("dynamics", "renderer", "perception")}


class Timing:
    """Sink factory recording each completed frame's wall time."""

    def __init__(self):
        self.stamps: list[float] = []

    def __call__(self, scenario, run_dir, segment):
        self.stamps.clear()

        def sink(seg, frame):
            self.stamps.append(time.perf_counter())
        return sink

    def rtf(self, period_s: float) -> float:
        s = [t for t in self.stamps if t - self.stamps[0] > SETTLE_S]
        if len(s) < 20:
            raise RuntimeError(f"only {len(s)} frames after the {SETTLE_S} s settling time: run more frames")
        return (len(s) - 1) * period_s / (s[-1] - s[0])


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
                    "lidar_side", "heightmaps") and shown.get(pid) != info["frame"] \
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


def recorder_metadata(path: Path) -> dict:
    """The ``recorder`` metadata record of a finished recording ({} if it has none)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        for m in make_reader(f).iter_metadata():
            if m.name == "recorder":
                return dict(m.metadata)
    return {}


def one_run(scenario: Scenario, specs, config: str, tmp: Path) -> float:
    timing = Timing()
    options = RecordOptions(image_every=5 if config.endswith("img5") else 1)
    record = TimedSink(mcap_sink(options))
    sinks = [timing] + ([record] if "record" in config else [])
    observers, client = [], None
    announce = tmp / "viewer.json"
    announce.unlink(missing_ok=True)
    if "viewer" in config or "foxglove" in config:
        observers = [ObserverSpec("viewer", "cosim.viewer.server:observe", {"port": 0, "announce": str(announce)})
                     if "viewer" in config else
                     ObserverSpec("foxglove", "cosim.foxglove.live:observe",
                                  {"port": 0, "announce": str(announce), "scenario_json": scenario.model_dump_json()})]
        script = CLIENT if "viewer" in config else FOX_CLIENT

        class ViewerCpu:
            """Sink: starts the polling client once the viewer is up; at the run's end (sinks close before the
            launcher stops its observers) takes the viewer's and the client's CPU time since then."""

            def __init__(self):
                self.t0 = self.cpu0 = None

            def __call__(self, s, frame):
                nonlocal client
                if self.t0 is None and announce.exists():
                    info = json.loads(announce.read_text())
                    self.pid, self.t0 = info["pid"], time.perf_counter()
                    self.cpu0 = process_cpu_s(self.pid) or 0.0
                    if not config.endswith("idle"):
                        client = subprocess.Popen([sys.executable, "-c", script, info["url"]])
                        self.cpu0 += process_cpu_s(client.pid) or 0.0

            def close(self):
                if self.t0 is None:
                    return
                cpu = process_cpu_s(self.pid) or 0.0
                if client is not None:
                    cpu += process_cpu_s(client.pid) or 0.0
                per_s = 1e3 * (cpu - self.cpu0) / (time.perf_counter() - self.t0)
                one_run.viewer_cpu.setdefault(config, []).append(per_s)
        sinks.append(lambda sc, run_dir, seg: ViewerCpu())
    out = tmp / f"run-{config}"
    try:
        res = launch(scenario, out, specs=specs, console_log=False, observers=observers, sinks=sinks)
    finally:
        if client is not None:
            client.terminate()
            client.wait(5)
    if not res.completed:
        raise RuntimeError(f"{config} run failed: {res.error}")
    if ("viewer" in config or "foxglove" in config) and not config.endswith("idle") and client is None:
        raise RuntimeError(f"the {config} observer never announced itself; no client polled it")
    size = (out / "recording.mcap").stat().st_size if "record" in config else 0
    one_run.sizes[config] = size / (len(timing.stamps) or 1)
    if record.calls:
        one_run.sink_ms.setdefault(config, []).append(1e3 * statistics.mean(record.calls))
        one_run.waits.setdefault(config, []).append(1e3 * getattr(record.inner, "waits", 0) / len(record.calls))
        meta = recorder_metadata(out / "recording.mcap")
        if meta:
            one_run.cpu_ms.setdefault(config, []).append(1e3 * float(meta["process_cpu_s"]) / int(meta["frames"]))
    return timing.rtf(scenario.timing.sensor_period_s)


one_run.sizes = {}
one_run.sink_ms = {}
one_run.cpu_ms = {}
#: per viewer config and run, the viewer's (and its polling client's) CPU time per second of run, ms
one_run.viewer_cpu = {}
#: per recording config and run, the sink's waits for a free frame slot per 1000 frames
one_run.waits = {}


def bench(name: str, scenario: Scenario, specs, reps: int, configs=CONFIGS, warmup: bool = True,
          rotate: int = 0) -> list[str]:
    """Run every config ``reps`` times, interleaved, the order rotated each rep (no config always first: the
    first run after start-up or after a recording's files were deleted is often the slowest), after one
    discarded warm-up run of ``plain``. ``vs plain``: ratio of the medians; ``paired``: median (range) of each
    rep's ratio to its own plain run, which a load that drifts between reps disturbs less."""
    results = {c: [] for c in configs}
    one_run.sink_ms.clear()
    one_run.cpu_ms.clear()
    one_run.waits.clear()
    one_run.viewer_cpu.clear()
    with tempfile.TemporaryDirectory() as tmp:
        if warmup:
            one_run(scenario, specs, "plain", Path(tmp))
        for r in range(reps):
            k = (r + rotate) % len(configs)
            for c in configs[k:] + configs[:k]:
                results[c].append(one_run(scenario, specs, c, Path(tmp)))
    base = statistics.median(results["plain"])
    rows = []
    for c in configs:
        med = statistics.median(results[c])
        spread = f"{min(results[c]):.2f}-{max(results[c]):.2f}"
        paired = [100 * (x / p - 1) for x, p in zip(results[c], results["plain"])]
        ratio = (f"{100 * (med / base - 1):+.1f} % | {statistics.median(paired):+.1f} % "
                 f"({min(paired):+.0f} to {max(paired):+.0f})") if c != "plain" else "- | -"
        if "record" in c:
            cpu = one_run.cpu_ms.get(c)
            rec = (f"{statistics.median(one_run.sink_ms[c]):.3f} | "
                   f"{f'{statistics.median(cpu):.2f}' if cpu else '?'} | {one_run.sizes.get(c, 0) / 1024:.0f} | "
                   f"{statistics.median(one_run.waits[c]):.1f}")
        else:
            rec = "- | - | - | -"
        vcpu = one_run.viewer_cpu.get(c)
        view = f"{statistics.median(vcpu):.1f}" if vcpu else "-"
        rows.append(f"| {name} | {c} | {med:.2f} | {spread} | {ratio} | {view} | {rec} |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--frames", type=int, default=250, help="payload frames")
    ap.add_argument("--dynamics-frames", type=int, default=12000,
                    help="dynamics frames (~1 ms each: enough for a steady window well past SETTLE_S)")
    ap.add_argument("--work-ms", type=float, default=10.0, help="CPU time per payload step, ms")
    ap.add_argument("--skip-dynamics", action="store_true")
    ap.add_argument("--skip-payload", action="store_true")
    ap.add_argument("--rotate", type=int, default=0,
                    help="start the rotation of the config order here (to interleave separate invocations)")
    ap.add_argument("--configs", default=",".join(CONFIGS),
                    help="comma-separated subset of %(default)s (plain is always run: the reference)")
    args = ap.parse_args()
    configs = ("plain",) + tuple(c for c in args.configs.split(",") if c and c != "plain")
    unknown = set(configs) - set(CONFIGS)
    if unknown:
        ap.error(f"unknown configs {sorted(unknown)}; choose from {CONFIGS}")
    period = 0.1
    load0 = os.getloadavg()[0]
    rows = []
    if not args.skip_payload:
        sc = Scenario(format_version=1, duration_s=args.frames * period, renderer="mock", viewer=True)
        rows += bench("payload", sc, payload_specs(args.work_ms), args.reps, configs, rotate=args.rotate)
    if not args.skip_dynamics:
        gt = Scenario(format_version=1, duration_s=args.dynamics_frames * period, feedback="ground_truth",
                      renderer="none")
        try:
            rows += bench("dynamics", gt, None, args.reps, configs, rotate=args.rotate)
        except Exception as exc:  # noqa: BLE001 - the real participant is someone else's work in progress
            rows.append(f"| dynamics | (failed: {type(exc).__name__}: {exc}) | | | | | | | | | |")
    print(f"machine: {os.cpu_count()} cores, load average {load0:.1f} before, {os.getloadavg()[0]:.1f} after; "
          f"{args.reps} runs each, interleaved; {args.frames} payload frames, {args.dynamics_frames} dynamics "
          f"frames; steady state from {SETTLE_S:g} s after frame 0; payload work {args.work_ms:g} ms CPU per step")
    print("| workload | config | real-time factor (median) | range | vs plain | paired vs plain | viewer (+ client) "
          "CPU ms/s | sink ms/frame | recorder CPU ms/frame | recording KiB/frame | slot waits per 1000 frames |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
