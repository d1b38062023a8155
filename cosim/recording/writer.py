"""The MCAP writer: channels planned from a run's schema, one frame's blocks encoded and written.

Per frame, with the frame's simulation time as log time and message timestamp:

* ``/tf`` foxglove.FrameTransform: world -> combine, tractor, cart (from the struct fields ``<v>_x_m``,
  ``<v>_y_m``, ``<v>_yaw_rad`` where they exist), cart -> cart_grid and the LiDAR mount parent -> lidar.
* ``/<block>`` ``cosim.struct.<block>`` (JSON): every struct block's fields (the scalar time series).
* ``/<cam>/depth_encoded`` foxglove.RawImage ``rgba8``, the image block's bytes unchanged (lossless, alpha =
  validity), and ``/<cam>/rgb`` foxglove.CompressedImage JPEG (or PNG, or RawImage: ``rgb_format``), every
  ``image_every``-th frame (default 5).
* ``/lidar/points`` foxglove.PointCloud (valid beams), ``/heightmap/<kind>`` foxglove.Grid.
* ``/cosim/frame`` ``cosim.Frame`` (JSON), last: the frame is complete in the file once its marker is there.

Foxglove's messages are protobuf (:mod:`cosim.recording.proto`): their bytes fields are written as they are,
without base64. Chunks holding camera images are lz4-compressed (``compression``: raw depth images shrink ~18 x),
chunks holding the LiDAR cloud are not (``cloud_compression``: float32 points gain ~3 % from lz4 for ~2 ms per
frame); the small messages go into whichever chunk is open (a run without camera images or cloud: ``compression``). Camera images are recorded every
5th frame by default (``image_every``), everything else every frame. The writer closes its chunk and flushes the
file at most every ``flush_s`` seconds (0: after each frame), so a file cut off at any point reads up to its last
whole frame flushed. :func:`frame_data` takes a frame's blocks from a segment (the synchronous path) and
:meth:`cosim.recording.slots.FrameSlots.frame` from a frame slot; :class:`McapWriter` encodes and writes them.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from shm_schema import Schema, Segment, StructBlock

from . import proto
from . import schemas as S
from .encode import (
    compressed_image_msg,
    grid_msg,
    planar_transform_msg,
    point_cloud_msg,
    raw_image_msg,
    scalars_msg,
    stamp,
    to_json,
    transform_msg,
)

__all__ = ["RecordOptions", "RunInfo", "McapWriter", "Recorded", "frame_data", "DEFAULT_NAME", "PROFILE", "VEHICLES",
           "FRAME_TOPIC"]

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
    #: record camera images every this many frames (1: every frame; 5: 2 Hz at the default 0.1 s frames); every
    #: other topic is recorded every frame. Images are ~80 % of a default frame's bytes (2 x 1.3 MB raw depth)
    image_every: int = 5
    #: RGB camera images (``<cam>_rgb``, present when the viewer asked for them): JPEG or PNG CompressedImage, or
    #: a RawImage rgba8 (no encoding work, larger); depth-encoded images are always RawImage (lossless)
    rgb_format: Literal["jpeg", "png", "raw"] = "jpeg"
    jpeg_quality: int = 90
    #: compression of the chunks holding camera images (raw depth-encoded images shrink ~18 x with lz4), and of
    #: every chunk of a run without a LiDAR cloud
    compression: Literal["lz4", "zstd", "none"] = "lz4"
    #: compression of the chunks holding the LiDAR cloud: float32 points gain ~3 % from lz4 for ~2 ms per frame;
    #: zstd saves ~60 % (points repeat across frames) for several ms per frame
    cloud_compression: Literal["lz4", "zstd", "none"] = "none"
    #: frame slots in flight to the recorder process (0: no process, write synchronously inside the sink; None:
    #: as many as fit in QUEUE_BYTES, within MIN_SLOTS..MAX_SLOTS: ~20 for a default frame, 256 for small ones)
    queue_frames: int | None = None
    #: the recorder process closes a chunk and flushes at most this often, s (0: after every frame)
    flush_s: float = 0.5
    #: niceness added to the recorder process: it yields the CPU to the ring (the credits still guarantee that
    #: it gets every frame: when all slots are full the ring waits for it)
    nice: int = 10

    def __post_init__(self) -> None:
        if not 0 <= self.nice <= 19:
            raise ValueError(f"nice must be in 0..19, got {self.nice}")
        if self.flush_s < 0:
            raise ValueError(f"flush_s must be >= 0, got {self.flush_s}")
        if self.queue_frames is not None and self.queue_frames < 0:
            raise ValueError(f"queue_frames must be >= 0, got {self.queue_frames}")
        if self.image_every < 1:
            raise ValueError(f"image_every must be >= 1, got {self.image_every}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in 1..100, got {self.jpeg_quality}")
        if self.rgb_format not in ("jpeg", "png", "raw"):
            raise ValueError(f"rgb_format must be jpeg, png or raw, got {self.rgb_format!r}")
        for name in ("compression", "cloud_compression"):
            if getattr(self, name) not in ("lz4", "zstd", "none"):
                raise ValueError(f"{name} must be lz4, zstd or none, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class Recorded:
    """Which blocks a run's recording takes, from its schema alone (the sink and the writer agree on it)."""

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

    @property
    def names(self) -> tuple[str, ...]:
        """Every recorded block."""
        return self.due(0, 1)

    def due(self, frame: int, image_every: int) -> tuple[str, ...]:
        """The blocks frame ``frame`` records: every struct, the LiDAR points and the height maps, and the
        images on every ``image_every``-th frame."""
        images = self.images if frame % image_every == 0 else ()
        return self.structs + (("lidar_points",) if self.lidar else ()) + self.grids + images


