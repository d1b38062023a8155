"""The compiled loop of :mod:`cosim.world.embree_packets` (numba; importing this module imports numba and raises
ImportError without it). Field offsets in lanes of one ``RTCRayHitN`` (``rtcore_ray.h``, Embree 4.4)."""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["trace_packets"]

# the ray's fields, then the hit's: each a row of ``width`` lanes
_DIR_X, _TFAR, _MASK, _PRIM_ID, _GEOM_ID, _INST_ID = 4, 8, 9, 17, 18, 19
#: rows before the instance stack
_ROWS = 19
#: alignment of a packet and of its valid mask, bytes (rtcIntersect16 asks 64)
_ALIGN = 64


@njit(cache=True)
def _aligned(n: int, dtype):
    """A zeroed (n,) array of 4-byte ``dtype`` starting on a 64-byte boundary."""
    buf = np.zeros(n + _ALIGN // 4, dtype)
    skip = ((_ALIGN - buf.ctypes.data % _ALIGN) % _ALIGN) // 4
    return buf[skip:skip + n]


@njit(cache=True)
def trace_packets(call, width, scene, d, tfar, geom, prim, levels):
    """Rays from the origin along ``d`` (N, 3) float32 up to ``tfar`` (N,) float32 through ``scene``, ``width``
    at a time by ``call`` (rtcIntersect<width>); writes ``tfar`` (the hit distance), ``geom`` and ``prim`` (N,)
    int32 (-1 on a miss). ``levels``: instance levels the scratch packet has room for (instID and instPrimID)."""
    w = width
    pk = _aligned((_ROWS + 2 * levels) * w, np.float32)
    ipk = pk.view(np.int32)
    valid = _aligned(w, np.int32)
    for j in range(w):                        # origin, tnear, time 0 (zeroed); mask all ones; id, flags 0
        ipk[_MASK * w + j] = -1
    n = d.shape[0]
    for start in range(0, n, w):
        m = min(w, n - start)
        for j in range(w):
            valid[j] = -1 if j < m else 0
        for j in range(m):
            i = start + j
            pk[_DIR_X * w + j] = d[i, 0]
            pk[(_DIR_X + 1) * w + j] = d[i, 1]
            pk[(_DIR_X + 2) * w + j] = d[i, 2]
            pk[_TFAR * w + j] = tfar[i]
            ipk[_GEOM_ID * w + j] = -1
            for lev in range(2 * levels):
                ipk[(_INST_ID + lev) * w + j] = -1
        call(valid.ctypes.data, scene, pk.ctypes.data, 0)
        for j in range(m):
            i = start + j
            tfar[i] = pk[_TFAR * w + j]
            geom[i] = ipk[_GEOM_ID * w + j]
            prim[i] = ipk[_PRIM_ID * w + j] if ipk[_GEOM_ID * w + j] != -1 else -1
    return n
