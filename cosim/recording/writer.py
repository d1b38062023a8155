"""The MCAP writer: channels planned from a run's schema, one frame's copied blocks encoded and written.

Per frame, with the frame's simulation time as log time and message timestamp:

* ``/tf`` foxglove.FrameTransform: world -> combine, tractor, cart (from the struct fields ``<v>_x_m``,
  ``<v>_y_m``, ``<v>_yaw_rad`` where they exist), cart -> cart_grid and the LiDAR mount parent -> lidar.
* ``/<block>`` ``cosim.struct.<block>``: every struct block's fields (the scalar time series).
* ``/<cam>/rgb`` (JPEG) and ``/<cam>/depth_encoded`` (PNG, lossless) foxglove.CompressedImage, every
  ``image_every``-th frame.
* ``/lidar/points`` foxglove.PointCloud (valid beams), ``/heightmap/<kind>`` foxglove.Grid.
* ``/cosim/frame`` ``cosim.Frame``, last: the frame is complete in the file once its marker is there.

The writer closes its chunk and flushes the file after each frame (``flush_s=0``) or at most every ``flush_s``
seconds (the recorder process, which outlives a killed launcher and finishes the file itself), so a file cut
off at any point reads up to its last whole frame flushed. :func:`capture` takes the copies (in the
supervisor, while it holds the token); :class:`McapWriter` encodes and writes them (in the recorder process, :mod:`cosim.recording.sink`).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from shm_schema import Schema, Segment, StructBlock

from . import schemas as S
from .encode import grid_msg, image_msg, point_cloud_msg, scalars_msg, stamp, to_json, transform_msg

__all__ = ["RecordOptions", "McapWriter", "Recorded", "capture", "DEFAULT_NAME", "PROFILE", "VEHICLES", "FRAME_TOPIC"]

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
    #: frames in flight to the recorder process (0: no process, write synchronously inside the sink)
    queue_frames: int = 4
    #: the recorder process closes a chunk and flushes at most this often, s (the synchronous writer: every frame)
    flush_s: float = 0.5

    def __post_init__(self) -> None:
        if self.flush_s < 0:
            raise ValueError(f"flush_s must be >= 0, got {self.flush_s}")
        if self.queue_frames < 0:
            raise ValueError(f"queue_frames must be >= 0, got {self.queue_frames}")
        if self.image_every < 1:
            raise ValueError(f"image_every must be >= 1, got {self.image_every}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in 1..100, got {self.jpeg_quality}")


@dataclass(frozen=True)
class Recorded:
    """Which blocks a run's recording takes, from its schema alone (the capture and the writer agree on it)."""

    structs: tuple[str, ...]
    images: tuple[str, ...]
    lidar: bool
    grids: tuple[str, ...]

    @classmethod
    def of(cls, schema: Schema) -> "Recorded":
        blocks = schema.blocks
        return cls(tuple(b.name for b in blocks if isinstance(b, StructBlock)),
                   tuple(b.name for b in blocks if getattr(b, "kind", "") == "image"),
                   "lidar_points" in schema and len(schema.block("lidar_points").shape) == 2,
                   tuple(b.name for b in blocks if b.name.startswith("heightmap") and not isinstance(b, StructBlock)
                         and len(b.shape) == 2))


def _writer(stream, compression: str):
    from mcap.writer import CompressionType, Writer

    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]
    if hasattr(Writer, "flush"):
        # chunked and indexed; each frame becomes its own chunk via Writer.flush()
        return Writer(stream, compression=comp), True
    return Writer(stream, use_chunking=False, compression=CompressionType.NONE), False


