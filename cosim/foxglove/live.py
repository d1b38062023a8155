"""The live Foxglove server: an observer that serves a running co-simulation over the Foxglove WebSocket protocol.

``run --foxglove`` starts :func:`observe` in a process of its own (``cosim.runtime.launcher.ObserverSpec``),
like the dashboard (:mod:`cosim.viewer.live`): it attaches to the run's segment read-only by name, learns the
layout from the segment, copies blocks under their seqlocks (``Segment.snapshot``), never writes, never
unlinks, takes no part in the lockstep and runs at nice 10. Every ``interval_s`` it reads the blocks' frame
stamps and sends what changed through foxglove-sdk's WebSocket server (subprotocol ``foxglove.sdk.v1``) on
127.0.0.1: the topics of the recording (:mod:`cosim.foxglove.publish`: point cloud, camera images, height maps
as grids, transforms, struct blocks as JSON messages) and ``/scene``, a foxglove.SceneUpdate of the render scene
(:mod:`cosim.foxglove.scene`). Frames in between are dropped. A big block (image, cloud, map) is copied only
while a client subscribes to its topic, so an unwatched server costs a few stamp reads per interval. If it fails
the launcher logs a warning and the run goes on; when the run ends (its segment name is gone) it stops.
"""
from __future__ import annotations

import json
import logging
import os
import socket
import sys
import threading
import time
from pathlib import Path

import foxglove
from foxglove.channels import SceneUpdateChannel

from cosim.runtime.files import atomic_write
from shm_schema import Segment, SnapshotTimeout, StructBlock

from .publish import FramePublisher, Recorded, RunInfo
from .scene import scene_update

__all__ = ["observe", "LiveFoxglove", "DEFAULT_PORT", "DEFAULT_HOST", "INTERVAL_S", "NICE", "SCENE_TOPIC"]

log = logging.getLogger("cosim.foxglove")

#: default WebSocket port: the Foxglove app's default (8765) plus one, since the dashboard (--viewer) has 8765
DEFAULT_PORT = 8766
DEFAULT_HOST = "127.0.0.1"
#: time between two looks at the segment, s (5 Hz, the dashboard's rate)
INTERVAL_S = 0.2
#: niceness added to the server process, like the viewer's
NICE = 10
#: seqlock attempts per block before it is skipped for this interval
SNAPSHOT_TRIES = 200
SCENE_TOPIC = "/scene"
#: how long the server's port gets to answer before the address is printed anyway with a warning, s
ANSWER_TIMEOUT_S = 5.0
#: dyn_state fields and blocks the scene is built from (cosim.world.scene.scene_from_state)
SCENE_FIELDS = ("spout_x_m", "spout_y_m", "spout_z_m", "stream_points")
SCENE_BLOCKS = ("dyn_state", "heightmap_truth", "stream")
SHM_DIR = Path("/dev/shm")


class _Listener:
    """foxglove.websocket.ServerListener: a subscription sets ``event``."""

    def __init__(self, event: threading.Event):
        self.event = event

    def on_subscribe(self, client, channel) -> None:
        self.event.set()


