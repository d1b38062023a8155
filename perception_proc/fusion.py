"""Several sensors' points merged into the one input of the built-in algorithm (docs/cameras.md).

The built-in stages work on points in the level frame, whichever sensor made them, so fusing is merging:
the LiDAR's returns, then every depth-giving camera's back-projected pixels in declaration order, one point
cloud with each point's range and border flags (the flags of its own sensor's grid). Points on the vehicle
that carries the sensors (its body box in the level frame, known like its GNSS pose) are dropped, as the
LiDAR's are (perception_proc.pipeline.own_vehicle_box).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["mask_box", "merge"]


def mask_box(rows: np.ndarray, box: tuple[np.ndarray, np.ndarray] | None) -> None:
    """Set to NaN, in place, the columns of ``rows`` (3, N) float64 (level-frame x, y, z rows) that lie in
    ``box`` (lo (3,), hi (3,)) m; nothing when ``box`` is None."""
    if box is None or rows.shape[1] == 0:
        return
    lo, hi = box
    with np.errstate(invalid="ignore"):
        inside = np.all((rows >= lo[:, None]) & (rows <= hi[:, None]), axis=0)
    rows[:, inside] = np.nan


def merge(points: Sequence[np.ndarray], ranges: Sequence[np.ndarray], borders: Sequence[np.ndarray],
          box: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One cloud of several sensors' level-frame ``points`` [(N_k, 3)], ``ranges`` [(N_k,) m] and ``borders``
    [(N_k,) uint8]: (points (N, 3) float64, column-major like ``PerceptionInput.points``; ranges (N,) float32;
    border (N,) uint8), N = sum N_k, in the given order; points in ``box`` (the own vehicle) are NaN."""
    n = sum(len(p) for p in points)
    rows = np.empty((3, n))
    k = 0
    for p in points:
        rows[:, k:k + len(p)] = np.asarray(p, np.float64).T
        k += len(p)
    mask_box(rows, box)
    r = np.concatenate([np.asarray(x, np.float32) for x in ranges]) if ranges else np.zeros(0, np.float32)
    b = np.concatenate([np.asarray(x, np.uint8) for x in borders]) if borders else np.zeros(0, np.uint8)
    return rows.T, r, b
