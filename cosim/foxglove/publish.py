"""A run's frames as Foxglove messages on a foxglove-sdk context: what the recording and the live server send.

:class:`FramePublisher` plans one channel per topic from a run's segment schema on a ``foxglove.Context`` and logs
one frame's blocks to them; whatever sinks the context has get them (an MCAP file: :class:`McapWriter`; a
WebSocket server: :mod:`cosim.foxglove.live`). Each block's messages carry the simulation time of the frame its
contents belong to (its stamp, ``Segment.frame_of``) as log time and message timestamp: a block that lags the
ring (perception one frame behind) is sent at its own time, and a block not rewritten since it was last sent is
not sent again. Topics, per block stamp:

* ``/tf`` foxglove.FrameTransform: world -> combine, tractor, cart (from the struct fields ``<v>_x_m``,
  ``<v>_y_m``, ``<v>_yaw_rad`` where they exist), and the constant cart -> cart_grid and LiDAR mount parent ->
  lidar once per new time sent.
* ``/<block>`` ``cosim.struct.<block>`` (JSON): every struct block's fields (the scalar time series).
* ``/<cam>/depth_encoded`` foxglove.RawImage ``rgba8`` (lossless, alpha = validity) and ``/<cam>/rgb``
  foxglove.CompressedImage JPEG (or PNG, or RawImage: ``rgb_format``), when the caller passes them.
* ``/lidar/points`` foxglove.PointCloud (valid beams), ``/heightmap/<kind>`` foxglove.Grid.
* per camera sensor (cosim.foxglove.cameras): ``/cam_<name>/rgb`` and ``/right`` (frame ``cam_<name>_optical``),
  ``/cam_<name>/calibration`` foxglove.CameraCalibration (with each of its images), ``/cam_<name>/depth``
  (``32FC1``, the measured depth), ``/depth_exact``, ``/labels`` (``mono8``), ``/cam_<name>/points``
  foxglove.PointCloud (frame ``cam_<name>``); the camera arrays are recorded on the images' beat.
* ``/cosim/frame`` ``cosim.Frame`` (JSON), last: everything before it is in a file once its marker is.

The recording (:class:`cosim.recording.writer.McapWriter`) is this publisher with an MCAP file as its sink.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import foxglove
import numpy as np
from foxglove.channels import (
    CameraCalibrationChannel,
    CompressedImageChannel,
    FrameTransformChannel,
    GridChannel,
    PointCloudChannel,
    RawImageChannel,
)

from shm_schema import Schema, StructBlock

from .cameras import (
    CAMERA_ARRAY_PARTS,
    CameraInfo,
    calibration_msg,
    camera_frames,
    float_image_msg,
    mono_image_msg,
)
from .messages import (
    FRAME_MARKER,
    compressed_image_msg,
    frame_transform,
    grid_msg,
    marker_json,
    planar_transform_msg,
    point_cloud_msg,
    quaternion_from_matrix,
    raw_image_msg,
    scalars_json,
    struct_schema,
)

__all__ = ["FramePublisher", "Recorded", "RunInfo", "VEHICLES", "FRAME_TOPIC"]

#: vehicles whose world pose is published when a struct has their ``_x_m``, ``_y_m`` and ``_yaw_rad`` fields
VEHICLES = ("combine", "tractor", "cart")
#: channel of the end-of-frame marker
FRAME_TOPIC = "/cosim/frame"


@dataclass(frozen=True)
class Recorded:
    """Which blocks a run's recording takes, from its schema alone (the sink and the writer agree on it)."""

    structs: tuple[str, ...]
    images: tuple[str, ...]
    lidar: bool
    grids: tuple[str, ...]
    #: the camera sensors' array blocks (``cam_<name>_measured``, ``_depth``, ``_labels``, ``_points``)
    camera_arrays: tuple[str, ...] = ()

    @classmethod
    def of(cls, schema: Schema) -> "Recorded":
        blocks = schema.blocks
        return cls(tuple(b.name for b in blocks if isinstance(b, StructBlock)),
                   tuple(b.name for b in blocks if getattr(b, "kind", "") == "image"),
                   "lidar_points" in schema and len(schema.block("lidar_points").shape) == 2,
                   tuple(b.name for b in blocks if b.name.startswith("heightmap") and not isinstance(b, StructBlock)
                         and len(b.shape) == 2),
                   tuple(b.name for b in blocks if b.name.startswith("cam_") and not isinstance(b, StructBlock)
                         and getattr(b, "kind", "") != "image"
                         and b.name.rpartition("_")[2] in CAMERA_ARRAY_PARTS))

    @property
    def names(self) -> tuple[str, ...]:
        """Every recorded block."""
        return self.due(0, 1)

    def due(self, frame: int, image_every: int) -> tuple[str, ...]:
        """The blocks frame ``frame`` records: every struct, the LiDAR points and the height maps, and the
        images on every ``image_every``-th frame."""
        images = self.images + self.camera_arrays if frame % image_every == 0 else ()
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
    #: the camera sensors (their frames are among ``static``)
    cameras: tuple[CameraInfo, ...] = ()
    #: what the dashboard's replay needs of the scenario (cosim.viewer.viewinfo.ViewInfo as JSON; "" unknown)
    view_json: str = ""

    @classmethod
    def of(cls, scenario) -> "RunInfo":
        from cosim.viewer.viewinfo import ViewInfo
        from cosim.world.geometry import cart_body_from_grid, mount_transform

        from .cameras import camera_infos

        cart = scenario.cart
        frames = [("cart", "cart_grid", np.asarray(cart_body_from_grid(cart), float))]
        if scenario.lidar is not None:
            mount = scenario.lidar.mount
            frames.append((mount.parent, "lidar", np.asarray(mount_transform(mount), float)))
        cams = camera_infos(scenario)
        frames += [f for c in cams for f in camera_frames(c)]
        return cls(scenario.name, float(scenario.timing.sensor_period_s), tuple(frames),
                   (float(cart.interior_length_m), float(cart.interior_width_m)), cams, ViewInfo.of(scenario).to_json())