class LiveFoxglove:
    """Sends the run in ``seg`` (attached) to the clients of a foxglove-sdk WebSocket server on ``host:port``."""

    def __init__(self, seg: Segment, scenario, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 interval_s: float = INTERVAL_S):
        self.seg, self.scenario, self.interval_s = seg, scenario, float(interval_s)
        ctx = foxglove.Context()
        #: set by the server's thread when a client subscribes: the next step sends every block's latest
        #: contents again, so a client that subscribes while the run holds a frame (or has ended) sees it
        self._resend = threading.Event()
        self.server = foxglove.start_server(name=f"graincosim {seg.run_id or seg.name}", host=host, port=port,
                                            context=ctx, server_listener=_Listener(self._resend))
        self.host, self.port = host, self.server.port
        self.publisher = FramePublisher(RunInfo.of(scenario), seg.schema, ctx)
        self.recorded = Recorded.of(seg.schema)
        self._structs = set(self.recorded.structs)
        dyn = seg.schema.block("dyn_state") if "dyn_state" in seg.schema else None
        self._scene = SceneUpdateChannel(SCENE_TOPIC, context=ctx) if (
            all(b in seg.schema for b in SCENE_BLOCKS) and isinstance(dyn, StructBlock)
            and set(SCENE_FIELDS) <= {f.name for f in dyn.fields}) else None
        #: per block, the stamp last sent
        self._sent: dict[str, int] = {}
        self.updates = 0

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def answers(self, timeout_s: float = ANSWER_TIMEOUT_S) -> bool:
        """Whether the server accepts a TCP connection within ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                with socket.create_connection((self.host, self.port), timeout=1.0):
                    return True
            except OSError:
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.05)

    def _copy(self, name: str):
        try:
            return self.seg.snapshot(name, tries=SNAPSHOT_TRIES)
        except SnapshotTimeout:
            return None

    def step(self) -> bool:
        """Send what changed since the last step (a block only while a client watches it). Returns whether
        anything was sent."""
        seg, pub = self.seg, self.publisher
        if self._resend.is_set():
            self._resend.clear()
            self._sent.clear()
            pub.forget()
        structs, arrays, stamps = {}, {}, {}
        scene = self._scene is not None and self._scene.has_sinks()
        for name in self.recorded.names:
            s = seg.frame_of(name)
            if s < 0 or s <= self._sent.get(name, -1):
                continue
            if name not in self._structs and not pub.watched(name) and not (scene and name in SCENE_BLOCKS):
                continue
            got = self._copy(name)
            if got is None:
                continue
            stamps[name] = got[0]
            (structs if name in self._structs else arrays)[name] = got[1]
            self._sent[name] = got[0]
        if not stamps:
            return False
        frame = max(stamps.values())
        pub.publish(frame, structs, {n: a for n, a in arrays.items() if pub.watched(n)}, stamps)
        if scene and "dyn_state" in structs:
            stream = self._copy("stream")
            height = (stamps["heightmap_truth"], arrays["heightmap_truth"]) if "heightmap_truth" in arrays \
                else self._copy("heightmap_truth")
            if stream is not None and height is not None:
                try:
                    self._send_scene(stamps["dyn_state"], structs["dyn_state"], height[1], stream[1])
                except Exception:  # noqa: BLE001 - the other topics go on without the scene
                    log.exception("foxglove: the scene of frame %d failed; %s is no longer sent", frame, SCENE_TOPIC)
                    self._scene = None
        self.updates += 1
        return True

    def _send_scene(self, frame: int, state: dict, heights, stream) -> None:
        from cosim.world.scene import scene_from_state

        t_ns = round(frame * self.publisher.period_s * 1e9)
        self._scene.log(scene_update(self.scenario, scene_from_state(self.scenario, state, heights, stream), t_ns),
                        log_time=t_ns)

    def run_alive(self) -> bool:
        return (SHM_DIR / self.seg.name).exists() if SHM_DIR.is_dir() else True

    def serve(self) -> None:
        """Step every ``interval_s`` until the run ends."""
        while self.run_alive():
            t0 = time.monotonic()
            self.step()
            time.sleep(max(0.0, self.interval_s - (time.monotonic() - t0)))
        log.info("foxglove: run %s ended after %d updates", self.seg.name, self.updates)

    def close(self) -> None:
        self.server.stop()
        self.seg.close()


def observe(segment_name: str, scenario_json: str, port: int = DEFAULT_PORT, host: str = DEFAULT_HOST,
            interval_s: float = INTERVAL_S, announce: str | None = None) -> None:
    """Observer entry (spawned by the launcher): serve run ``segment_name`` (scenario ``scenario_json``) until it
    ends. Prints ``foxglove: ws://HOST:PORT`` on stderr once the server answers; ``announce``: also write
    ``{"url", "port", "pid"}`` as JSON to that file then."""
    from cosim.scenario.config import Scenario

    try:
        os.nice(NICE)
    except OSError:
        pass
    live = LiveFoxglove(Segment.attach(segment_name), Scenario.model_validate_json(scenario_json), host, port,
                        interval_s)
    try:
        if not live.answers():
            log.warning("foxglove: %s does not answer yet", live.url)
        sys.stderr.write(f"foxglove: {live.url} (Foxglove or Lichtblick: open a Foxglove WebSocket connection)\n")
        log.info("foxglove: serving %s on %s", segment_name, live.url)
        if announce:
            atomic_write(Path(announce), json.dumps({"url": live.url, "port": live.port, "pid": os.getpid()}))
        live.serve()
    finally:
        live.close()
