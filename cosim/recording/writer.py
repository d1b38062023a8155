"""The MCAP writer: channels planned from a run's schema, one frame's blocks written through foxglove-sdk.

The file is written by foxglove-sdk's MCAP writer (``foxglove.open_mcap`` on a context of its own) with
Foxglove's schemas in protobuf encoding (the SDK's message types, :mod:`cosim.recording.encode`) and our own
JSON channels (:mod:`cosim.recording.schemas`). Each block's messages carry the simulation time of the frame its
contents belong to (its stamp, ``Segment.frame_of``) as log time and message timestamp: a block that lags the
ring (perception one frame behind) is written at its own time, and a block not rewritten since it was last
recorded is not written again. Per block stamp:

* ``/tf`` foxglove.FrameTransform: world -> combine, tractor, cart (from the struct fields ``<v>_x_m``,
  ``<v>_y_m``, ``<v>_yaw_rad`` where they exist), and the constant cart -> cart_grid and LiDAR mount parent ->
  lidar once per new time written.
* ``/<block>`` ``cosim.struct.<block>`` (JSON): every struct block's fields (the scalar time series).
* ``/<cam>/depth_encoded`` foxglove.RawImage ``rgba8`` (lossless, alpha = validity) and ``/<cam>/rgb``
  foxglove.CompressedImage JPEG (or PNG, or RawImage: ``rgb_format``), every ``image_every``-th frame.
* ``/lidar/points`` foxglove.PointCloud (valid beams), ``/heightmap/<kind>`` foxglove.Grid.
* ``/cosim/frame`` ``cosim.Frame`` (JSON), last: everything before it is in the file once its marker is.

Chunks are compressed (zstd by default) and have no size limit: the writer closes its chunk and flushes the
file every ``flush_s`` seconds (1 s; 0: after each frame), so zstd finds each frame's repeats of the one before
and a file cut off at any point reads up to its last whole frame flushed. The SDK's writer is told not to seek
(``disable_seeking``): a chunk reaches the file whole, never as a header waiting for its length.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, NamedTuple

import foxglove
import numpy as np
from foxglove.channels import (
    CompressedImageChannel,
    FrameTransformChannel,
    GridChannel,
    PointCloudChannel,
    RawImageChannel,
)
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from shm_schema import Schema, Segment, StructBlock

from . import schemas as S
from .encode import (
    compressed_image_msg,
    grid_msg,
    planar_transform_msg,
    point_cloud_msg,
    raw_image_msg,
    scalars_json,
    transform_msg,
)

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
_COMPRESSION = {"zstd": MCAPCompression.Zstd, "lz4": MCAPCompression.Lz4, "none": None}


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
    #: chunk compression (foxglove-sdk's MCAP writer, default level): zstd shrinks raw depth-encoded images and
    #: the LiDAR points repeated from an earlier frame of the chunk; lz4 is faster and larger; none writes raw
    compression: Literal["lz4", "zstd", "none"] = "zstd"
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
        if self.compression not in ("lz4", "zstd", "none"):
            raise ValueError(f"compression must be lz4, zstd or none, got {self.compression!r}")


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
        self._run = run if isinstance(run, RunInfo) else RunInfo.of(run)
        self.period_s = self._run.period_s
        self.frames_written = 0
        self._closed = False
        self._ctx = foxglove.Context()
        self._mcap = foxglove.open_mcap(self.path, allow_overwrite=True, context=self._ctx, writer_options=MCAPWriteOptions(
            compression=_COMPRESSION[options.compression], profile=PROFILE, chunk_size=None, compression_threads=0,
            disable_seeking=True))
        #: per block, the last stamp written (a block is written again only with a newer one)
        self._last: dict[str, int] = {}
        #: the last time (frame) the constant transforms were written at
        self._static_frame = -1
        self._plan(schema)
        self._mcap.write_metadata("run", {"run_id": run_id, "fingerprint": fingerprint, "scenario": self._run.scenario,
                                          "sensor_period_s": repr(self.period_s)})
        self._mcap.flush()

    def _plan(self, schema: Schema) -> None:
        rec = self.recorded = Recorded.of(schema)
        ctx = self._ctx
        fields = {b.name: b.fields for b in schema.blocks if isinstance(b, StructBlock)}
        self._structs = {n: foxglove.Channel(f"/{n}", schema=S.struct_schema(n, [(f.name, f.unit) for f in fields[n]]),
                                             context=ctx) for n in rec.structs}
        self._vehicles = []
        for v in VEHICLES:
            for n in rec.structs:
                if {f"{v}_x_m", f"{v}_y_m", f"{v}_yaw_rad"} <= {f.name for f in fields[n]}:
                    self._vehicles.append((v, n))
                    break
        self._tf = FrameTransformChannel("/tf", context=ctx)
        self._images: dict[str, tuple[str, str, object]] = {}
        for name in rec.images:
            cam, _, kind = name.rpartition("_")
            if kind == "rgb" and self.options.rgb_format != "raw":
                fmt, channel = self.options.rgb_format, CompressedImageChannel(f"/{cam}/rgb", context=ctx)
            else:
                topic = {"rgb": f"/{cam}/rgb", "depth": f"/{cam}/depth_encoded"}.get(kind, f"/{name}")
                fmt, channel = "raw", RawImageChannel(topic, context=ctx)
            self._images[name] = (fmt, cam or name, channel)
        self._lidar = PointCloudChannel("/lidar/points", context=ctx) if rec.lidar else None
        self._grids: dict[str, tuple[tuple[float, float], GridChannel]] = {}
        length_m, width_m = self._run.cart_interior_m
        for name in rec.grids:
            shape = schema.block(name).shape
            kind = name[len("heightmap"):].lstrip("_") or "map"
            self._grids[name] = ((length_m / shape[0], width_m / shape[1]),
                                 GridChannel(f"/heightmap/{kind}", context=ctx))
        self._marker = foxglove.Channel(FRAME_TOPIC, schema=S.FRAME_MARKER, context=ctx)

    # -- frames ------------------------------------------------------------------------------------------
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
        """Write sink call ``frame``: ``structs`` {block: {field: value}}; ``arrays`` {block: array} of the
        non-struct blocks this call records (images only on their beat; blocks never written left out);
        ``stamps`` {block: frame its contents belong to} (None or a block missing: ``frame``). A block is written
        at its stamp's time, and only if that stamp is newer than the last it was written with; the frame
        marker carries ``frame``. The arrays are only read during the call (they may be views of a frame slot).
        """
        stamps = stamps or {}
        written = [(name, s) for name in (*structs, *arrays) if (name in self._structs or name in self._grids
                   or name in self._images or (name == "lidar_points" and self._lidar is not None))
                   and (s := self._new(name, stamps, frame)) is not None]
        newest = max((s for _, s in written), default=-1)
        if newest > self._static_frame:
            self._static_frame = newest
            t_ns = self._t_ns(newest)
            for parent, child, tf in self._run.static:
                self._tf.log(transform_msg(t_ns, parent, child, tf), log_time=t_ns)
        for name, s in written:
            t_ns = self._t_ns(s)
            if name in self._structs:
                values = structs[name]
                for v in (v for v, block in self._vehicles if block == name):
                    x, y, yaw = values[f"{v}_x_m"], values[f"{v}_y_m"], values[f"{v}_yaw_rad"]
                    if math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw):
                        self._tf.log(planar_transform_msg(t_ns, "world", v, x, y, yaw), log_time=t_ns)
                self._structs[name].log(scalars_json(t_ns, s, values), log_time=t_ns)
            elif name in self._grids:
                (cx, cy), channel = self._grids[name]
                channel.log(grid_msg(t_ns, arrays[name], cx, cy), log_time=t_ns)
            elif name in self._images:
                fmt, cam, channel = self._images[name]
                img = arrays[name]
                msg = raw_image_msg(t_ns, img, cam) if fmt == "raw" else \
                    compressed_image_msg(t_ns, img, cam, fmt, self.options.jpeg_quality)
                channel.log(msg, log_time=t_ns)
            else:
                self._lidar.log(point_cloud_msg(t_ns, arrays[name]), log_time=t_ns)
        t_ns = self._t_ns(frame)
        self._marker.log(S.marker_json(t_ns, frame, frame * self.period_s), log_time=t_ns)
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
            self._mcap.flush()

    def close(self, stats: dict[str, str] | None = None) -> None:
        """Write ``stats`` (if given) as the ``recorder`` metadata record, the summary, and close the file.
        Idempotent."""
        if self._closed:
            return
        self._closed = True
        if stats:
            self._mcap.write_metadata("recorder", {"frames": str(self.frames_written), **stats})
        self._mcap.close()
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
