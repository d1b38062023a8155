"""The depth camera's structured-light measurement model (``model: structured_light``, docs/cameras.md): exact
rendered depth -> what a Kinect-class structured-light camera reports. Pure functions, seeded per frame; the
time-of-flight model (perception_proc.cameras.time_of_flight) shares its incidence and edge detection.

The noise model is Nguyen, Izadi and Lovell (2012), "Modeling Kinect Sensor Noise for Improved 3D
Reconstruction and Tracking" (3DIMPVT), with its coefficients as the record's defaults
(cosim.scenario.config.cameras.DepthCamera), z the planar depth (m), theta the incidence angle between the
pixel's ray and the surface normal:

* axial: sigma_z = a + b (z - z0)^2 m, plus c / sqrt(z) theta^2 / (pi/2 - theta)^2 beyond the grazing angle
  (60 deg in the paper);
* lateral: sigma_L = l0 + l1 theta / (pi/2 - theta) px: the pixel reads the depth of a point displaced by
  that much in the image (its Gaussian displacement is drawn per pixel and rounded to the nearest pixel).

On top of it, as the device class does: a pixel whose 3 x 3 neighbourhood of exact depth spans more than
``flying_edge_m`` straddles a depth edge and reports a mixture of its nearest and farthest neighbour, a
uniform draw between them ("flying pixels", the mixed returns of a pixel footprint across an edge); pixels
beyond ``max_incidence_deg``, outside ``range_min_m`` .. ``range_max_m`` or with no hit are invalid (NaN).
The incidence comes from the exact depth image (normals of its back-projected points, each tangent taken on
the pixel's own side of a depth edge), so it is the renderer's geometry, not an estimate from the noisy data. ``noise: false`` keeps the exact depth and applies
only the range limits.
"""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config.cameras import DepthCamera
from cosim.world.camera import Pinhole

__all__ = ["TOF_STREAM", "frame_generator", "incidence", "axial_sigma", "lateral_sigma_px", "flying_mask",
           "tof_depth"]

#: third seed word of the depth-camera noise stream (separate from the LiDAR's and the accuracy sample's)
TOF_STREAM = 0x544F4644  # "TOFD"


def frame_generator(seed: int, frame: int, sensor_index: int) -> np.random.Generator:
    """The noise generator of one camera's frame: PCG64 seeded by (seed, frame, TOF_STREAM, sensor index)."""
    return np.random.default_rng([int(seed), int(frame), TOF_STREAM, int(sensor_index)])


def _smooth_side(p: tuple, axis: int) -> tuple:
    """The difference of neighbouring points (x, y, z components, each (H, W)) along ``axis`` taken on the side
    whose depth changes least (forward or backward): at a depth edge each pixel keeps its own surface's tangent.
    The border pixels have one side only. Each difference ``d`` is taken once: pixel i's forward one is d[i],
    its backward one d[i - 1]."""
    def cut(a: np.ndarray, start: int, stop: int | None) -> np.ndarray:
        idx = [slice(None)] * a.ndim
        idx[axis] = slice(start, stop)
        return a[tuple(idx)]

    d = [cut(c, 1, None) - cut(c, 0, -1) for c in p]
    with np.errstate(invalid="ignore"):
        use_fwd = np.abs(cut(d[2], 1, None)) <= np.abs(cut(d[2], 0, -1))
    out = []
    for dc in d:
        t = np.empty_like(p[0])
        cut(t, 1, -1)[...] = np.where(use_fwd, cut(dc, 1, None), cut(dc, 0, -1))
        cut(t, 0, 1)[...] = cut(dc, 0, 1)
        cut(t, -1, None)[...] = cut(dc, -1, None)
        out.append(t)
    return tuple(out)


