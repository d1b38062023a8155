"""MCAP recorder: a per-frame sink of the launcher (``launch(..., sinks=[mcap_sink()])``).

The supervisor calls the sink after each completed frame while it holds the token, so the recorder sees every
frame consistently without a seqlock retry and without a process of its own. Per frame it writes, with the
frame's simulation time as log time and message timestamp:

* ``/tf`` foxglove.FrameTransform: world -> combine, tractor, cart (from the struct fields ``<v>_x_m``,
  ``<v>_y_m``, ``<v>_yaw_rad`` where they exist), cart -> cart_grid and the LiDAR mount parent -> lidar.
* ``/<block>`` ``cosim.struct.<block>``: every struct block's fields (the scalar time series).
* ``/<cam>/rgb`` (JPEG) and ``/<cam>/depth_encoded`` (PNG, lossless) foxglove.CompressedImage, every
  ``image_every``-th frame.
* ``/lidar/points`` foxglove.PointCloud (valid beams), ``/heightmap/<kind>`` foxglove.Grid.
* ``/cosim/frame`` ``cosim.Frame``, last: the frame is complete in the file once its marker is there.

Cost: the sink only copies the frame's blocks (a memcpy) and queues them; a writer thread encodes (cv2 and
zstd release the GIL) and writes. The ring is sequential, so on a 2-core machine the writer mostly uses the core
the ring leaves idle. The queue is bounded (``queue_frames``): when encoding cannot keep up, the sink waits, so
no frame is ever dropped from a recording. ``queue_frames=0`` writes synchronously inside the sink.

After each frame the writer closes its chunk and flushes the file, so a run killed at any point leaves a file
that :func:`cosim.recording.reader.read_recording` reads up to the last frame written: with a child's crash
or a stop, ``close`` drains the queue first (every completed frame); with the launcher itself SIGKILLed, the
frames still queued (at most ``queue_frames``) are lost. A recording failure (disk full, ...) is logged once
and recording stops; the run goes on.
"""
from __future__ import annotations

import logging
import queue
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from shm_schema import Segment, StructBlock

from . import schemas as S
from .encode import grid_msg, image_msg, point_cloud_msg, scalars_msg, stamp, to_json, transform_msg

__all__ = ["RecordOptions", "McapRecorder", "mcap_sink", "DEFAULT_NAME", "PROFILE", "VEHICLES"]

log = logging.getLogger("cosim.recording")

#: file name of a run's recording inside its run directory
DEFAULT_NAME = "recording.mcap"
#: MCAP profile string of our files
PROFILE = "graincosim"
#: vehicles whose world pose is published when a struct has their ``_x_m``, ``_y_m`` and ``_yaw_rad`` fields
VEHICLES = ("combine", "tractor", "cart")
#: channel of the end-of-frame marker
FRAME_TOPIC = "/cosim/frame"


@dataclass(frozen=True)
class RecordOptions:
    """What and how to record. ``path`` None: ``<run_dir>/recording.mcap``."""

    path: Path | None = None
    #: record images every this many frames (1: every frame); other topics are recorded every frame
    image_every: int = 1
    rgb_format: Literal["jpeg", "png"] = "jpeg"
    jpeg_quality: int = 90
    #: per-frame chunk compression
    compression: Literal["zstd", "lz4", "none"] = "zstd"
    #: frames that may wait for the writer thread (0: write synchronously in the sink)
    queue_frames: int = 4

    def __post_init__(self) -> None:
        if self.queue_frames < 0:
            raise ValueError(f"queue_frames must be >= 0, got {self.queue_frames}")
        if self.image_every < 1:
            raise ValueError(f"image_every must be >= 1, got {self.image_every}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in 1..100, got {self.jpeg_quality}")


def _writer(stream, compression: str):
    from mcap.writer import CompressionType, Writer

    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]
    if hasattr(Writer, "flush"):
        # chunked and indexed; each frame becomes its own chunk via Writer.flush()
        return Writer(stream, compression=comp), True
    return Writer(stream, use_chunking=False, compression=CompressionType.NONE), False


