"""LiDAR from camera images when the LiDAR is mounted away from the camera centre (the general case).

A beam leaves the LiDAR origin, not the camera centre, so its image point depends on the unknown range. The
general method: decode and back-project the camera pixels (Eq 5), transform them into the sensor frame, find
for each point the beam whose direction is nearest (within ``tolerance``), and keep per beam the nearest
return (a z-buffer in beam space: what the LiDAR would see first). The kept pixel's direction is off the beam
by up to the tolerance; the hit is then refined by intersecting the beam with the local surface plane through
that pixel and its right and lower neighbours, where those three are continuous (no edge between them).

Beam look-up is separable for the grid and honeycomb presets (rows by elevation, columns by azimuth); a CSV
table uses a k-d tree of the beam directions. Only pixels whose ray from the camera lies within the pattern's
window, widened by the parallax of the mount offset at :data:`NEAR_RANGE_M`, are processed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from cosim.camera import Rig, beam_directions
from cosim.config import Codec

from .codec import decode_lut, decode_words
from .resample import DISCONTINUITY_REL, words_of

__all__ = ["OffsetCamera", "OffsetTable", "build_offset_table", "resample_offset", "NEAR_RANGE_M",
           "TOLERANCE_PIXELS", "is_offset"]

#: nearest range the parallax margin of the pixel window is sized for, m
NEAR_RANGE_M = 1.0
#: angular tolerance between a pixel's point and a beam, in pixel pitches (1/f rad): covers the half-diagonal
TOLERANCE_PIXELS = 0.75
#: a camera centre farther than this from the LiDAR origin makes the rig "offset", m
OFFSET_EPS_M = 1e-9


def is_offset(rig: Rig) -> bool:
    """Whether any rig camera's centre is away from the sensor origin."""
    return any(np.linalg.norm(c.sensor_from_camera[:3, 3]) > OFFSET_EPS_M for c in rig.cameras)


@dataclass(frozen=True)
class OffsetCamera:
    """Pixels of one camera worth processing. ``pixel`` (K,) int64 flat indices; ``rotation`` (3, 3),
    ``translation`` (3,) float64 sensor_from_camera; image size in pixels and focal length ``f`` (pixels);
    ``kx``, ``ky`` (K,) float32 X/Z and Y/Z of each kept pixel's camera-frame ray (so P = Z (kx, ky, 1))."""

    pixel: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    width: int
    height: int
    f: float

    kx: np.ndarray
    ky: np.ndarray


