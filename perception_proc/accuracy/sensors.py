"""Accuracy of each sensor against truth (docs/cameras.md): a camera's depth against the exact ray cast of the
same pixels, and the height map one sensor alone gives against the true heights. Pure functions; called after
the frame's outputs are computed, so truth never feeds an estimate.

Depth error: the measured planar depth of a stratified, seeded sample of pixels (one per equal run of the
row-major image, as ``perception_proc.accuracy.stage.sample_beams`` draws beams) against the exact planar depth of
the same pixel centres' rays; a pixel counts when both are valid and the exact depth lies in the camera's
working range (``range_min_m`` .. ``range_max_m``). Coverage is the share of pixels with an exact depth in
that range that have a measured depth; spurious, the share of measured depths where the exact cast has none
in range.

Fill height: the sensor's own points gridded by the height map stage in the frame's perceived cart, against
the true heights on the same grid: mean |h - h_true| / h_true (h_true > 0) and mean h - h_true over the cells
it maps (the relative pile-height error of stereo fill measurement studies).
"""
from __future__ import annotations

import math

import numpy as np

from cosim.world.camera import Pinhole
from perception_proc.accuracy.stage import ABOVE_M, P99, sample_beams
from perception_proc.orderstats import median_sorted, percentile_sorted

__all__ = ["sample_pixels", "exact_depths", "depth_error_stats", "fill_error", "NAN_STATS", "NAN_FILL"]

#: the depth-error fields when nothing is evaluated
NAN_STATS = {"depth_pixels": math.nan, "depth_err_mean_m": math.nan, "depth_err_median_m": math.nan,
             "depth_err_p99_m": math.nan, "frac_above_5cm": math.nan, "coverage": math.nan,
             "spurious_frac": math.nan}
#: the fill-height fields when nothing is evaluated
NAN_FILL = {"fill_rel_err": math.nan, "fill_bias_m": math.nan, "fill_cells": math.nan}


def sample_pixels(pin: Pinhole, count: int, seed: int, frame: int) -> np.ndarray:
    """Flat pixel indices (K,) int64 of a stratified sample of ``count`` pixels (0: every pixel), seeded by
    (seed, frame) as :func:`perception_proc.accuracy.stage.sample_beams`."""
    return sample_beams(pin.width * pin.height, count, seed, frame)


def exact_depths(scene, world_from_camera: np.ndarray, pin: Pinhole, pixels: np.ndarray) -> np.ndarray:
    """Exact planar depth (K,) float64 m (inf on a miss) of the pixel centres ``pixels`` (K,) (flat, row-major)
    of a camera at ``world_from_camera`` (4, 4), by the exact ray cast (``cosim.world.fastcast``)."""
    from cosim.world.fastcast import cast_from  # lazily: only evaluated frames build the scene

    d_cam = pin.ray_directions_at(pixels)
    t = cast_from(scene, world_from_camera[:3, 3], d_cam @ world_from_camera[:3, :3].T)
    return t * d_cam[:, 2]


def depth_error_stats(measured: np.ndarray, exact: np.ndarray, lo_m: float, hi_m: float) -> dict:
    """The depth-error fields of ``sensor_<name>`` from measured (K,) m (NaN invalid) and exact (K,) m (inf
    miss) depths of the same pixels, in the working range [``lo_m``, ``hi_m``]."""
    m = np.asarray(measured, np.float64)
    x = np.asarray(exact, np.float64)
    truth = np.isfinite(x) & (x >= lo_m) & (x <= hi_m)
    ours = np.isfinite(m)
    both = truth & ours
    err = np.sort(np.abs(m[both] - x[both]))
    out = dict(NAN_STATS)
    out["depth_pixels"] = float(err.size)
    out["coverage"] = float(np.count_nonzero(both) / truth.sum()) if truth.any() else math.nan
    out["spurious_frac"] = float(np.count_nonzero(ours & ~truth) / ours.sum()) if ours.any() else math.nan
    if err.size:
        out["depth_err_mean_m"] = float(err.mean())
        out["depth_err_median_m"] = median_sorted(err)
        out["depth_err_p99_m"] = percentile_sorted(err, P99)
        out["frac_above_5cm"] = float(np.count_nonzero(err > ABOVE_M) / err.size)
    return out


def fill_error(heights: np.ndarray, truth_grid: np.ndarray) -> dict:
    """The fill-height fields of ``sensor_<name>``: a sensor's own height map (nx, ny) m (NaN unknown) against
    the true heights on the same grid."""
    h = np.asarray(heights, np.float64)
    t = np.asarray(truth_grid, np.float64)
    ok = np.isfinite(h) & np.isfinite(t) & (t > 0.0)
    if not ok.any():
        return {**NAN_FILL, "fill_cells": 0.0}
    return {"fill_rel_err": float(np.mean(np.abs(h[ok] - t[ok]) / t[ok])),
            "fill_bias_m": float(np.mean(h[ok] - t[ok])), "fill_cells": float(ok.sum())}
