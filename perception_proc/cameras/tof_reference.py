"""The depth camera's measurement model in its plain form: the readable reference of ``tof.incidence``,
``tof.flying_mask`` and ``tof.tof_depth`` (3-vector arrays, ``np.cross``, ``np.nanmin`` over a stack, 2-D fancy
indexing). ``tof`` computes the same numbers componentwise with fewer temporaries; tests/test_tof_kernel.py holds
the two equal to the bit.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from cosim.scenario.config.cameras import DepthCamera
from cosim.world.camera import Pinhole
from perception_proc.cameras.tof import axial_sigma, lateral_sigma_px

__all__ = ["incidence", "flying_mask", "tof_depth"]


def _smooth_side(p: np.ndarray, axis: int) -> np.ndarray:
    """The difference of neighbouring points (H, W, 3) along ``axis`` taken on the side whose depth changes
    least (forward or backward): at a depth edge each pixel keeps its own surface's tangent."""
    fwd = np.diff(p, axis=axis, append=np.take(p, [-1], axis=axis))
    bwd = np.diff(p, axis=axis, prepend=np.take(p, [0], axis=axis))
    first = [slice(None)] * 3
    first[axis] = 0
    last = list(first)
    last[axis] = -1
    fwd[tuple(last)] = bwd[tuple(last)]                 # the border pixels have one side only
    bwd[tuple(first)] = fwd[tuple(first)]
    with np.errstate(invalid="ignore"):
        use_fwd = np.abs(fwd[..., 2]) <= np.abs(bwd[..., 2])
    return np.where(use_fwd[..., None], fwd, bwd)


def incidence(pin: Pinhole, z: np.ndarray) -> np.ndarray:
    """Incidence angle (H, W) float64 rad between each pixel's ray and the surface normal, from planar depth
    ``z`` (H, W) m: the normal of the back-projected points' tangents, each taken towards the neighbour on the
    pixel's own side of a depth edge (:func:`_smooth_side`); NaN where ``z`` or both neighbours are not
    finite."""
    uu, vv = pin.pixel_centres()
    p = pin.backproject(uu, vv, z)
    n = np.cross(_smooth_side(p, 1), _smooth_side(p, 0))
    ray = p / np.linalg.norm(p, axis=2, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(np.einsum("hwi,hwi->hw", n, ray)) / np.linalg.norm(n, axis=2)
    return np.arccos(np.clip(cos, 0.0, 1.0))


def _neighbourhood(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) over each pixel's 3 x 3 neighbourhood of ``z`` (H, W), ignoring NaN (edge pixels use what
    they have); a pixel with no finite neighbour gets NaN."""
    h, w = z.shape
    pad = np.pad(z, 1, constant_values=np.nan)
    stack = np.stack([pad[i:i + h, j:j + w] for i in range(3) for j in range(3)])
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)              # all-NaN neighbourhoods give NaN
        return np.nanmin(stack, axis=0), np.nanmax(stack, axis=0)


def flying_mask(z: np.ndarray, edge_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels straddling a depth edge: (mask (H, W) bool, nearest (H, W), farthest (H, W) m of the 3 x 3
    neighbourhood). A pixel next to a miss (NaN) is on an edge too (its far side is the background)."""
    lo, hi = _neighbourhood(z)
    h, w = z.shape
    pad = np.pad(np.isfinite(z), 1, constant_values=True)
    next_to_miss = ~np.all(np.stack([pad[i:i + h, j:j + w] for i in range(3) for j in range(3)]), axis=0)
    with np.errstate(invalid="ignore"):
        mask = np.isfinite(z) & ((hi - lo > edge_m) | next_to_miss)
    return mask, lo, hi


def tof_depth(z: np.ndarray, pin: Pinhole, cam: DepthCamera, gen: np.random.Generator | None) -> np.ndarray:
    """The depth camera's reported planar depth (H, W) float32 m, NaN invalid, from the exact planar depth
    ``z`` (H, W) float32 (NaN no hit) of pinhole ``pin``. ``gen`` None (or ``cam.noise`` false): exact depth
    within the limits, no noise."""
    z = np.asarray(z, np.float64)
    theta = incidence(pin, z)
    out = z.copy()
    if gen is not None and cam.noise:
        h, w = z.shape
        sl = lateral_sigma_px(np.nan_to_num(theta, nan=0.0), cam)
        dv = np.rint(gen.standard_normal((h, w)) * sl).astype(np.int64)
        du = np.rint(gen.standard_normal((h, w)) * sl).astype(np.int64)
        rows = np.clip(np.arange(h)[:, None] + dv, 0, h - 1)
        cols = np.clip(np.arange(w)[None, :] + du, 0, w - 1)
        out = z[rows, cols]                                         # the depth of the laterally displaced point
        theta = theta[rows, cols]
        fly, near, far = flying_mask(z, cam.flying_edge_m)
        mix = gen.random((h, w))
        out = np.where(fly, near + mix * (np.where(np.isfinite(far), far, near) - near), out)
        with np.errstate(invalid="ignore"):
            out = out + gen.standard_normal((h, w)) * axial_sigma(out, np.nan_to_num(theta, nan=0.0), cam)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(out) | (out < cam.range_min_m) | (out > cam.range_max_m) | (
            theta > math.radians(cam.max_incidence_deg))
    out[bad] = np.nan
    return out.astype(np.float32)
