"""The readable reference of :func:`perception_proc.lidar.resample_offset.resample_offset`: the per-pixel method.

The same method as the fast kernel, written for reading and for testing the kernel against, with none of its
speed-ups (no pixel window, row band or column pre-test, no decode table, no float32 operation order, no
chunking, no repeated scatter):

1. decode every pixel of every camera (Eq 3) and back-project it (Eq 5): P = Z (kx, ky, 1) in the camera
   frame, kx = (u - W/2) / f, ky = (H/2 - v) / f at the pixel centre (u, v) = (col + 1/2, row + 1/2);
2. move it into the sensor frame, P_s = R P + t (R, t = sensor_from_camera), and find the beam whose direction
   is nearest to P_s / |P_s| (a k-d tree on the unit beam directions: the nearest chord is the largest cosine);
   keep the pixel as a candidate for that beam when the angle is within the table's tolerance;
3. per beam keep the candidate with the smallest range |P_s| (what the LiDAR would see first);
4. refine the kept range by intersecting the beam with the plane through the kept pixel and its right and
   lower neighbours (left / upper at the image border), where the three are continuous (their ranges from the
   LiDAR spread less than ``DISCONTINUITY_REL`` of the nearest plus twice the codec bound) and the hit stays
   within ``DISCONTINUITY_REL`` of the kept range.

Everything is float64. The kernel works in float32 and drops pixels nearer than ``NEAR_RANGE_M``, so the two
agree to float32 rounding on scenes beyond that range, with the candidate sets differing only at the
tolerance's edge (tests/test_perc_resample_offset_reference.py).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from cosim.scenario.config import Codec
from perception_proc.lidar.codec import decode_depth
from perception_proc.lidar.resample import DISCONTINUITY_REL
from perception_proc.lidar.resample_offset import OffsetTable

__all__ = ["resample_offset_reference"]


def _pixel_rays(width: int, height: int, f: float) -> tuple[np.ndarray, np.ndarray]:
    """kx, ky (H * W,) float64 of every pixel centre, row-major (Eq 5 without the depth)."""
    u = np.arange(width) + 0.5
    v = np.arange(height) + 0.5
    kx = np.broadcast_to((u - width / 2.0) / f, (height, width))
    ky = np.broadcast_to(((height / 2.0 - v) / f)[:, None], (height, width))
    return kx.ravel(), ky.ravel()


def resample_offset_reference(images, table: OffsetTable, codec: Codec) -> np.ndarray:
    """Ranges (N,) float64, m, NaN where no return: the per-pixel method on ``images`` (one (H, W, 4) uint8
    depth image per rig camera, rig order) for the beams of ``table`` (sensor frame, from the LiDAR origin).
    Only the cameras' geometry and the tolerance are read from ``table``."""
    n = table.n_beams
    tree = cKDTree(table.directions)
    best = np.full(n, np.inf)
    source = np.full((n, 2), -1, np.int64)                          # (camera, flat pixel) of each beam's winner
    depths = []
    for k, (cam, img) in enumerate(zip(table.cameras, images)):
        z = decode_depth(img, codec).astype(np.float64).ravel()     # (H * W,) planar depth, NaN invalid
        depths.append(z)
        kx, ky = _pixel_rays(cam.width, cam.height, cam.f)
        pix = np.flatnonzero(np.isfinite(z))
        p_cam = z[pix, None] * np.stack([kx[pix], ky[pix], np.ones(pix.size)], axis=1)
        p_s = p_cam @ cam.rotation.T + cam.translation
        r = np.linalg.norm(p_s, axis=1)
        s = p_s / r[:, None]
        _, beam = tree.query(s)
        cos = np.einsum("ij,ij->i", s, table.directions[beam])
        ok = cos >= table.cos_tol
        for b, rr, p in zip(beam[ok], r[ok], pix[ok]):
            if rr < best[b]:
                best[b], source[b] = rr, (k, p)
    out = np.where(np.isfinite(best), best, np.nan)
    for b in np.flatnonzero(source[:, 0] >= 0):
        k, p = source[b]
        refined = _plane_hit(table, int(k), int(p), depths[int(k)], table.directions[b], out[b], codec)
        if refined is not None:
            out[b] = refined
    return out


def _plane_hit(table: OffsetTable, k: int, p: int, depth: np.ndarray, beam_s: np.ndarray, kept: float,
               codec: Codec) -> float | None:
    """Range along the beam (sensor-frame unit ``beam_s``) to the plane through pixel ``p`` of camera ``k``
    and its right and lower neighbours, or None where they are not continuous or the hit strays."""
    cam = table.cameras[k]
    row, col = divmod(p, cam.width)
    dh = 1 if col + 1 < cam.width else -1
    dv = 1 if row + 1 < cam.height else -1
    o = -cam.rotation.T @ cam.translation                          # the LiDAR origin in the camera frame
    q = []
    for rr, cc in ((row, col), (row, col + dh), (row + dv, col)):
        z = depth[rr * cam.width + cc]
        if not np.isfinite(z):
            return None
        ray = np.array([(cc + 0.5 - cam.width / 2.0) / cam.f, (cam.height / 2.0 - rr - 0.5) / cam.f, 1.0])
        q.append(z * ray - o)
    ranges = [float(np.linalg.norm(v)) for v in q]
    lo = min(ranges)
    if max(ranges) - lo > DISCONTINUITY_REL * lo + 2.0 * codec.bound_m:
        return None
    normal = np.cross(q[1] - q[0], q[2] - q[0])
    s_cam = cam.rotation.T @ beam_s
    den = float(normal @ s_cam)
    if den == 0.0:
        return None
    t = float(normal @ q[0]) / den
    return t if abs(t - kept) <= DISCONTINUITY_REL * kept else None