class McapRecorder:
    """Writes one run's frames to an MCAP file (see the module docstring for the channels)."""

    def __init__(self, scenario, run_dir: Path, segment: Segment, options: RecordOptions | None = None):
        self.options = options or RecordOptions()
        self.path = Path(self.options.path) if self.options.path else Path(run_dir) / DEFAULT_NAME
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.period_s = float(scenario.timing.sensor_period_s)
        self.frames_written = 0
        self._scenario = scenario
        self._failed = False
        self._closed = False
        self._file = open(self.path, "wb")
        self._w, self._chunked = _writer(self._file, self.options.compression)
        self._w.start(PROFILE, "graincosim.cosim.recording")
        self._schemas: dict[str, int] = {}
        self._plan(segment)
        self._queue: queue.Queue = queue.Queue(maxsize=max(1, self.options.queue_frames))
        self._thread = None
        if self.options.queue_frames > 0:
            self._thread = threading.Thread(target=self._worker, name="mcap-writer", daemon=True)
            self._thread.start()
        self._w.add_metadata("run", {"run_id": segment.run_id, "fingerprint": segment.fingerprint,
                                     "scenario": scenario.name, "sensor_period_s": repr(self.period_s)})
        self._flush()

    # -- channels ----------------------------------------------------------------------------------------
    def _channel(self, topic: str, schema: dict) -> int:
        name = schema["title"]
        if name not in self._schemas:
            self._schemas[name] = self._w.register_schema(name, "jsonschema", S.encode_schema(schema))
        return self._w.register_channel(topic, "json", self._schemas[name])

    def _plan(self, seg: Segment) -> None:
        from cosim.geometry import cart_body_from_grid, mount_transform

        blocks = seg.schema.blocks
        self._structs = [(b.name, self._channel(f"/{b.name}", S.struct_schema(b.name, [(f.name, f.unit)
                                                                                   for f in b.fields])))
                         for b in blocks if isinstance(b, StructBlock)]
        self._vehicles = []
        for v in VEHICLES:
            for b in blocks:
                if isinstance(b, StructBlock) and {f"{v}_x_m", f"{v}_y_m", f"{v}_yaw_rad"} <= {f.name for f in
                                                                                              b.fields}:
                    self._vehicles.append((v, b.name))
                    break
        mount = self._scenario.sensor.mount
        self._static = [("cart", "cart_grid", cart_body_from_grid(self._scenario.cart)),
                        (mount.parent, "lidar", mount_transform(mount))]
        self._tf = self._channel("/tf", S.FRAME_TRANSFORM)
        self._images = []
        for b in blocks:
            if getattr(b, "kind", "") != "image":
                continue
            cam, _, kind = b.name.rpartition("_")
            if kind == "rgb":
                fmt, topic = self.options.rgb_format, f"/{cam}/rgb"
            elif kind == "depth":
                fmt, topic = "png", f"/{cam}/depth_encoded"
            else:
                fmt, topic = "png", f"/{b.name}"
            self._images.append((b.name, fmt, cam or b.name, self._channel(topic, S.COMPRESSED_IMAGE)))
        self._lidar = None
        if "lidar_points" in seg.schema and len(seg.schema.block("lidar_points").shape) == 2:
            self._lidar = self._channel("/lidar/points", S.POINT_CLOUD)
        self._grids = []
        cart = self._scenario.cart
        for b in blocks:
            if b.name.startswith("heightmap") and not isinstance(b, StructBlock) and len(b.shape) == 2:
                kind = b.name[len("heightmap"):].lstrip("_") or "map"
                cell = (cart.interior_length_m / b.shape[0], cart.interior_width_m / b.shape[1])
                self._grids.append((b.name, cell, self._channel(f"/heightmap/{kind}", S.GRID)))
        self._marker = self._channel(FRAME_TOPIC, S.FRAME_MARKER)

    @property
    def topics(self) -> int:
        """Number of channels this recording has."""
        return 2 + len(self._structs) + len(self._images) + len(self._grids) + (self._lidar is not None)

    # -- frames ------------------------------------------------------------------------------------------
    def _put(self, channel: int, t_ns: int, msg: dict) -> None:
        self._w.add_message(channel, log_time=t_ns, data=to_json(msg), publish_time=t_ns)

    def _flush(self) -> None:
        if self._chunked:
            self._w.flush()
        else:
            self._file.flush()

    def __call__(self, seg: Segment, frame: int) -> None:
        """Record completed frame ``frame`` (called by the supervisor while it holds the token)."""
        if self._failed or self._closed:
            return
        try:
            item = self._capture(seg, frame)
            if self._thread is None:
                self._write(item)
            else:
                self._queue.put(item)
        except Exception:  # noqa: BLE001 - a recording failure must not end the run
            self._fail(frame)

    def _fail(self, frame: int) -> None:
        self._failed = True
        log.exception("recording to %s failed at frame %d; the run goes on without recording", self.path, frame)

    def _capture(self, seg: Segment, frame: int) -> tuple:
        """Copies of what frame ``frame`` records (the blocks are quiescent while the supervisor holds the token)."""
        structs = {name: seg.view(name).as_dict() for name, _ in self._structs}
        images = []
        if frame % self.options.image_every == 0:
            images = [(fmt, cam, ch, np.array(seg.view(name)[..., :3])) for name, fmt, cam, ch in self._images
                      if seg.frame_of(name) >= 0]
        lidar = (np.array(seg.view("lidar_points")) if self._lidar is not None and seg.frame_of("lidar_points") >= 0
                 else None)
        grids = [(cell, ch, np.array(seg.view(name))) for name, cell, ch in self._grids if seg.frame_of(name) >= 0]
        return frame, structs, images, lidar, grids

    def _worker(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._failed:
                continue
            try:
                self._write(item)
            except Exception:  # noqa: BLE001
                self._fail(item[0])

    def _write(self, item: tuple) -> None:
        frame, structs, images, lidar, grids = item
        t_ns = round(frame * self.period_s * 1e9)
        for parent, child, tf in self._static:
            self._put(self._tf, t_ns, transform_msg(t_ns, parent, child, tf))
        for v, block in self._vehicles:
            s = structs[block]
            c, sn = np.cos(s[f"{v}_yaw_rad"]), np.sin(s[f"{v}_yaw_rad"])
            tf = np.array([[c, -sn, 0.0, s[f"{v}_x_m"]], [sn, c, 0.0, s[f"{v}_y_m"]], [0, 0, 1, 0], [0, 0, 0, 1]])
            if np.isfinite(tf).all():
                self._put(self._tf, t_ns, transform_msg(t_ns, "world", v, tf))
        for name, channel in self._structs:
            self._put(channel, t_ns, scalars_msg(t_ns, frame, structs[name]))
        for fmt, cam, channel, rgb in images:
            self._put(channel, t_ns, image_msg(t_ns, rgb, cam, fmt, self.options.jpeg_quality))
        if lidar is not None:
            self._put(self._lidar, t_ns, point_cloud_msg(t_ns, lidar))
        for (cx, cy), channel, h in grids:
            self._put(channel, t_ns, grid_msg(t_ns, h, cx, cy))
        self._put(self._marker, t_ns, {"timestamp": stamp(t_ns), "frame": int(frame), "t_s": frame * self.period_s})
        self._flush()
        self.frames_written += 1

    def close(self) -> None:
        """Drain the queue, write the summary and close the file. Idempotent; also called on failure or stop."""
        if self._closed:
            return
        self._closed = True
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join()
        try:
            self._w.finish()
        finally:
            self._file.close()
        log.info("recording %s: %d frames", self.path, self.frames_written)


def mcap_sink(options: RecordOptions | None = None):
    """A launcher sink factory: ``launch(..., sinks=[mcap_sink(RecordOptions(...))])``."""

    def factory(scenario, run_dir, segment) -> McapRecorder:
        return McapRecorder(scenario, run_dir, segment, options)

    return factory