class McapWriter:
    """Writes one run's frames to an MCAP file (see the module docstring for the channels).

    ``schema`` is the run's segment schema; ``run_id`` and ``fingerprint`` go into the file's metadata.
    """

    def __init__(self, scenario, schema: Schema, path: Path, options: RecordOptions, run_id: str = "",
                 fingerprint: str = "", flush_s: float = 0.0):
        self.options = options
        self.flush_s = float(flush_s)
        self._t_flush = time.monotonic()
        self._dirty = False
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.period_s = float(scenario.timing.sensor_period_s)
        self.frames_written = 0
        self._scenario = scenario
        self._closed = False
        self._file = open(self.path, "wb")
        self._w, self._chunked = _writer(self._file, options.compression)
        self._w.start(PROFILE, "graincosim.cosim.recording")
        self._schemas: dict[str, int] = {}
        self._plan(schema)
        self._w.add_metadata("run", {"run_id": run_id, "fingerprint": fingerprint, "scenario": scenario.name,
                                     "sensor_period_s": repr(self.period_s)})
        self._flush()

    # -- channels ----------------------------------------------------------------------------------------
    def _channel(self, topic: str, schema: dict) -> int:
        name = schema["title"]
        if name not in self._schemas:
            self._schemas[name] = self._w.register_schema(name, "jsonschema", S.encode_schema(schema))
        return self._w.register_channel(topic, "json", self._schemas[name])

    def _plan(self, schema: Schema) -> None:
        from cosim.geometry import cart_body_from_grid, mount_transform

        rec = Recorded.of(schema)
        fields = {b.name: b.fields for b in schema.blocks if isinstance(b, StructBlock)}
        self._structs = [(n, self._channel(f"/{n}", S.struct_schema(n, [(f.name, f.unit) for f in fields[n]])))
                         for n in rec.structs]
        self._vehicles = []
        for v in VEHICLES:
            for n in rec.structs:
                if {f"{v}_x_m", f"{v}_y_m", f"{v}_yaw_rad"} <= {f.name for f in fields[n]}:
                    self._vehicles.append((v, n))
                    break
        mount = self._scenario.sensor.mount
        self._static = [("cart", "cart_grid", cart_body_from_grid(self._scenario.cart)),
                        (mount.parent, "lidar", mount_transform(mount))]
        self._tf = self._channel("/tf", S.FRAME_TRANSFORM)
        self._images: dict[str, tuple[str, str, int]] = {}
        for name in rec.images:
            cam, _, kind = name.rpartition("_")
            if kind == "rgb":
                fmt, topic = self.options.rgb_format, f"/{cam}/rgb"
            elif kind == "depth":
                fmt, topic = "png", f"/{cam}/depth_encoded"
            else:
                fmt, topic = "png", f"/{name}"
            self._images[name] = (fmt, cam or name, self._channel(topic, S.COMPRESSED_IMAGE))
        self._lidar = self._channel("/lidar/points", S.POINT_CLOUD) if rec.lidar else None
        self._grids: dict[str, tuple[tuple[float, float], int]] = {}
        cart = self._scenario.cart
        for name in rec.grids:
            shape = schema.block(name).shape
            kind = name[len("heightmap"):].lstrip("_") or "map"
            cell = (cart.interior_length_m / shape[0], cart.interior_width_m / shape[1])
            self._grids[name] = (cell, self._channel(f"/heightmap/{kind}", S.GRID))
        self._marker = self._channel(FRAME_TOPIC, S.FRAME_MARKER)

    # -- frames ------------------------------------------------------------------------------------------
    def _put(self, channel: int, t_ns: int, msg: dict) -> None:
        self._w.add_message(channel, log_time=t_ns, data=to_json(msg), publish_time=t_ns)

    def _flush(self) -> None:
        if self._chunked:
            self._w.flush()
        else:
            self._file.flush()

    def write(self, item: tuple) -> None:
        """Encode and write one frame captured by :func:`capture`, then flush."""
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
        for name, rgb in images:
            fmt, cam, channel = self._images[name]
            self._put(channel, t_ns, image_msg(t_ns, rgb, cam, fmt, self.options.jpeg_quality))
        if lidar is not None and self._lidar is not None:
            self._put(self._lidar, t_ns, point_cloud_msg(t_ns, lidar))
        for name, h in grids:
            (cx, cy), channel = self._grids[name]
            self._put(channel, t_ns, grid_msg(t_ns, h, cx, cy))
        self._put(self._marker, t_ns, {"timestamp": stamp(t_ns), "frame": int(frame), "t_s": frame * self.period_s})
        self.frames_written += 1
        self._dirty = True
        if time.monotonic() - self._t_flush >= self.flush_s:
            self.flush()

    def flush(self) -> None:
        """Close the chunk and flush the file now, if any frame was written since the last flush."""
        if self._dirty:
            self._t_flush = time.monotonic()
            self._dirty = False
            self._flush()

    def close(self) -> None:
        """Write the summary and close the file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._w.finish()
        finally:
            self._file.close()
        log.info("recording %s: %d frames", self.path, self.frames_written)


def capture(seg: Segment, rec: Recorded, frame: int, image_every: int = 1) -> tuple:
    """Copies of what frame ``frame`` records (blocks are quiescent while the supervisor holds the token).

    Returns ``(frame, structs, images, lidar, grids)``: {block: {field: value}}; [(block, (H, W, 3) uint8)] for
    the images due this frame; the (N, 4) float32 LiDAR rows or None; [(block, (nx, ny) float32)]. Blocks never
    written yet are left out.
    """
    structs = {name: seg.view(name).as_dict() for name in rec.structs}
    images = []
    if frame % image_every == 0:
        images = [(name, np.array(seg.view(name)[..., :3])) for name in rec.images if seg.frame_of(name) >= 0]
    lidar = np.array(seg.view("lidar_points")) if rec.lidar and seg.frame_of("lidar_points") >= 0 else None
    grids = [(name, np.array(seg.view(name))) for name in rec.grids if seg.frame_of(name) >= 0]
    return frame, structs, images, lidar, grids
