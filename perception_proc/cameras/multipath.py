"""Multipath of a time-of-flight camera (``multipath: true`` of a ``model: time_of_flight`` depth camera,
docs/cameras.md): light of the camera's own source that reaches a surface by way of another one adds a longer
path to the pixel's return, so concave scenes (a cart's inside, a corner) read too far. Pure functions.

The one-bounce diffuse model of Fuchs (2010, "Multipath interference compensation in time-of-flight camera
images", ICPR): the scene is cut into patches (:data:`PATCH_PX` square blocks of the exact depth image), each a
Lambertian surface of the camera's ``albedo`` with its point P (m), unit normal n and area a (m^2), lit by a point
source at the camera. Patch i receives E_i = cos(theta_i) / r_i^2 directly and passes on to patch j the irradiance

    E_ij = albedo E_i a_i cos(out_ij) cos(in_ij) / (pi d_ij^2)

(d_ij the distance between the patches, out_ij and in_ij the angles of the line between them to n_i and n_j; only
pairs that face each other, cos > 0 at both ends). Both reach the camera by j's reflection, so the pixel's return
mixes the direct path 2 r_j with weight E_j and the detours r_i + d_ij + r_j with weights E_ij. Its range is the
weighted mean of the half path lengths (:func:`multipath_range_bias`), the low-frequency limit of the phasor sum;
at a real modulation frequency a detour's phase shift is sin(phi) for phi, smaller, so this is the upper end of the
bias for the given amplitudes. Not modelled: occlusion between patches (every facing pair sees each other), more
than one bounce, specular reflection.
"""
from __future__ import annotations

import numpy as np

from cosim.world.camera import Pinhole

__all__ = ["PATCH_PX", "MAX_PATCHES", "patch_size", "patches", "multipath_range_bias", "pixel_range_bias"]

#: side of the square block of pixels one patch stands for, at least, px
PATCH_PX = 16
#: most patches of an image: the pairs cost N^2 (1024 patches: about 8 MB a temporary, 0.1-0.3 s a frame)
MAX_PATCHES = 1024


def patch_size(height: int, width: int) -> int:
    """The block side (px) for an image of ``height`` x ``width``: :data:`PATCH_PX`, or larger so that there are
    at most :data:`MAX_PATCHES` blocks."""
    return max(PATCH_PX, int(np.ceil(np.sqrt(height * width / MAX_PATCHES))))


def patches(pin: Pinhole, z: np.ndarray, size: int = PATCH_PX) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scene's patches from planar depth ``z`` (H, W) m (NaN no hit): (points (N, 3) m, unit normals (N, 3)
    facing the camera, areas (N,) m^2), camera frame (X right, Y up, Z forward), one per ``size`` x ``size`` block
    whose pixels all hit; the block's mean point, the normal of its least-squares plane, its pixels' footprint
    (z / f)^2 per pixel over cos(incidence). Rows of a block with a miss are NaN."""
    h, w = z.shape
    uu, vv = pin.pixel_centres()
    zz = np.asarray(z, np.float64)
    pts = np.stack([zz * (uu - w / 2.0) / pin.f, zz * (h / 2.0 - vv) / pin.f, zz], axis=-1)
    hb, wb = h // size, w // size
    blocks = pts[:hb * size, :wb * size].reshape(hb, size, wb, size, 3).transpose(0, 2, 1, 3, 4)
    blocks = blocks.reshape(hb * wb, size * size, 3)
    centre = blocks.mean(axis=1)                                            # NaN where any pixel missed
    dev = blocks - centre[:, None, :]
    cov = np.einsum("nki,nkj->nij", np.nan_to_num(dev), np.nan_to_num(dev))
    _, vecs = np.linalg.eigh(cov)
    normal = vecs[:, :, 0]                                                  # the smallest spread: the normal
    normal *= -np.sign(np.einsum("ni,ni->n", normal, centre))[:, None]      # facing the camera
    r = np.linalg.norm(centre, axis=1)
    cos = np.abs(np.einsum("ni,ni->n", normal, centre)) / r
    with np.errstate(invalid="ignore", divide="ignore"):
        area = size * size * (centre[:, 2] / pin.f) ** 2 / cos
    return centre, normal, area


def multipath_range_bias(points: np.ndarray, normals: np.ndarray, areas: np.ndarray, albedo: float
                         ) -> np.ndarray:
    """(N,) m: how much farther each patch reads with one diffuse bounce (module docstring) than its range, from
    the patches' ``points`` (N, 3) m, unit ``normals`` (N, 3) and ``areas`` (N,) m^2 (NaN rows: no patch, NaN out)."""
    r = np.linalg.norm(points, axis=1)
    g = points @ normals.T                                  # [a, b]: p_a . n_b
    own = np.diagonal(g)                                    # p_i . n_i
    sq = np.sum(points * points, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        lit = np.abs(own) / r ** 3                                                  # E_i = cos / r^2
        dist = np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2.0 * (points @ points.T), 0.0))  # [j, i]
        cos_out = (g - own[None, :]) / dist                 # at i, towards j: (p_j - p_i) . n_i / d
        cos_in = (g.T - own[:, None]) / dist                # at j, towards i: (p_i - p_j) . n_j / d
        e = albedo * lit[None, :] * areas[None, :] * cos_out * cos_in / (np.pi * dist * dist)
    e = np.where((cos_out > 0.0) & (cos_in > 0.0) & np.isfinite(e), e, 0.0)
    np.fill_diagonal(e, 0.0)
    detour = (r[None, :] + dist + r[:, None]) / 2.0                                # half the path, m
    detour = np.where(e > 0.0, detour, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ranged = (lit * r + np.sum(e * detour, axis=1)) / (lit + np.sum(e, axis=1))
    return ranged - r


def pixel_range_bias(pin: Pinhole, z: np.ndarray, albedo: float, size: int | None = None) -> np.ndarray:
    """(H, W) m: each pixel's multipath range bias, its patch's (:func:`multipath_range_bias`) spread over the
    patch's block of ``size`` px (default :func:`patch_size`; pixels past the last whole block take the nearest
    block's); 0 where the block has no patch."""
    h, w = z.shape
    size = patch_size(h, w) if size is None else size
    pts, nrm, area = patches(pin, z, size)
    bias = np.nan_to_num(multipath_range_bias(pts, nrm, area, albedo)).reshape(h // size, w // size)
    rows = np.minimum(np.arange(h) // size, h // size - 1)
    cols = np.minimum(np.arange(w) // size, w // size - 1)
    return bias[np.ix_(rows, cols)]
