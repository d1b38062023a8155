"""Embree's packet traversal (``rtcIntersect4/8``) in a compiled loop: the rays of a frame in packets, no Python
per packet.

embreex's ``EmbreeScene.run`` traverses one ray per ``rtcIntersect1`` call; Embree's packet calls traverse 4 or 8
rays together (its SIMD width), which pays for coherent rays such as a LiDAR pattern's neighbouring beams in their
order. A call per packet from Python (ctypes) costs what the packets save, so the loop is compiled with numba
(``cache=True``: compiled once per installation and loaded from numba's cache afterwards). Without numba, or on
a device whose packets are not native, :func:`packet_tracer` returns None and the caller keeps embreex's loop.

Each packet is written into one 64-byte aligned scratch ``RTCRayHitN`` (structure of arrays, N lanes per field;
Embree 4.4's ``rtcore_ray.h``): the ray's 12 fields (origin, tnear, direction, time, tfar, mask, id, flags),
then the hit's 7 (normal, u, v, primID, geomID) and the instance stack (``instID``, then ``instPrimID`` where the
library has instance arrays), whose depth (``RTC_MAX_INSTANCE_LEVEL_COUNT``) the library does not report: the
scratch has room for :data:`MAX_INSTANCE_LEVELS` levels of both. The hit fields read back (primID, geomID) come
before the instance stack, so their offsets do not depend on that depth.

Results are those of ``EmbreeScene.run(..., output=True)`` for the fields the ray cast uses: per ray the geometry
and primitive ids (int32, -1 on a miss) and tfar (float32, the input tfar on a miss), the rays from the origin
with tnear 0, mask all ones (tested ray for ray against ``run``, ``tests/test_rigidcast.py``).
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np

from . import embree_api as emb

__all__ = ["MAX_INSTANCE_LEVELS", "PacketTracer", "packet_tracer"]

#: instance levels the scratch packet has room for (Embree's default build has 1)
MAX_INSTANCE_LEVELS = 8
#: ``rtcGetDeviceProperty`` ids (``rtcore_device.h``): native 4-, 8- and 16-wide packets
_NATIVE_RAY = {4: 32, 8: 33, 16: 34}
#: packet widths tried, widest first (16 needs AVX-512)
_WIDTHS = (16, 8, 4)
_PACKET_CALL = ctypes.CFUNCTYPE(None, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t)


@dataclass(frozen=True)
class PacketTracer:
    """Packets of ``width`` rays through Embree's ``rtcIntersect<width>`` (``call``: its C entry point)."""

    width: int
    call: object

    def trace(self, scene: int, directions: np.ndarray, tfar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest hits in committed scene ``scene`` (RTCScene) of rays from the origin along ``directions`` (N, 3)
        float32, up to ``tfar`` (N,) float32 (overwritten with the hit distance, as embreex's ``run`` does);
        returns (geomID, primID), (N,) int32 each, -1 on a miss."""
        from ._packet_loop import trace_packets

        d = np.ascontiguousarray(directions, dtype=np.float32)
        if tfar.dtype != np.float32 or not tfar.flags.c_contiguous or len(tfar) != len(d):
            raise ValueError("tfar must be a contiguous float32 array, one per ray")
        geom, prim = np.empty(len(d), np.int32), np.empty(len(d), np.int32)
        trace_packets(self.call, self.width, scene, d, tfar, geom, prim, MAX_INSTANCE_LEVELS)
        return geom, prim


def packet_tracer(device: int, width: int | None = None) -> PacketTracer | None:
    """A tracer for ``device`` (RTCDevice) at ``width`` (4, 8 or 16), or at the widest width its packets are
    native; None when numba is not installed or the device has no native packets (then keep ``EmbreeScene.run``).
    Imports numba and loads (or on first use compiles) the loop: a fraction of a second."""
    try:
        from . import _packet_loop  # noqa: F401 - numba's import and the compiled loop
    except ImportError:
        return None
    lib = emb.api()
    native = [w for w in _WIDTHS if lib.rtcGetDeviceProperty(device, _NATIVE_RAY[w]) == 1]
    if width is None:
        if not native:
            return None
        width = native[0]
    elif width not in _NATIVE_RAY:
        raise ValueError(f"packet width {width}: choose 4, 8 or 16")
    fn = getattr(lib, f"rtcIntersect{width}")
    return PacketTracer(width, _PACKET_CALL(ctypes.cast(fn, ctypes.c_void_p).value))