@dataclass(frozen=True)
class OffsetTable:
    """Tables for the general case. ``directions`` (N, 3) unit beams (sensor frame); for separable patterns
    ``rows`` x ``cols`` with ``elev_rows`` (rows,) rad descending and azimuth ``az0``, ``daz`` (rad, first and
    step, descending); ``tree`` for arbitrary tables; ``cos_tol`` cosine of the angular tolerance."""

    directions: np.ndarray
    cameras: tuple[OffsetCamera, ...]
    cos_tol: float
    rows: int
    cols: int
    elev_rows: np.ndarray | None
    az0: float
    daz: float
    tree: cKDTree | None

    @property
    def n_beams(self) -> int:
        return int(self.directions.shape[0])

    @property
    def directions32(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Beam direction components, each (N,) float32 C-contiguous."""
        store = self.__dict__.setdefault("_derived", {})
        if "d32" not in store:
            store["d32"] = tuple(np.ascontiguousarray(self.directions[:, i], dtype=np.float32) for i in range(3))
        return store["d32"]


def _separable(elev: np.ndarray, az: np.ndarray, shape: tuple[int, int] | None):
    if shape is None:
        return None
    rows, cols = shape
    e, a = elev.reshape(rows, cols), az.reshape(rows, cols)
    if not (np.all(e == e[:, :1]) and np.all(a == a[:1, :])):
        return None
    er, ac = e[:, 0], a[0, :]
    if rows > 1 and not np.all(np.diff(er) < 0):
        return None
    if cols > 1:
        step = np.diff(ac)
        if not (np.all(step < 0) and np.allclose(step, step[0], rtol=1e-9, atol=1e-12)):
            return None
        return rows, cols, er, float(ac[0]), float(step[0])
    return rows, cols, er, float(ac[0]), -1.0


def _lookup(table_like, dirs: np.ndarray) -> np.ndarray:
    """Nearest-beam index (K,) int64 for unit sensor-frame directions (K, 3), -1 outside the table."""
    t = table_like
    if t.tree is not None:
        _, idx = t.tree.query(dirs, k=1, distance_upper_bound=2.0 * math.sqrt(2 * (1 - t.cos_tol)) + 1e-12)
        return np.where(idx >= t.n_beams, -1, idx).astype(np.int64)
    el = np.arcsin(np.clip(dirs[:, 1], -1.0, 1.0))
    az = np.arctan2(-dirs[:, 0], dirs[:, 2])
    er = t.elev_rows
    if t.rows > 1:
        mids = 0.5 * (er[:-1] + er[1:])                 # descending
        row = np.searchsorted(-mids, -el)
    else:
        row = np.zeros(el.shape, np.int64)
    col = np.rint((az - t.az0) / t.daz).astype(np.int64) if t.cols > 1 else np.zeros(el.shape, np.int64)
    ok = (col >= 0) & (col < t.cols)
    return np.where(ok, row * t.cols + np.clip(col, 0, t.cols - 1), -1).astype(np.int64)


def build_offset_table(rig: Rig, elevation: np.ndarray, azimuth: np.ndarray,
                       shape: tuple[int, int] | None = None) -> OffsetTable:
    """Precompute the pixel windows and the beam look-up. ``elevation``, ``azimuth``: (N,) rad; ``shape``:
    (rows, cols) when the table is a row-major grid (``perception_proc.patterns.pattern_shape``)."""
    e = np.asarray(elevation, np.float64)
    a = np.asarray(azimuth, np.float64)
    dirs = beam_directions(e, a)
    pitch = min(1.0 / c.intrinsics.f for c in rig.cameras)
    tol = TOLERANCE_PIXELS * pitch
    sep = _separable(e, a, shape)
    if sep is None:
        rows, cols, er, az0, daz, tree = 0, 0, None, 0.0, 0.0, cKDTree(dirs)
    else:
        (rows, cols, er, az0, daz), tree = sep, None
    base = OffsetTable(dirs, (), math.cos(tol), rows, cols, er, az0, daz, tree)
    cams = []
    for cam in rig.cameras:
        rot, trans = cam.sensor_from_camera[:3, :3], cam.sensor_from_camera[:3, 3]
        margin = tol + math.atan(float(np.linalg.norm(trans)) / NEAR_RANGE_M)
        rays = cam.intrinsics.ray_directions().reshape(-1, 3)
        d_s = rays @ rot.T
        idx = _lookup(base, d_s)
        ok = idx >= 0
        cosang = np.einsum("ij,ij->i", d_s[ok], dirs[idx[ok]])
        keep = np.flatnonzero(ok)[cosang >= math.cos(margin + 2.0 * tol)] if margin > 0 else np.flatnonzero(ok)
        # widen by the parallax margin: pixels near any kept pixel in angle are taken as well
        if margin > tol:
            grow = int(math.ceil(margin * cam.intrinsics.f))
            mask = np.zeros(rays.shape[0], bool)
            mask[keep] = True
            import cv2
            m2 = mask.reshape(cam.intrinsics.height, cam.intrinsics.width).astype(np.uint8)
            m2 = cv2.dilate(m2, np.ones((2 * grow + 1, 2 * grow + 1), np.uint8))
            keep = np.flatnonzero(m2.ravel())
        r = rays[keep]
        cams.append(OffsetCamera(
            pixel=keep.astype(np.int64), rotation=rot.copy(), translation=trans.copy(),
            width=cam.intrinsics.width, height=cam.intrinsics.height, f=cam.intrinsics.f,
            kx=np.ascontiguousarray(r[:, 0] / r[:, 2], dtype=np.float32),
            ky=np.ascontiguousarray(r[:, 1] / r[:, 2], dtype=np.float32),
        ))
    return OffsetTable(dirs, tuple(cams), base.cos_tol, rows, cols, er, az0, daz, tree)


def _decode_at(words: np.ndarray, idx: np.ndarray, codec: Codec) -> np.ndarray:
    return decode_words(words[idx], decode_lut(codec))


def _points(cam: OffsetCamera, words: np.ndarray, flat: np.ndarray, codec: Codec) -> np.ndarray:
    """Sensor-frame points (K, 3) float64 of flat pixel indices; NaN where invalid."""
    z = _decode_at(words, flat, codec).astype(np.float64)
    col, row = flat % cam.width, flat // cam.width
    s = z / cam.f
    p = np.stack([s * (col + 0.5 - cam.width / 2.0), s * (cam.height / 2.0 - (row + 0.5)), z], axis=1)
    return p @ cam.rotation.T + cam.translation


def _beam_of(table: OffsetTable, x: np.ndarray, y: np.ndarray, z: np.ndarray, inv_r: np.ndarray) -> np.ndarray:
    """Nearest beam (K,) int64 of sensor-frame points given as components (float32), -1 if none in tolerance."""
    if table.tree is not None:
        d = np.stack([x * inv_r, y * inv_r, z * inv_r], axis=1).astype(np.float64)
        beam = _lookup(table, d)
    else:
        lut, lo, scale = _elevation_lut(table)
        key = np.clip(((y * inv_r - lo) * scale).astype(np.int64), 0, lut.size - 1)
        row = lut[key]
        az = np.arctan2(-x, z)
        col = np.rint((az - np.float32(table.az0)) * np.float32(1.0 / table.daz)).astype(np.int64) \
            if table.cols > 1 else np.zeros(x.shape, np.int64)
        beam = np.where((col >= 0) & (col < table.cols), row * table.cols + col, -1)
    ok = beam >= 0
    b = np.where(ok, beam, 0)
    dirs = table.directions32
    cosang = (x * dirs[0][b] + y * dirs[1][b] + z * dirs[2][b]) * inv_r
    return np.where(ok & (cosang >= np.float32(table.cos_tol)), beam, -1)


#: samples of the elevation look-up table over sin(elevation) in [-1, 1]
ELEVATION_LUT_SIZE = 1 << 16


def _elevation_lut(table: OffsetTable):
    """Row index by sin(elevation): (ELEVATION_LUT_SIZE,) int64, the lower bound (-1) and the scale."""
    store = table.__dict__.setdefault("_derived", {})
    if "elut" not in store:
        sin_e = np.linspace(-1.0, 1.0, ELEVATION_LUT_SIZE)
        er = table.elev_rows
        if table.rows > 1:
            mids = np.sin(0.5 * (er[:-1] + er[1:]))
            row = np.searchsorted(-mids, -sin_e)
        else:
            row = np.zeros(ELEVATION_LUT_SIZE, np.int64)
        store["elut"] = (row.astype(np.int64), np.float32(-1.0), np.float32((ELEVATION_LUT_SIZE - 1) / 2.0))
    return store["elut"]


def resample_offset(images, table: OffsetTable, codec: Codec) -> np.ndarray:
    """Ranges (N,) float32, m, NaN where no return, for a LiDAR away from the camera centres.

    ``images``: one (H, W, 4) uint8 depth image per rig camera, rig order.
    """
    n = table.n_beams
    best = np.full(n, np.inf, dtype=np.float32)
    owner = np.full(n, -1, np.int64)                # packed camera << 32 | flat pixel of the kept return
    lut = decode_lut(codec)
    for k, (img, cam) in enumerate(zip(images, table.cameras)):
        z = decode_words(words_of(img)[cam.pixel], lut)
        ok = np.flatnonzero(z == z)                  # not NaN
        z = z[ok]
        px, py = z * cam.kx[ok], z * cam.ky[ok]
        R, t = cam.rotation.astype(np.float32), cam.translation.astype(np.float32)
        x = R[0, 0] * px + R[0, 1] * py + R[0, 2] * z + t[0]
        y = R[1, 0] * px + R[1, 1] * py + R[1, 2] * z + t[1]
        zz = R[2, 0] * px + R[2, 1] * py + R[2, 2] * z + t[2]
        r = np.sqrt(x * x + y * y + zz * zz)
        beam = _beam_of(table, x, y, zz, np.float32(1.0) / r)
        hit = beam >= 0
        beam, r, pix = beam[hit], r[hit], cam.pixel[ok[hit]]
        np.minimum.at(best, beam, r)
        win = r <= best[beam]
        owner[beam[win]] = (k << 32) | pix[win]
    return _refine(images, table, codec, best.astype(np.float64), owner)


def _refine(images, table: OffsetTable, codec: Codec, best: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """Intersect each beam with the plane through its kept pixel and two neighbours where continuous."""
    out = np.where(np.isfinite(best), best, np.nan).astype(np.float32)
    for k, (img, cam) in enumerate(zip(images, table.cameras)):
        sel = np.flatnonzero((owner >= 0) & ((owner >> 32) == k))
        if sel.size == 0:
            continue
        flat = owner[sel] & 0xFFFFFFFF
        col, row = flat % cam.width, flat // cam.width
        inside = (col + 1 < cam.width) & (row + 1 < cam.height)
        sel, flat = sel[inside], flat[inside]
        words = words_of(img)
        p0 = _points(cam, words, flat, codec)
        p1 = _points(cam, words, flat + 1, codec)
        p2 = _points(cam, words, flat + cam.width, codec)
        r0, r1, r2 = (np.linalg.norm(q, axis=1) for q in (p0, p1, p2))
        with np.errstate(invalid="ignore"):
            lo = np.fmin(np.fmin(r0, r1), r2)
            smooth = (np.fmax(np.fmax(r0, r1), r2) - lo) <= DISCONTINUITY_REL * lo + 2 * codec.bound_m
            nrm = np.cross(p1 - p0, p2 - p0)
            s = table.directions[sel]
            den = np.einsum("ij,ij->i", nrm, s)
            t = np.einsum("ij,ij->i", nrm, p0) / den
            good = smooth & np.isfinite(t) & (np.abs(t - best[sel]) <= DISCONTINUITY_REL * best[sel])
        out[sel[good]] = t[good]
    return out
