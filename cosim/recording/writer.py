"""The MCAP writer: channels planned from a run's schema, one frame's blocks encoded and written.

Each block's messages carry the simulation time of the frame its contents belong to (its stamp in the
segment, ``Segment.frame_of``) as log time and message timestamp: a block that lags the ring (perception one
frame behind) is written at its own time, when its new contents arrive, and a block not rewritten since it was
last recorded is not written again. Per block stamp:

* ``/tf`` foxglove.FrameTransform: world -> combine, tractor, cart (from the struct fields ``<v>_x_m``,
  ``<v>_y_m``, ``<v>_yaw_rad`` where they exist, at that struct's stamp), and the constant cart -> cart_grid
  and LiDAR mount parent -> lidar once per new time written.
* ``/<block>`` ``cosim.struct.<block>`` (JSON): every struct block's fields (the scalar time series).
* ``/<cam>/depth_encoded`` foxglove.RawImage ``rgba8``, the image block's bytes unchanged (lossless, alpha =
  validity), and ``/<cam>/rgb`` foxglove.CompressedImage JPEG (or PNG, or RawImage: ``rgb_format``), every
  ``image_every``-th frame (default 5).
* ``/lidar/points`` foxglove.PointCloud (valid beams), ``/heightmap/<kind>`` foxglove.Grid.
* ``/cosim/frame`` ``cosim.Frame`` (JSON), last, with the sink call's frame: everything before it is in the
  file once its marker is there.

Foxglove's messages are protobuf (:mod:`cosim.recording.proto`): their bytes fields are written as they are,
without base64, and copied once, straight into the chunk (:mod:`cosim.recording.mcapfile`). Chunks are
zstd-compressed at a fast level with a window that spans a chunk's frames (``compression``): LiDAR points and
image rows that did not change since an earlier frame of the chunk (most of them) cost next to nothing, so a
default frame shrinks ~7 x for less CPU time than lz4 (~2 x) or than writing it uncompressed to the page cache.
Camera images are recorded every 5th frame by default (``image_every``), everything else every frame. The
writer closes its chunk and flushes the file at most every ``flush_s`` seconds (1 s; 0: after each frame), so a
file cut off at any point reads up to its last whole frame flushed. :func:`frame_data` takes a frame's blocks
from a segment (the synchronous path) and :meth:`cosim.recording.slots.FrameSlots.frame` from a frame slot;
:class:`McapWriter` encodes and writes them.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np

from shm_schema import Schema, Segment, StructBlock

from . import proto
from . import schemas as S
from .encode import (
    compressed_image_msg,
    grid_msg,
    point_cloud_msg,
    raw_image_msg,
    scalars_json,
    transform_msg,
)
from .mcapfile import McapFile
from .templates import PlanarTransform, ScalarsTemplate, marker_json, timestamp_field

__all__ = ["RecordOptions", "RunInfo", "McapWriter", "Recorded", "FrameData", "frame_data", "DEFAULT_NAME", "PROFILE",
           "VEHICLES", "FRAME_TOPIC"]

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
    #: compression of the chunks holding camera images, and of every chunk of a run without a LiDAR cloud: zstd
    #: (fast level, 8 MiB window: mcapfile.ZSTD_*) shrinks raw depth-encoded images ~25 x at ~2 GB/s, lz4 ~18 x
    #: at ~3 GB/s but leaves the cloud ~1.1 x
    compression: Literal["lz4", "zstd", "none"] = "zstd"
    #: compression of the chunks holding the LiDAR cloud: with zstd's window spanning a chunk's frames, points
    #: repeated from an earlier frame (~96 % of a default frame's) cost next to nothing (~6 x at ~1.5 GB/s); lz4
    #: gains ~10 %; none writes 0.6 MB a frame to the page cache, which costs about as much CPU time as zstd.
    #: Chunks switch compression only when images and cloud differ
    cloud_compression: Literal["lz4", "zstd", "none"] = "zstd"
    #: frame slots in flight to the recorder process (0: no process, write synchronously inside the sink; None:
    #: as many as fit in QUEUE_BYTES, within MIN_SLOTS..MAX_SLOTS: ~20 for a default frame, 256 for small ones)
    queue_frames: int | None = None
    #: the recorder process closes a chunk and flushes at most this often, s (0: after every frame): 1 s (10
    #: default frames, ~11 MB before compression) lets zstd find each frame's repeats of the one before (the
    #: first frame of a chunk has none) and the second image pair's repeats of the first; ~30 % less CPU time
    #: and file than 0.5 s
    flush_s: float = 1.0
    #: niceness added to the recorder process: it yields the CPU to the ring (the credits still guarantee that
    #: it gets every frame: when all slots are full the ring waits for it). Not SCHED_IDLE: on a machine whose
    #: other work keeps both cores busy an idle-class recorder gets next to no CPU, the slots fill and the ring
    #: waits on it for as long as that work lasts (measured: 30-92x real time against 67-120x at nice 10 in the
    #: same rounds), and an unprivileged process can never leave SCHED_IDLE again
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


class FrameData(NamedTuple):
    """One sink call's recorded blocks for :meth:`McapWriter.write`: ``structs`` {block: {field: value}},
    ``arrays`` {block: array} (views, valid while the source is quiescent) and ``stamps`` {block: the frame its
    contents belong to} for every block in either."""

    structs: dict[str, dict]
    arrays: dict[str, np.ndarray]
    stamps: dict[str, int]


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
        from cosim.world.geometry import cart_body_from_grid, mount_transform

        mount, cart = scenario.sensor.mount, scenario.cart
        return cls(scenario.name, float(scenario.timing.sensor_period_s),
                   (("cart", "cart_grid", np.asarray(cart_body_from_grid(cart), float)),
                    (mount.parent, "lidar", np.asarray(mount_transform(mount), float))),
                   (float(cart.interior_length_m), float(cart.interior_width_m)))


def _constant(schema: str, msg: dict) -> bytes:
    """Wire bytes of the fields of ``msg`` other than its timestamp and data."""
    return proto.encode(schema, {k: v for k, v in msg.items() if k not in ("timestamp", "data")})


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
        self._w = McapFile(self._file, options.compression)
        self._w.start(PROFILE, "graincosim.cosim.recording")
        self._schemas: dict[str, int] = {}
        #: per block, the last stamp written (a block is written again only with a newer one)
        self._last: dict[str, int] = {}
        #: the last time (frame) the constant transforms were written at
        self._static_frame = -1
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
        #: per struct block, its JSON message template (field names in block order)
        self._scalars = {n: ScalarsTemplate([f.name for f in fields[n]], [np.dtype(f.dtype).kind for f in fields[n]])
                         for n in rec.structs}
        self._vehicles = []
        for v in VEHICLES:
            for n in rec.structs:
                if {f"{v}_x_m", f"{v}_y_m", f"{v}_yaw_rad"} <= {f.name for f in fields[n]}:
                    self._vehicles.append((v, n))
                    break
        self._tf = self._proto_channel("/tf", "foxglove.FrameTransform")
        self._planar = {v: PlanarTransform("world", v) for v, _ in self._vehicles}
        # constant transforms: encoded once without their timestamp; a frame prepends its timestamp field
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
        # the cloud in the mount frame, rewritten every frame: one buffer for the whole run
        self._cloud = np.empty((schema.block("lidar_points").shape[0], 4), "<f4") if rec.lidar else None
        self._grids: dict[str, tuple[tuple[float, float], int]] = {}
        length_m, width_m = self._run.cart_interior_m
        for name in rec.grids:
            shape = schema.block(name).shape
            kind = name[len("heightmap"):].lstrip("_") or "map"
            cell = (length_m / shape[0], width_m / shape[1])
            self._grids[name] = (cell, self._proto_channel(f"/heightmap/{kind}", "foxglove.Grid"))
        self._marker = self._json_channel(FRAME_TOPIC, S.FRAME_MARKER)
        # the fields that never change (frame, pose, layout, sizes) encoded once per channel; a message is then its
        # timestamp and data followed by these (protobuf parsers take fields in any order)
        self._const: dict[str, bytes] = {}
        if rec.lidar:
            self._const["lidar_points"] = _constant("foxglove.PointCloud",
                                                    point_cloud_msg(0, np.zeros((0, 4), np.float32)))
        for name, ((cx, cy), _) in self._grids.items():
            self._const[name] = _constant("foxglove.Grid", grid_msg(0, np.zeros(schema.block(name).shape, "<f4"),
                                                                    cx, cy))
        for name, (fmt, cam, _) in self._images.items():
            if fmt == "raw":
                self._const[name] = _constant("foxglove.RawImage",
                                              raw_image_msg(0, np.zeros(schema.block(name).shape, np.uint8), cam))

    def _message(self, schema: str, name: str, ts_field: bytes, data) -> list:
        """Parts of a message of channel block ``name``: its timestamp field, its data, then the constant fields
        (the order of the schema's fields, as :func:`cosim.recording.proto.encode` writes them)."""
        return [ts_field, *proto.encode_parts(schema, {"data": data}), self._const[name]]

    # -- frames ------------------------------------------------------------------------------------------
    def _put(self, channel: int, t_ns: int, parts) -> None:
        self._w.add_message(channel, t_ns, parts)

    def _compress_next_with(self, compression: str) -> None:
        """Compress the chunks from here on with ``compression`` (finishing the chunk in progress if it changes)."""
        self._w.set_compression(compression)

    def _t_ns(self, frame: int) -> int:
        return round(frame * self.period_s * 1e9)

    def _new(self, name: str, stamps: dict[str, int], frame: int) -> int | None:
        """The stamp to write block ``name`` at, or None when it is not newer than the last one written."""
        s = stamps.get(name, frame)
        if s <= self._last.get(name, -1):
            return None
        self._last[name] = s
        return s

    def write(self, frame: int, structs: dict[str, dict], arrays: dict[str, np.ndarray],
              stamps: dict[str, int] | None = None) -> None:
        """Encode and write sink call ``frame``: ``structs`` {block: {field: value}}; ``arrays`` {block: array} of
        the non-struct blocks this call records (images only on their beat; blocks never written left out);
        ``stamps`` {block: frame its contents belong to} (None or a block missing: ``frame``). A block is written
        at its stamp's time, and only if that stamp is newer than the last it was written with; the frame
        marker carries ``frame``. The arrays are only read during the call (they may be views of a frame slot).
        """
        stamps = stamps or {}
        new = self._new
        struct_stamps = [(name, channel, s) for name, channel in self._structs if name in structs
                         and (s := new(name, stamps, frame)) is not None]
        grid_stamps = [(name, cell, channel, s) for name, (cell, channel) in self._grids.items() if name in arrays
                       and (s := new(name, stamps, frame)) is not None]
        image_stamps = [(name, s) for name in self._images if name in arrays
                        and (s := new(name, stamps, frame)) is not None]
        lidar = arrays.get("lidar_points") if self._lidar is not None else None
        lidar_stamp = new("lidar_points", stamps, frame) if lidar is not None else None
        newest = max([s for *_, s in struct_stamps + grid_stamps + image_stamps] +
                     ([lidar_stamp] if lidar_stamp is not None else []), default=-1)
        ts_fields: dict[int, bytes] = {}

        def ts_field(t_ns: int) -> bytes:
            if t_ns not in ts_fields:
                ts_fields[t_ns] = timestamp_field(t_ns)
            return ts_fields[t_ns]

        if newest > self._static_frame:
            self._static_frame = newest
            t_ns = self._t_ns(newest)
            for rest in self._static:
                self._put(self._tf, t_ns, (ts_field(t_ns), rest))
        for name, channel, s in struct_stamps:
            t_ns = self._t_ns(s)
            values = structs[name]
            for v, block in self._vehicles:
                if block != name:
                    continue
                x, y, yaw = values[f"{v}_x_m"], values[f"{v}_y_m"], values[f"{v}_yaw_rad"]
                if math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw):
                    self._put(self._tf, t_ns, (self._planar[v].encode(ts_field(t_ns), x, y, yaw),))
            self._put(channel, t_ns, (self._scalars_json(name, t_ns, s, values),))
        for name, (cx, cy), channel, s in grid_stamps:
            t_ns = self._t_ns(s)
            # Grid rows run along y: the bytes of h.T (encode.grid_msg)
            self._put(channel, t_ns, self._message("foxglove.Grid", name, ts_field(t_ns),
                                                   np.ascontiguousarray(np.asarray(arrays[name], "<f4").T)))
        if image_stamps:
            self._compress_next_with(self.options.compression)
        for name, s in image_stamps:
            fmt, cam, channel = self._images[name]
            t_ns = self._t_ns(s)
            img = arrays[name]
            if fmt == "raw":
                self._put(channel, t_ns, self._message("foxglove.RawImage", name, ts_field(t_ns),
                                                       raw_image_msg(t_ns, img, cam)["data"]))
            else:
                msg = compressed_image_msg(t_ns, img, cam, fmt, self.options.jpeg_quality)
                self._put(channel, t_ns, proto.encode_parts("foxglove.CompressedImage", msg))
        if lidar_stamp is not None:
            self._compress_next_with(self.options.cloud_compression)
            t_ns = self._t_ns(lidar_stamp)
            self._put(self._lidar, t_ns, self._message("foxglove.PointCloud", "lidar_points", ts_field(t_ns),
                                                       point_cloud_msg(t_ns, lidar, out=self._cloud)["data"]))
        t_ns = self._t_ns(frame)
        self._put(self._marker, t_ns, (marker_json(t_ns, frame, frame * self.period_s),))
        self.frames_written += 1
        self._dirty = True
        if time.monotonic() - self._t_flush >= self.flush_s:
            self.flush()

    def _scalars_json(self, name: str, t_ns: int, frame: int, values: dict) -> bytes:
        """The ``cosim.struct.<name>`` message of ``values`` {field: value} (every field of the block, or any
        subset: then through the generic encoder)."""
        template = self._scalars[name]
        if len(values) == len(template.names):
            try:
                return template.encode(t_ns, frame, tuple(map(values.__getitem__, template.names)))
            except KeyError:
                pass
        return scalars_json(t_ns, frame, values)

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


def frame_data(seg: Segment, names) -> FrameData:
    """(structs, arrays, stamps) of blocks ``names`` of ``seg`` for :meth:`McapWriter.write`: struct fields copied
    into dicts, arrays as zero-copy views (valid while the blocks are quiescent: the supervisor holds the token,
    or they are a frame slot the recorder owns), and each block's stamp (``seg.frame_of``: the frame its
    contents belong to, which may be earlier than the sink call's). Blocks never written are left out."""
    structs, arrays, stamps = {}, {}, {}
    for n in names:
        s = seg.frame_of(n)
        if s < 0:
            continue
        stamps[n] = s
        v = seg.view(n)
        if isinstance(seg.schema.block(n), StructBlock):
            arr = v.array
            structs[n] = dict(zip(arr.dtype.names, arr.item()))
        else:
            arrays[n] = v
    return FrameData(structs, arrays, stamps)