class FramePublisher:
    """Channels for a run with segment schema ``schema`` on ``context``, and :meth:`publish` of one frame.

    ``run`` is a :class:`RunInfo`; ``rgb_format`` and ``jpeg_quality`` say how RGB images are sent."""

    def __init__(self, run: RunInfo, schema: Schema, context, rgb_format: Literal["jpeg", "png", "raw"] = "jpeg",
                 jpeg_quality: int = 90):
        self._run, self._ctx = run, context
        self.rgb_format, self.jpeg_quality = rgb_format, jpeg_quality
        self.period_s = run.period_s
        #: per block, the last stamp sent (a block is sent again only with a newer one)
        self._last: dict[str, int] = {}
        #: the last time (frame) the constant transforms were sent at
        self._static_frame = -1
        #: the constant transforms as (parent, child, translation, quaternion), converted once
        self._static = [(parent, child, tf[:3, 3].tolist(), quaternion_from_matrix(tf)) for parent, child, tf in run.static]
        self._plan(schema)

    def _plan(self, schema: Schema) -> None:
        rec = self.recorded = Recorded.of(schema)
        ctx = self._ctx
        fields = {b.name: b.fields for b in schema.blocks if isinstance(b, StructBlock)}
        self._structs = {n: foxglove.Channel(f"/{n}", schema=struct_schema(n, [(f.name, f.unit) for f in fields[n]]),
                                             context=ctx) for n in rec.structs}
        self._vehicles = []
        for v in VEHICLES:
            for n in rec.structs:
                if {f"{v}_x_m", f"{v}_y_m", f"{v}_yaw_rad"} <= {f.name for f in fields[n]}:
                    self._vehicles.append((v, n))
                    break
        self._tf = FrameTransformChannel("/tf", context=ctx)
        self._images: dict[str, tuple[str, str, object]] = {}
        cameras = {c.frame: c for c in self._run.cameras}
        #: per camera sensor frame: its info and calibration channel, and the last stamp its calibration went at
        self._calib: dict[str, tuple[CameraInfo, object]] = {
            c.frame: (c, CameraCalibrationChannel(f"/{c.frame}/calibration", context=ctx)) for c in cameras.values()}
        self._calib_sent: dict[str, int] = {}
        for name in rec.images:
            cam, _, kind = name.rpartition("_")
            frame_id = cam or name
            if cam in cameras:                                     # a camera sensor: its optical frames
                frame_id = f"{cam}_optical" if kind == "rgb" else f"{cam}_right_optical"
            if kind in ("rgb", "right") and self.rgb_format != "raw":
                fmt, channel = self.rgb_format, CompressedImageChannel(f"/{cam}/{kind}", context=ctx)
            else:
                topic = {"rgb": f"/{cam}/rgb", "right": f"/{cam}/right",
                         "depth": f"/{cam}/depth_encoded"}.get(kind, f"/{name}")
                fmt, channel = "raw", RawImageChannel(topic, context=ctx)
            self._images[name] = (fmt, frame_id, channel)
        self._cam_arrays: dict[str, tuple[str, str, object]] = {}
        for name in rec.camera_arrays:
            cam, _, part = name.rpartition("_")
            topic = f"/{cam}/{CAMERA_ARRAY_PARTS[part]}"
            channel = PointCloudChannel(topic, context=ctx) if part == "points" else RawImageChannel(topic, context=ctx)
            self._cam_arrays[name] = (part, cam if part == "points" else f"{cam}_optical", channel)
        self._lidar = PointCloudChannel("/lidar/points", context=ctx) if rec.lidar else None
        self._grids: dict[str, tuple[tuple[float, float], GridChannel]] = {}
        length_m, width_m = self._run.cart_interior_m
        for name in rec.grids:
            shape = schema.block(name).shape
            kind = name[len("heightmap"):].lstrip("_") or "map"
            self._grids[name] = ((length_m / shape[0], width_m / shape[1]),
                                 GridChannel(f"/heightmap/{kind}", context=ctx))
        self._marker = foxglove.Channel(FRAME_TOPIC, schema=FRAME_MARKER, context=ctx)

    @property
    def topics(self) -> dict[str, str]:
        """{topic: schema name} of every channel."""
        chans = [*self._structs.values(), *(c for _, c in self._grids.values()),
                 *(c for *_, c in self._images.values()), *(c for *_, c in self._cam_arrays.values()),
                 *(c for _, c in self._calib.values()), self._tf, self._marker, self._lidar]
        return {c.topic(): c.schema_name() for c in chans if c is not None}

    def forget(self) -> None:
        """Send every block again from its next publish on, even at a stamp already sent."""
        self._last.clear()
        self._calib_sent.clear()
        self._static_frame = -1

    def watched(self, name: str) -> bool:
        """Whether a sink takes the messages of block ``name`` (an MCAP file always; a WebSocket server while a
        client subscribes to its topic)."""
        ch = self._structs.get(name) or (self._grids[name][1] if name in self._grids else None) or \
            (self._images[name][2] if name in self._images else None) or \
            (self._cam_arrays[name][2] if name in self._cam_arrays else None) or \
            (self._lidar if name == "lidar_points" else None)
        return ch is not None and ch.has_sinks()

    def _calibration(self, cam: str, s: int, t_ns: int) -> None:
        """The CameraCalibration of camera sensor frame ``cam`` at stamp ``s``, once per stamp (nothing for a
        block that is not a camera sensor's)."""
        if cam not in self._calib or self._calib_sent.get(cam, -1) >= s:
            return
        self._calib_sent[cam] = s
        info, channel = self._calib[cam]
        channel.log(calibration_msg(t_ns, info, f"{cam}_optical"), log_time=t_ns)

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

    def publish(self, frame: int, structs: dict[str, dict], arrays: dict[str, np.ndarray],
                stamps: dict[str, int] | None = None) -> None:
        """Send sink call ``frame``: ``structs`` {block: {field: value}}; ``arrays`` {block: array} of the
        non-struct blocks this call records (images only on their beat; blocks never written left out);
        ``stamps`` {block: frame its contents belong to} (None or a block missing: ``frame``). A block is written
        at its stamp's time, and only if that stamp is newer than the last it was written with; the frame
        marker carries ``frame``. The arrays are only read during the call (they may be views of a frame slot).
        """
        stamps = stamps or {}
        sent = [(name, s) for name in (*structs, *arrays) if (name in self._structs or name in self._grids
                   or name in self._images or name in self._cam_arrays
                   or (name == "lidar_points" and self._lidar is not None))
                   and (s := self._new(name, stamps, frame)) is not None]
        newest = max((s for _, s in sent), default=-1)
        if newest > self._static_frame:
            self._static_frame = newest
            t_ns = self._t_ns(newest)
            for parent, child, xyz, q in self._static:
                self._tf.log(frame_transform(t_ns, parent, child, xyz, q), log_time=t_ns)
        for name, s in sent:
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
                    compressed_image_msg(t_ns, img, cam, fmt, self.jpeg_quality)
                channel.log(msg, log_time=t_ns)
                self._calibration(name.rpartition("_")[0], s, t_ns)
            elif name in self._cam_arrays:
                part, frame_id, channel = self._cam_arrays[name]
                a = arrays[name]
                msg = (point_cloud_msg(t_ns, a, frame_id) if part == "points" else
                       mono_image_msg(t_ns, a, frame_id) if part == "labels" else float_image_msg(t_ns, a, frame_id))
                channel.log(msg, log_time=t_ns)
                self._calibration(name.rpartition("_")[0], s, t_ns)
            else:
                self._lidar.log(point_cloud_msg(t_ns, arrays[name]), log_time=t_ns)
        t_ns = self._t_ns(frame)
        self._marker.log(marker_json(t_ns, frame, frame * self.period_s), log_time=t_ns)
