"""Accuracy of the perception stage against truth (docs/CONTRACTS.md, docs/architecture.md).

Pure functions. Range errors compare each beam's noise-free range with the exact range of the same beam from
the LiDAR origin (an exact ray cast of the same scene: ``cosim.world.raycast``); a beam counts when both
are valid and within the sensor's range limits. The other measures compare the perceived rim corners, height
map and impact with the dynamics' ground truth. Truth never feeds the estimates: these functions are called
after the frame's outputs are computed.

Sampling: an evaluation need not cast every beam. :func:`sample_beams` draws one beam uniformly from each of
``count`` equal runs of the beam table (row-major for the grid and honeycomb patterns, so a run is a short
stretch of one row and the sample covers the whole field evenly), seeded by the scenario seed and the frame:
reproducible, and a different sample each evaluated frame, so a run's statistics cover every part of the
field. Each frame's statistics then carry a sampling error: about s / sqrt(n) for a mean (s the spread of the
per-beam errors, n the compared beams; stratification only lowers it) and sqrt(p (1 - p) / n) for a share p.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from cosim.scenario.config import Cart, Scenario
from cosim.world.geometry import apply, cart_body_from_grid, entity_pose, invert
from perception_proc.blocks import RANGE_BANDS_M, band_name
from perception_proc.orderstats import median_sorted, percentile_sorted

__all__ = ["range_error_stats", "exact_ranges", "sample_beams", "ACCURACY_STREAM", "true_corners_sensor", "corner_error", "truth_on_grid",
           "heightmap_error", "impact_error", "world_from_parent", "ABOVE_M", "WORKING_RANGE_M"]

#: the "large error" threshold of the range statistics, m
ABOVE_M = 0.05
#: the working range inside which the accuracy target applies, m
WORKING_RANGE_M = (2.0, 15.0)
#: the percentile of the range-error statistics
P99 = 99.0
#: fixed third seed word that separates the accuracy sample from any other use of (seed, frame)
ACCURACY_STREAM = 0x41434355  # "ACCU"


def sample_beams(n_beams: int, count: int, seed: int, frame: int) -> np.ndarray:
    """Beam indices (min(count, N),) int64, ascending: one drawn uniformly from each of ``count`` equal runs of
    consecutive beams (stratified sample), PCG64 seeded by (seed, frame, ACCURACY_STREAM). ``count`` 0 or at
    least ``n_beams``: every beam."""
    if count <= 0 or count >= n_beams:
        return np.arange(n_beams, dtype=np.int64)
    edges = (np.arange(count + 1, dtype=np.int64) * n_beams) // count
    gen = np.random.default_rng([int(seed), int(frame), ACCURACY_STREAM])
    return edges[:-1] + (gen.random(count) * np.diff(edges)).astype(np.int64)


def range_error_stats(ranges: np.ndarray, exact: np.ndarray, range_min_m: float, range_max_m: float) -> dict:
    """Statistics of |ranges - exact| per beam. ``ranges`` (N,) m NaN invalid; ``exact`` (N,) m, inf on a miss.

    Returns the ``perc_state`` accuracy fields for ranges (NaN where a band holds no beam)."""
    r = np.asarray(ranges, np.float64)
    x = np.asarray(exact, np.float64)
    truth_ok = np.isfinite(x) & (x >= range_min_m) & (x <= range_max_m)
    ours_ok = np.isfinite(r)
    both = truth_ok & ours_ok
    err = np.abs(r[both] - x[both])
    dist = x[both]
    out: dict[str, float] = {
        "range_beams": float(both.sum()),
        "beam_missing_frac": float(np.count_nonzero(truth_ok & ~ours_ok) / max(truth_ok.sum(), 1)),
        "beam_spurious_frac": float(np.count_nonzero(ours_ok & ~truth_ok) / max(ours_ok.sum(), 1)),
    }
    nan = math.nan

    def mean_above(e: np.ndarray) -> tuple[float, float]:
        """Mean error and share above :data:`ABOVE_M` (NaN when empty)."""
        if e.size == 0:
            return nan, nan
        return float(e.mean()), float(np.count_nonzero(e > ABOVE_M) / e.size)

    # order statistics from one sort each (the values numpy's median, percentile and max give)
    s = np.sort(err)
    out["range_err_mean_m"], out["frac_above_5cm"] = mean_above(err)
    out["range_err_median_m"] = median_sorted(s)
    out["range_err_p99_m"] = percentile_sorted(s, P99)
    out["range_err_max_m"] = float(s[-1]) if s.size else nan
    lo, hi = WORKING_RANGE_M
    working = err[(dist >= lo) & (dist < hi)]
    out["range_err_mean_2_15_m"], out["frac_above_5cm_2_15"] = mean_above(working)
    out["range_err_p99_2_15_m"] = percentile_sorted(np.sort(working), P99)
    for lo, hi in RANGE_BANDS_M:
        e = err[(dist >= lo) & (dist < hi)]
        b = band_name(lo, hi)
        out[f"rerr_{b}_n"] = float(e.size)
        out[f"rerr_{b}_mean_m"], out[f"rerr_{b}_above5_frac"] = mean_above(e)
        out[f"rerr_{b}_p99_m"] = percentile_sorted(np.sort(e), P99)
    return out


def world_from_parent(scenario: Scenario, state: Mapping[str, float]) -> np.ndarray:
    """world_from_body (4 x 4) of the sensor's parent entity from dyn_state fields (identity for 'world')."""
    parent = scenario.lidar.mount.parent
    if parent == "world":
        return np.eye(4)
    return entity_pose(state, parent)


