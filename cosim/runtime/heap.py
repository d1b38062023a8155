"""Keep freed memory in the process heap, so per-frame arrays reuse warm pages (glibc ``mallopt``).

A frame's numpy temporaries of more than 128 KiB (a LiDAR frame's 38,400 float64 ranges are 300 KiB) are, by
glibc's defaults, each mapped fresh from the kernel and unmapped when freed, and the heap's top is trimmed back
to the kernel: every frame then pays a page fault and a zeroed page for every 4 KiB it touches, which costs
more than the arithmetic on those pages (``bench/HISTORY.md``: the mock renderer's float64 re-intersection,
2.4 ms of page faults against 0.8 ms of work). :func:`keep_heap` raises the mmap threshold and the trim threshold
so that such blocks come from the heap and stay there between frames; the process's memory then peaks at its
largest frame's working set. Called at the start of every ring member (``cosim.runtime.child``); a no-op where
the C library has no ``mallopt`` (not glibc).
"""
from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["MMAP_THRESHOLD_B", "TOP_PAD_B", "TRIM_THRESHOLD_B", "keep_heap"]

#: mallopt parameters (glibc malloc.h)
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3
#: blocks below this come from the heap, not from their own mapping, bytes (glibc's largest allowed value on
#: 64-bit is 32 MiB; a frame's largest temporaries are a few MiB)
MMAP_THRESHOLD_B = 32 << 20
#: the heap's free top is given back to the kernel only beyond this, bytes
TRIM_THRESHOLD_B = 256 << 20
#: extra bytes taken from the kernel whenever the heap grows, bytes
TOP_PAD_B = 16 << 20


def keep_heap() -> bool:
    """Set the thresholds above for this process; True where ``mallopt`` took all three."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return all(mallopt(param, value) == 1 for param, value in (
        (_M_MMAP_THRESHOLD, MMAP_THRESHOLD_B), (_M_TRIM_THRESHOLD, TRIM_THRESHOLD_B), (_M_TOP_PAD, TOP_PAD_B)))
