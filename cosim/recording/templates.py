"""Per-frame messages from pre-encoded templates: only the values that change are encoded each frame.

A ground-truth run records ~8 small messages per frame at ~1000 frames per second of wall time; built through
the generic dict encoders (:func:`cosim.recording.proto.encode`, :func:`json.dumps` of a dict) they cost the
recorder ~0.1 ms per frame, which on a loaded 2-core machine is CPU taken from the ring. The templates here
write the same bytes (tests/test_recording_templates.py compares them with the generic encoders) in a few
microseconds each:

* :func:`timestamp_field`: field 1 (``timestamp``) of every Foxglove message we write, once per time.
* :class:`PlanarTransform`: a foxglove.FrameTransform of a pose in the plane, parent and child pre-encoded.
* :class:`ScalarsTemplate`: the ``cosim.struct.<block>`` JSON of a struct block's values, a format string made
  once from the field names (floats written by ``repr`` as :func:`json.dumps` does, non-finite ones as null).
* :func:`marker_json`: the ``cosim.Frame`` end-of-frame marker.
"""
from __future__ import annotations

import json
import math
import re
import struct

from . import proto
from .encode import scalars_json

__all__ = ["timestamp_field", "PlanarTransform", "ScalarsTemplate", "marker_json", "NS_PER_S"]

NS_PER_S = 1_000_000_000
#: protobuf wire types
_VARINT, _I64, _LEN = 0, 1, 2
#: FrameTransform fields translation (4, a Vector3) and rotation (5, a Quaternion) with every component written,
#: zeros included, as the generic encoder does: key, length, then (key, double) per component
_POSE_TAIL = struct.Struct("<BB" + "Bd" * 3 + "BB" + "Bd" * 4)
_POSE_KEYS = ((4 << 3 | _LEN), 27, 1 << 3 | _I64, 2 << 3 | _I64, 3 << 3 | _I64,
              (5 << 3 | _LEN), 36, 1 << 3 | _I64, 2 << 3 | _I64, 3 << 3 | _I64, 4 << 3 | _I64)
#: a non-finite value as ``repr`` writes it, in a value position of a JSON object (after ``:``)
_NON_FINITE = re.compile(r"(?<=:)(?:-?inf|nan)(?=[,}])")


def timestamp_field(t_ns: int) -> bytes:
    """Field 1 of a Foxglove message: a ``google.protobuf.Timestamp`` {seconds, nanos} of ``t_ns`` >= 0 (ns),
    both written even when zero, as :func:`cosim.recording.proto.encode` writes ``{"timestamp": stamp(t_ns)}``."""
    sec, nsec = divmod(max(0, int(t_ns)), NS_PER_S)
    ts = b"\x08" + proto.varint(sec) + b"\x10" + proto.varint(nsec)
    return bytes((1 << 3 | _LEN, len(ts))) + ts


class PlanarTransform:
    """foxglove.FrameTransform bytes of ``parent`` -> ``child`` poses in the plane: translation (x, y, 0),
    rotation yaw about z (:func:`cosim.recording.encode.planar_transform_msg`, encoded)."""

    def __init__(self, parent: str, child: str):
        self.parent, self.child = parent, child
        self._ids = proto.encode("foxglove.FrameTransform", {"parent_frame_id": parent, "child_frame_id": child})

    def encode(self, ts_field: bytes, x_m: float, y_m: float, yaw_rad: float) -> bytes:
        """The message at the time of ``ts_field`` (:func:`timestamp_field`); x, y in m, yaw in rad."""
        k = _POSE_KEYS
        tail = _POSE_TAIL.pack(k[0], k[1], k[2], float(x_m), k[3], float(y_m), k[4], 0.0,
                               k[5], k[6], k[7], 0.0, k[8], 0.0, k[9], math.sin(0.5 * yaw_rad),
                               k[10], math.cos(0.5 * yaw_rad))
        return ts_field + self._ids + tail


class ScalarsTemplate:
    """The ``cosim.struct.<block>`` JSON message of a struct block with fields ``names`` (float or integer kinds,
    ``kinds[i]`` a numpy dtype kind ``"f"``/``"i"``/``"u"``), from the block's values as a tuple in field
    order (``ndarray.item()`` of the struct): byte for byte :func:`cosim.recording.encode.scalars_json`.

    A field named ``frame`` takes the place (and the value) of the message's own ``frame``, as the dict merge in
    :func:`scalars_json` does. A field named ``timestamp``, or of another kind, falls back to
    :func:`scalars_json`.
    """

    def __init__(self, names, kinds):
        self.names = tuple(names)
        kinds = tuple(kinds)
        self._fallback = ("timestamp" in self.names or any(k not in "fiu" for k in kinds)
                          or any("%" in n for n in self.names))
        #: position of a ``frame`` field among the values, None without one
        self._frame_at = self.names.index("frame") if "frame" in self.names else None
        spec = {n: "%r" if k == "f" else "%d" for n, k in zip(self.names, kinds)}
        items = "".join(f",{json.dumps(n)}:{spec[n]}" for n in self.names if n != "frame")
        self._fmt = '{"timestamp":{"sec":%d,"nsec":%d},"frame":' + spec.get("frame", "%d") + items + "}"

    def encode(self, t_ns: int, frame: int, values: tuple) -> bytes:
        """JSON bytes at ``t_ns`` (ns, >= 0) for sink frame ``frame`` of the struct values ``values``."""
        if self._fallback:
            return scalars_json(t_ns, frame, dict(zip(self.names, values)))
        sec, nsec = divmod(max(0, int(t_ns)), NS_PER_S)
        i = self._frame_at
        if i is None:
            out = self._fmt % (sec, nsec, int(frame), *values)
        else:
            out = self._fmt % (sec, nsec, values[i], *values[:i], *values[i + 1:])
        if "inf" in out or "nan" in out:
            out = _NON_FINITE.sub("null", out)
        return out.encode()


def marker_json(t_ns: int, frame: int, t_s: float) -> bytes:
    """The ``cosim.Frame`` marker ``{"timestamp", "frame", "t_s"}`` as :func:`cosim.recording.encode.to_json`
    writes it (``t_s`` finite)."""
    sec, nsec = divmod(max(0, int(t_ns)), NS_PER_S)
    return b'{"timestamp":{"sec":%d,"nsec":%d},"frame":%d,"t_s":%s}' % (sec, nsec, int(frame),
                                                                          float.__repr__(float(t_s)).encode())