@dataclass(frozen=True)
class RunInfo:
    """What the writer needs from the scenario, as plain values (the recorder process then imports no config)."""

    scenario: str
    #: frame period, s
    period_s: float
    #: constant transforms (parent, child, 4 x 4 parent_from_child, m): cart -> cart_grid, mount parent -> lidar
    static: tuple[tuple[str, str, np.ndarray], ...]
    #: cart interior length (along grid x) and width (along grid y), m
    cart_interior_m: tuple[float, float]

    @classmethod
    def of(cls, scenario) -> "RunInfo":
        from cosim.geometry import cart_body_from_grid, mount_transform

        mount, cart = scenario.sensor.mount, scenario.cart
        return cls(scenario.name, float(scenario.timing.sensor_period_s),
                   (("cart", "cart_grid", np.asarray(cart_body_from_grid(cart), float)),
                    (mount.parent, "lidar", np.asarray(mount_transform(mount), float))),
                   (float(cart.interior_length_m), float(cart.interior_width_m)))


def _compression_type(name: str):
    from mcap.writer import CompressionType

    return {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[name]


def _writer(stream, compression: str):
    from mcap.writer import Writer

    return Writer(stream, compression=_compression_type(compression))


#: where mcap's Writer keeps the compression of the chunks it finalizes (private: mcap 1.x). The writer switches
#: it between chunks so that images and the LiDAR cloud can be compressed differently; without it (another mcap
#: version) every chunk gets ``compression``.
_WRITER_COMPRESSION = "_Writer__compression"


class McapWriter:
    """Writes one run's frames to an MCAP file (see the module docstring for the channels).

    ``run`` is a :class:`RunInfo` (or a scenario, turned into one); ``schema`` is the run's segment schema;
    ``run_id`` and ``fingerprint`` go into the file's metadata.
    """

    def __init__(self, run, schema: Schema, path: Path, options: RecordOptions, run_id: str = "",
                 fingerprint: str = "", flush_s: float = 0.0):
        self.options = options
        self.flush_s = float(flush_s)
        self._t_flush = time.monotonic()
        self._dirty = False
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        run = run if isinstance(run, RunInfo) else RunInfo.of(run)
        self.period_s = run.period_s
        self.frames_written = 0
        self._run = run
        self._closed = False
        self._file = open(self.path, "wb")
        self._w = _writer(self._file, options.compression)
        self._chunk_compression = options.compression
        self._switchable = hasattr(self._w, _WRITER_COMPRESSION)
        self._w.start(PROFILE, "graincosim.cosim.recording")
        self._schemas: dict[str, int] = {}
        self._plan(schema)
        self._w.add_metadata("run", {"run_id": run_id, "fingerprint": fingerprint, "scenario": run.scenario,
                                     "sensor_period_s": repr(self.period_s)})
        self._w.flush()

    # -- channels ----------------------------------------------------------------------------------------
    def _json_channel(self, topic: str, schema: dict) -> int:
        name = schema["title"]
        if name not in self._schemas:
            self._schemas[name] = self._w.register_schema(name, "jsonschema", S.encode_schema(schema))
        return self._w.register_channel(topic, "json", self._schemas[name])

    def _proto_channel(self, topic: str, name: str) -> int:
        if name not in self._schemas:
            self._schemas[name] = self._w.register_schema(name, "protobuf", proto.descriptor_set(name))
        return self._w.register_channel(topic, "protobuf", self._schemas[name])

    def _plan(self, schema: Schema) -> None:
        rec = self.recorded = Recorded.of(schema)
        fields = {b.name: b.fields for b in schema.blocks if isinstance(b, StructBlock)}
        self._structs = [(n, self._json_channel(f"/{n}", S.struct_schema(n, [(f.name, f.unit) for f in fields[n]])))
                         for n in rec.structs]
        self._vehicles = []
        for v in VEHICLES:
            for n in rec.structs:
                if {f"{v}_x_m", f"{v}_y_m", f"{v}_yaw_rad"} <= {f.name for f in fields[n]}:
                    self._vehicles.append((v, n))
                    break
        self._tf = self._proto_channel("/tf", "foxglove.FrameTransform")
        # constant transforms: encoded once without their timestamp; a frame prepends its timestamp field
        # (concatenated protobuf messages merge)
        self._static = [proto.encode("foxglove.FrameTransform", {**transform_msg(0, parent, child, tf),
                                                                 "timestamp": None})
                        for parent, child, tf in self._run.static]
        self._images: dict[str, tuple[str, str, int]] = {}
        for name in rec.images:
            cam, _, kind = name.rpartition("_")
            if kind == "rgb" and self.options.rgb_format != "raw":
                fmt, topic, schema_name = self.options.rgb_format, f"/{cam}/rgb", "foxglove.CompressedImage"
            else:
                topic = {"rgb": f"/{cam}/rgb", "depth": f"/{cam}/depth_encoded"}.get(kind, f"/{name}")
                fmt, schema_name = "raw", "foxglove.RawImage"
            self._images[name] = (fmt, cam or name, self._proto_channel(topic, schema_name))
        self._lidar = self._proto_channel("/lidar/points", "foxglove.PointCloud") if rec.lidar else None
        self._grids: dict[str, tuple[tuple[float, float], int]] = {}
        length_m, width_m = self._run.cart_interior_m
        for name in rec.grids:
            shape = schema.block(name).shape
            kind = name[len("heightmap"):].lstrip("_") or "map"
            cell = (length_m / shape[0], width_m / shape[1])
            self._grids[name] = (cell, self._proto_channel(f"/heightmap/{kind}", "foxglove.Grid"))
        self._marker = self._json_channel(FRAME_TOPIC, S.FRAME_MARKER)

    # -- frames ------------------------------------------------------------------------------------------
    def _put(self, channel: int, t_ns: int, data) -> None:
        self._w.add_message(channel, log_time=t_ns, data=data, publish_time=t_ns)

    def _compress_next_with(self, compression: str) -> None:
        """Finish the chunk in progress and compress the following chunks with ``compression``."""
        if compression == self._chunk_compression or not self._switchable:
            return
        self._w.flush()
        setattr(self._w, _WRITER_COMPRESSION, _compression_type(compression))
        self._chunk_compression = compression

    def write(self, frame: int, structs: dict[str, dict], arrays: dict[str, np.ndarray]) -> None:
        """Encode and write frame ``frame``: ``structs`` {block: {field: value}}; ``arrays`` {block: array} of the
        non-struct blocks this frame records (images only on their beat; blocks never written left out). The
        arrays are only read during the call (they may be views of a frame slot)."""
        t_ns = round(frame * self.period_s * 1e9)
        ts = stamp(t_ns)
        ts_field = proto.encode("foxglove.FrameTransform", {"timestamp": ts})
        for rest in self._static:
            self._put(self._tf, t_ns, ts_field + rest)
        for v, block in self._vehicles:
            s = structs.get(block)
            if s is None:
                continue
            x, y, yaw = s[f"{v}_x_m"], s[f"{v}_y_m"], s[f"{v}_yaw_rad"]
            if np.isfinite((x, y, yaw)).all():
                self._put(self._tf, t_ns, proto.encode("foxglove.FrameTransform",
                                                       planar_transform_msg(t_ns, "world", v, x, y, yaw)))
        for name, channel in self._structs:
            if name in structs:
                self._put(channel, t_ns, to_json(scalars_msg(t_ns, frame, structs[name])))
        for name, ((cx, cy), channel) in self._grids.items():
            if name in arrays:
                self._put(channel, t_ns, proto.encode("foxglove.Grid", grid_msg(t_ns, arrays[name], cx, cy)))
        images = [(name, arrays[name]) for name in self._images if name in arrays]
        if images:
            self._compress_next_with(self.options.compression)
        for name, img in images:
            fmt, cam, channel = self._images[name]
            if fmt == "raw":
                self._put(channel, t_ns, proto.encode("foxglove.RawImage", raw_image_msg(t_ns, img, cam)))
            else:
                msg = compressed_image_msg(t_ns, img, cam, fmt, self.options.jpeg_quality)
                self._put(channel, t_ns, proto.encode("foxglove.CompressedImage", msg))
        lidar = arrays.get("lidar_points")
        if lidar is not None and self._lidar is not None:
            self._compress_next_with(self.options.cloud_compression)
            self._put(self._lidar, t_ns, proto.encode("foxglove.PointCloud", point_cloud_msg(t_ns, lidar)))
        self._put(self._marker, t_ns, to_json({"timestamp": ts, "frame": int(frame), "t_s": frame * self.period_s}))
        self.frames_written += 1
        self._dirty = True
        if time.monotonic() - self._t_flush >= self.flush_s:
            self.flush()

    def flush_due_in(self) -> float | None:
        """Seconds until a flush is due (0: now), None when nothing is waiting to be flushed."""
        if not self._dirty:
            return None
        return max(0.0, self.flush_s - (time.monotonic() - self._t_flush))

    def flush(self) -> None:
        """Close the chunk and flush the file now, if any frame was written since the last flush."""
        if self._dirty:
            self._t_flush = time.monotonic()
            self._dirty = False
            self._w.flush()

    def close(self, stats: dict[str, str] | None = None) -> None:
        """Write ``stats`` (if given) as the ``recorder`` metadata record, the summary, and close the file.
        Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            if stats:
                self._w.add_metadata("recorder", {"frames": str(self.frames_written), **stats})
            self._w.finish()
        finally:
            self._file.close()
        log.info("recording %s: %d frames", self.path, self.frames_written)


def frame_data(seg: Segment, names) -> tuple[dict[str, dict], dict[str, np.ndarray]]:
    """(structs, arrays) of blocks ``names`` of ``seg`` for :meth:`McapWriter.write`: struct fields copied into
    dicts, arrays as zero-copy views (valid while the blocks are quiescent: the supervisor holds the token, or
    they are a frame slot the recorder owns). Blocks never written are left out."""
    structs, arrays = {}, {}
    for n in names:
        if seg.frame_of(n) < 0:
            continue
        v = seg.view(n)
        if isinstance(seg.schema.block(n), StructBlock):
            arr = v.array
            structs[n] = dict(zip(arr.dtype.names, arr.item()))
        else:
            arrays[n] = v
    return structs, arrays