def exact_ranges(scenario: Scenario, state: Mapping[str, float], heightmap_truth: np.ndarray,
                 stream: np.ndarray, world_from_sensor: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Exact range (N,) float64 m (inf on a miss) of every beam, by the renderer's ray caster on the scene
    the renderer drew (``cosim.world.fastcast``: Embree when installed, else the numpy ray cast).
    ``directions`` (N, 3) unit beams in the sensor frame."""
    from cosim.world.fastcast import cast_from  # lazily: only accuracy frames need the scene
    from cosim.world.scene import scene_from_state

    scene = scene_from_state(scenario, state, heightmap_truth, stream)
    return cast_from(scene, world_from_sensor[:3, 3], directions @ world_from_sensor[:3, :3].T)


def true_corners_sensor(cart: Cart, state: Mapping[str, float], world_from_sensor: np.ndarray) -> np.ndarray:
    """The true rim corners (4, 3) m in the sensor frame, grid order (front-left, rear-left, rear-right,
    front-right at rim-top height)."""
    L, W = cart.interior_length_m, cart.interior_width_m
    zr = cart.interior_depth_m + cart.rim_height_m
    g = np.array([[0, 0, zr], [L, 0, zr], [L, W, zr], [0, W, zr]], dtype=np.float64)
    world_from_grid = entity_pose(state, "cart") @ cart_body_from_grid(cart)
    return apply(invert(world_from_sensor) @ world_from_grid, g)


def corner_error(est: np.ndarray, truth: np.ndarray) -> float:
    """Mean distance (m) between estimated and true corners (4, 3), same order; NaN if any estimate is NaN."""
    d = np.linalg.norm(np.asarray(est, np.float64) - truth, axis=1)
    return float(d.mean()) if np.all(np.isfinite(d)) else math.nan


def truth_on_grid(truth: np.ndarray, truth_cell_m: float, shape: tuple[int, int], cart: Cart) -> np.ndarray:
    """The true height map (grain grid, ``truth_cell_m``) sampled at the centres of a grid of ``shape`` over
    the same interior (nearest truth cell); (nx, ny) float64 m."""
    nx, ny = shape
    tx, ty = truth.shape
    cx = (np.arange(nx) + 0.5) * cart.interior_length_m / nx
    cy = (np.arange(ny) + 0.5) * cart.interior_width_m / ny
    i = np.clip((cx / truth_cell_m).astype(np.int64), 0, tx - 1)
    j = np.clip((cy / truth_cell_m).astype(np.int64), 0, ty - 1)
    return np.asarray(truth, np.float64)[np.ix_(i, j)]


def heightmap_error(perceived: np.ndarray, truth_grid: np.ndarray) -> tuple[float, float, float]:
    """(rmse m, bias m, coverage) of a perceived map against the truth on the same grid; RMSE and bias over
    cells with a perceived height (NaN when there is none), coverage the share of such cells."""
    p = np.asarray(perceived, np.float64)
    ok = np.isfinite(p) & np.isfinite(truth_grid)
    cov = float(np.count_nonzero(np.isfinite(p)) / p.size)
    if not ok.any():
        return math.nan, math.nan, cov
    e = p[ok] - truth_grid[ok]
    return float(np.sqrt(np.mean(e**2))), float(e.mean()), cov


def impact_error(est_grid_xyz: np.ndarray, state: Mapping[str, float]) -> float:
    """Horizontal distance (m, cart grid frame) between the perceived and the true impact; NaN when either is
    missing. The truth is ``dyn_state.impact_g{x,y}_m`` with ``impact_valid``."""
    if not int(state.get("impact_valid", 0)) or not np.all(np.isfinite(est_grid_xyz[:2])):
        return math.nan
    dx = est_grid_xyz[0] - float(state["impact_gx_m"])
    return float(math.hypot(dx, est_grid_xyz[1] - float(state["impact_gy_m"])))
