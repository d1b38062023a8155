"""A depth camera's own expected error (docs/cameras.md): per point, and of one controller cell's height at the
cart, so that perception gates points by it and withholds a height map the sensor cannot support.

* per point (perception drops a point whose 1-sigma exceeds :data:`GATE_SIGMA_M`): the stereo law
  sigma_Z = Z^2 sigma_d / (f B) with the matcher's expected disparity error sigma_d
  (:func:`disparity_sigma_px`: the profile's stated figure, which is SGBM's, times the matcher's measured
  :data:`MATCHER_DD_RATIO`), the depth camera's noise model at normal incidence
  (perception_proc.cameras.depth_models);
* per cell: a cell of ``cell_m`` seen at planar depth Z spans ``cell_m f / Z`` pixels each way; its height rests
  on n independent measurements, the cell's pixels divided into squares of the points' stride or, for stereo,
  of the matcher's block when larger (neighbouring windows share their pixels, so their errors are not
  independent): sigma_cell = sigma_Z / sqrt(n), n >= 1.

A sensor is fit for the target when sigma_cell at the cart is within :data:`FIT_SIGMAS` sigmas of the overfill
tolerance (``outcome.overfill_tolerance_m``): a cell's height then errs by more than the tolerance in about 2.5 %
of cells one way.
"""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config.cameras import Camera, DepthCamera, StereoCamera
from perception_proc.cameras.depth_models import normal_sigma_m

__all__ = ["FIT_SIGMAS", "GATE_SIGMA_M", "MATCHER_DD_RATIO", "disparity_sigma_px", "error_basis", "point_sigma_m",
           "cell_sigma_m", "cart_depth_m"]

#: the overfill tolerance must hold this many of a cell's expected 1-sigma
FIT_SIGMAS = 2.0
#: a point whose expected depth 1-sigma exceeds this is dropped: the rim finder's band and a cell's clusters are
#: a few decimetres deep, so such a point lands in the wrong one about as often as in its own, m (a quarter metre
#: already drops the far rim of a small-baseline module on the mast and it loses the cart)
GATE_SIGMA_M = 0.5

#: each matcher's disparity error over SGBM's on the same rendered pairs (the profiles' ``disparity_sigma_px`` is
#: SGBM's): dd fitted to dZ = Z^2 dd / (f B) over 3-9 m on the textured plane seen 40 deg down from 3 m, both
#: with the camera's texture check and sub-pixel refinement, ideal images; BM's is the larger of the packaged
#: profiles' (S21B 0.321 / 0.236 px, OAK-D 0.319 / 0.253 px): ``python bench/stereo_matchers.py``
MATCHER_DD_RATIO = {"sgbm": 1.0, "bm": 1.36}


def disparity_sigma_px(spec: StereoCamera) -> float:
    """The disparity 1-sigma (px) stereo camera ``spec`` is expected to hold with its matcher: its profile's
    stated (SGBM) figure times :data:`MATCHER_DD_RATIO` of its ``matcher``."""
    return spec.disparity_sigma_px * MATCHER_DD_RATIO[spec.matcher]


def error_basis(spec: Camera) -> str:
    """What a camera's expected error rests on, for a reason's sentence: "StereoBM, disparity 1-sigma 0.34 px"
    for a stereo camera, the model for a depth camera."""
    if isinstance(spec, StereoCamera):
        name = {"sgbm": "StereoSGBM", "bm": "StereoBM"}[spec.matcher]
        return f"{name}, disparity 1-sigma {disparity_sigma_px(spec):.2f} px"
    if isinstance(spec, DepthCamera):
        return f"{spec.model.replace('_', ' ')} model"
    return ""


def point_sigma_m(spec: Camera, focal_px: float, z_m):
    """Expected depth 1-sigma (m, like ``z_m``) of one pixel at planar depth ``z_m`` (m, scalar or array); 0 for a
    camera without depth."""
    z = np.asarray(z_m, np.float64)
    if isinstance(spec, StereoCamera):
        return z * z * disparity_sigma_px(spec) / (focal_px * spec.baseline_m)
    if isinstance(spec, DepthCamera):
        return normal_sigma_m(spec, z)
    return np.zeros_like(z)


def cell_sigma_m(spec: Camera, focal_px: float, stride: int, cell_m: float, z_m: float) -> float:
    """Expected 1-sigma of a ``cell_m`` cell's height (m) measured at planar depth ``z_m`` (m) from every
    ``stride``-th pixel (module docstring)."""
    side = max(stride, spec.block_size) if isinstance(spec, StereoCamera) else stride
    n = max(1.0, (cell_m * focal_px / z_m / side) ** 2)
    return float(point_sigma_m(spec, focal_px, z_m)) / math.sqrt(n)


def cart_depth_m(record: np.ndarray, level: np.ndarray, corners: np.ndarray) -> float:
    """Median planar depth (m) of a camera's points inside the cart's rim rectangle seen from above; NaN when none.
    ``record`` (M, 4) camera frame x y z range; ``level`` (M, 3) the same points in the level frame; ``corners``
    (4, 3) the rim's interior corners, level frame, in order around the rectangle."""
    ok = np.flatnonzero(np.isfinite(level[:, 0]))
    x, y = level[ok, 0], level[ok, 1]
    c = np.asarray(corners, np.float64)[:, :2]
    orientation = _orientation(c)
    inside = np.ones(ok.size, bool)
    for k in range(4):
        a, b = c[k], c[(k + 1) % 4]
        cross = (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0])
        inside &= cross * orientation >= 0.0
    z = record[ok[inside], 2]
    return float(np.median(z)) if z.size else math.nan


def _orientation(c: np.ndarray) -> float:
    """+1 for corners counter-clockwise in x-y, -1 clockwise."""
    area = sum(c[k, 0] * c[(k + 1) % 4, 1] - c[(k + 1) % 4, 0] * c[k, 1] for k in range(4))
    return 1.0 if area >= 0 else -1.0