def incidence(pin: Pinhole, z: np.ndarray) -> np.ndarray:
    """Incidence angle (H, W) float64 rad between each pixel's ray and the surface normal, from planar depth
    ``z`` (H, W) m: the normal of the back-projected points' tangents, each taken towards the neighbour on the
    pixel's own side of a depth edge (:func:`_smooth_side`); NaN where ``z`` or both neighbours are not
    finite. Componentwise (x, y, z arrays): the arithmetic of ``Pinhole.backproject``, ``np.cross``,
    ``np.linalg.norm`` and ``np.einsum`` to the bit (``tof_reference.incidence`` is the plain form, tested against this)."""
    uu, vv = pin.pixel_centres()
    z = np.asarray(z, dtype=np.float64)
    s = z / pin.f
    p = (s * (uu - pin.width / 2.0), s * (pin.height / 2.0 - vv), z)
    (a0, a1, a2), (b0, b1, b2) = _smooth_side(p, 1), _smooth_side(p, 0)
    n0, n1, n2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    r = np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    with np.errstate(invalid="ignore", divide="ignore"):
        # the dot product is einsum's over a last axis, whose rounding a plain sum of products does not match
        dot = np.einsum("hwi,hwi->hw", np.stack([n0, n1, n2], axis=-1), np.stack([c / r for c in p], axis=-1))
        cos = np.abs(dot) / np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    return np.arccos(np.clip(cos, 0.0, 1.0))


def axial_sigma(z: np.ndarray, theta: np.ndarray, cam: DepthCamera) -> np.ndarray:
    """Axial 1-sigma (m) at planar depth ``z`` (m) and incidence ``theta`` (rad), Nguyen et al. 2012."""
    s = cam.axial_a_m + cam.axial_b_per_m * (z - cam.axial_z0_m) ** 2
    graze = theta > math.radians(cam.grazing_from_deg)
    with np.errstate(invalid="ignore", divide="ignore"):
        extra = cam.axial_grazing_m / np.sqrt(z) * theta**2 / (np.pi / 2.0 - theta) ** 2
    return np.where(graze, s + extra, s)


def lateral_sigma_px(theta: np.ndarray, cam: DepthCamera) -> np.ndarray:
    """Lateral 1-sigma (px) at incidence ``theta`` (rad), Nguyen et al. 2012."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return cam.lateral_px + cam.lateral_grazing_px * theta / (np.pi / 2.0 - theta)


def _shifted(pad: np.ndarray, shape: tuple[int, int]):
    """The 9 views of the 3 x 3 neighbourhood of every pixel in ``pad`` (the image padded by 1)."""
    h, w = shape
    return (pad[i:i + h, j:j + w] for i in range(3) for j in range(3))


def _neighbourhood(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) over each pixel's 3 x 3 neighbourhood of ``z`` (H, W), ignoring NaN (edge pixels use what
    they have); a pixel with no finite neighbour gets NaN. ``np.fmin`` / ``np.fmax`` over the 9 views (what
    ``np.nanmin`` / ``np.nanmax`` of their stack compute, without the stack)."""
    views = list(_shifted(np.pad(z, 1, constant_values=np.nan), z.shape))
    lo, hi = views[0].copy(), views[0].copy()
    for v in views[1:]:
        np.fmin(lo, v, out=lo)
        np.fmax(hi, v, out=hi)
    return lo, hi


def flying_mask(z: np.ndarray, edge_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels straddling a depth edge: (mask (H, W) bool, nearest (H, W), farthest (H, W) m of the 3 x 3
    neighbourhood). A pixel next to a miss (NaN) is on an edge too (its far side is the background)."""
    lo, hi = _neighbourhood(z)
    seen = np.ones(z.shape, bool)
    for v in _shifted(np.pad(np.isfinite(z), 1, constant_values=True), z.shape):
        seen &= v
    with np.errstate(invalid="ignore"):
        mask = np.isfinite(z) & ((hi - lo > edge_m) | ~seen)
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
        at = rows * w + cols                                        # flat index of the laterally displaced point
        out = np.take(z, at)                                        # its depth
        theta = np.take(theta, at)
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
