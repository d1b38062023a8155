"""Impact location of the grain stream on the grain surface, from stream returns and the height map.

All in the cart grid frame (m). The stream returns (``HeightMap.stream``) are clustered top-down around their
median; the lowest :data:`FIT_SPAN_M` of the stream is fitted with a straight line x(z), y(z) (least squares;
the stream is near vertical there). The surface height at the stream is the highest grain cell within
``search_radius`` of the stream's foot (the pile peaks under the stream, and the cell right under it is hidden
by the stream), capped by the lowest stream return (the stream cannot be seen below the surface). The impact
is the fitted line at that height. No stream returns (auger off), too few, or no grain cell near the foot:
no answer.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from perception_proc.orderstats import median_sorted, percentile_sorted

__all__ = ["Impact", "find_impact", "blank_under_stream", "line_fits", "MIN_STREAM_POINTS", "FIT_SPAN_M", "CLUSTER_RADIUS_M"]

#: fewest stream returns for an answer
MIN_STREAM_POINTS = 6
#: height of the lowest part of the stream used for the line fit, m
FIT_SPAN_M = 1.0
#: stream returns farther than this (top-down) from their median are not the stream, m
CLUSTER_RADIUS_M = 1.0
#: mean distance, in radii, of a cylinder's visible returns in front of its axis (returns uniform across the
#: projected width: pi/4)
FACE_TO_AXIS = math.pi / 4.0
#: below this vertical spread the stream is taken as vertical through its mean, m
MIN_FIT_SPREAD_M = 0.2
#: percentile of the low returns' distances from the fitted axis taken as the stream's visible half-width
RADIUS_PERCENTILE = 90.0


@dataclass(frozen=True)
class Impact:
    """``valid``; ``xyz`` (3,) float64 m in the grid frame (NaN when not valid); ``n_points`` stream returns
    used; ``reason`` why there is no answer ('' when valid); ``radius_m`` the stream's visible half-width (the
    90th percentile distance of its low returns from the fitted axis), NaN when there is no stream."""

    valid: bool
    xyz: np.ndarray
    n_points: int
    reason: str
    radius_m: float = math.nan


def _none(reason: str, n: int = 0) -> Impact:
    return Impact(False, np.full(3, np.nan), n, reason)


def blank_under_stream(heights: np.ndarray, impact: Impact, cell_m: tuple[float, float]) -> int:
    """Set to NaN (in place) the cells the stream hides: centres within 2 radius + half a cell diagonal of
    the impact point (the fitted axis runs through the stream's visible face, up to a radius off its centre).
    ``heights`` (nx, ny) m. Returns the number of cells blanked (0 without a valid impact)."""
    if not impact.valid or not math.isfinite(impact.radius_m):
        return 0
    nx, ny = heights.shape
    dx, dy = cell_m
    reach = 2.0 * impact.radius_m + 0.5 * math.hypot(dx, dy)
    cx = (np.arange(nx) + 0.5) * dx
    cy = (np.arange(ny) + 0.5) * dy
    hide = (cx[:, None] - impact.xyz[0]) ** 2 + (cy[None, :] - impact.xyz[1]) ** 2 <= reach**2
    hide &= np.isfinite(heights)
    heights[hide] = np.nan
    return int(np.count_nonzero(hide))


def _polyval(coef: tuple, x):
    """``np.polyval(coef, x)`` of a line (a, b), the same operations (Horner from zero: (0 x + a) x + b), on a
    float or an array, without its argument handling."""
    a, b = coef
    return (0.0 * x + a) * x + b


def line_fits(z: np.ndarray, ys: tuple[np.ndarray, ...]) -> list[tuple]:
    """``tuple(np.polyfit(z, y, 1))`` (slope, intercept) for each y of ``ys`` (M,) over the same ``z`` (M,), M >= 2:
    numpy's own steps (the column-scaled Vandermonde matrix, ``lstsq`` at polyfit's rcond, the solution
    unscaled, its rank warning), with the matrix and its scale built once for all of them: the same numbers
    (tested against ``np.polyfit``) for about two thirds of the instructions of two polyfits."""
    x = np.asarray(z) + 0.0
    lhs = np.vander(x, 2)
    scale = np.sqrt((lhs * lhs).sum(axis=0))
    lhs /= scale
    rcond = len(x) * np.finfo(x.dtype).eps
    fits = []
    for y in ys:
        c, _, rank, _ = np.linalg.lstsq(lhs, np.asarray(y) + 0.0, rcond)
        if rank != 2:
            warnings.warn("Polyfit may be poorly conditioned", np.exceptions.RankWarning, stacklevel=2)
        fits.append(tuple((c.T / scale).T))
    return fits


def find_impact(grid_points: np.ndarray, stream: np.ndarray, heights: np.ndarray, cell_m: tuple[float, float],
                search_radius_m: float, sensor_xy: tuple[float, float] | None = None) -> Impact:
    """Impact point from ``grid_points`` (M, 3) grid frame, their ``stream`` flags (M,) bool, the height map
    ``heights`` (nx, ny) m (NaN holes) with cell sizes ``cell_m`` (dx, dy) m. ``sensor_xy``: the LiDAR origin
    in the grid frame (m); the stream's returns lie on its near face, so the fitted line is moved away from
    the sensor by :data:`FACE_TO_AXIS` stream radii (None: no correction)."""
    # the stream returns (K, 3), gathered from the coordinate rows of the column-major points (np.take on
    # the column-major array itself would first copy all of it to row-major)
    s = np.take(np.asarray(grid_points, dtype=np.float64).T, np.flatnonzero(stream), axis=1).T
    if s.shape[0] < MIN_STREAM_POINTS:
        return _none(f"{s.shape[0]} stream returns, need {MIN_STREAM_POINTS}", s.shape[0])
    med = np.array([median_sorted(np.sort(s[:, k])) for k in (0, 1)])
    s = s[np.hypot(*(s[:, :2] - med).T) <= CLUSTER_RADIUS_M]
    if s.shape[0] < MIN_STREAM_POINTS:
        return _none("stream returns too scattered", s.shape[0])
    z_low = float(s[:, 2].min())
    low = s[s[:, 2] <= z_low + FIT_SPAN_M]
    z = low[:, 2]
    if np.ptp(z) < MIN_FIT_SPREAD_M or low.shape[0] < 3:
        coef_x, coef_y = (0.0, float(low[:, 0].mean())), (0.0, float(low[:, 1].mean()))
    else:
        coef_x, coef_y = line_fits(z, (low[:, 0], low[:, 1]))
    foot = np.array([_polyval(coef_x, z_low), _polyval(coef_y, z_low)])
    nx, ny = heights.shape
    dx, dy = cell_m
    cx = (np.arange(nx) + 0.5) * dx
    cy = (np.arange(ny) + 0.5) * dy
    near = (cx[:, None] - foot[0]) ** 2 + (cy[None, :] - foot[1]) ** 2 <= search_radius_m**2
    vals = heights[near & np.isfinite(heights)]
    if vals.size == 0:
        return _none("no grain height near the stream foot", s.shape[0])
    z_imp = min(float(vals.max()), z_low)
    xyz = np.array([_polyval(coef_x, z_imp), _polyval(coef_y, z_imp), z_imp])
    if not np.all(np.isfinite(xyz)) or math.isnan(z_imp):
        return _none("fit failed", s.shape[0])
    off = np.hypot(low[:, 0] - _polyval(coef_x, z), low[:, 1] - _polyval(coef_y, z))    # from the fitted axis
    radius = percentile_sorted(np.sort(off), RADIUS_PERCENTILE)
    if sensor_xy is not None:
        away = xyz[:2] - np.asarray(sensor_xy, dtype=np.float64)
        norm = float(np.hypot(*away))
        if norm > 0:
            xyz[:2] += FACE_TO_AXIS * radius * away / norm
    return Impact(True, xyz, int(s.shape[0]), "", radius)
