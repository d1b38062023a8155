"""LiDAR from camera images when the LiDAR is mounted away from the camera centre (the general case).

A beam leaves the LiDAR origin, not the camera centre, so its image point depends on the unknown range. The
general method: decode and back-project the camera pixels (Eq 5), transform them into the sensor frame, find
for each point the beam whose direction is nearest (within ``tolerance``), and keep per beam the nearest
return (a z-buffer in beam space: what the LiDAR would see first). The kept pixel's direction is off the beam
by up to the tolerance; the hit is then refined by intersecting the beam with the local surface plane through
that pixel and its right and lower neighbours, where those three are continuous (no edge between them).

Per rig, :func:`build_offset_table` does everything that does not depend on depth (frames: camera X right,
Y up, Z forward; sensor frame likewise; a pixel's point at planar depth Z is Z a + t in the sensor frame,
a = R (kx, ky, 1), R and t = sensor_from_camera; as 1/Z runs from 0 to 1/NEAR_RANGE_M its direction from the
LiDAR moves along a great-circle arc, the parallax of the mount):

* the pixel window: pixels whose ray lies within the pattern's field widened by the parallax at
  :data:`NEAR_RANGE_M`; a window covering most of its span is processed as one run (no gather);
* for separable patterns (grid, honeycomb: rows by elevation, columns by azimuth) the *row band*: the arc's
  elevation range has a closed form (:func:`_elevation_band`), and pixels whose arc stays farther than the
  tolerance from every beam row can never meet a beam and are dropped (useful for sparse rows and small
  vertical parallax; with NEAR_RANGE_M = 1 m and 0.2 m offsets it rarely drops many);
* per pixel the column pre-test bound (:func:`_column_tolerance`): a point within the tolerance of a beam is
  within a known azimuth difference of that beam's column, smaller where the arc stays at low elevation.

Per frame, in cache-sized runs of :data:`CHUNK_PIXELS`: table decode of the RGBA words (invalid pixels get a
negative depth, not NaN, which slows arctan2 several times), x and z of the point, its column by arctan2 and
the column pre-test, which leaves a fifth to a half of the pixels. On those: the point by the reference
arithmetic (:func:`_rotated`), the row by a table on sin(elevation), and the float32 cosine test of the
reference per-pixel method, so the candidates are the reference's except that the column pre-test applies
the tolerance exactly in azimuth: points that only float32 rounding let through (up to about 2e-7 in
1 - cos beyond the tolerance) are dropped, 0.2-2.5 % of the candidates on the bench and default scenes, with
identical coverage and error statistics (``python bench/run.py offset_accuracy``). Then an exact per-beam minimum
(:func:`_nearest_per_beam`: repeated scatter, no sort, no ``ufunc.at``) and the plane refinement of the
winners in float32 (:func:`_refine`; at the image border with the left / upper neighbour).

The readable reference of the whole method, with none of these speed-ups, is
:func:`perception_proc.lidar.resample_offset_reference.resample_offset_reference`; a test holds the two together.

Validity: points nearer than :data:`NEAR_RANGE_M` (camera depth) may fall outside the window, the row band
and the column bound and are then ignored (a beam whose nearest surface is that close reports the next
surface behind it or nothing); a pattern given as a CSV table (not separable) uses a k-d tree on every
window pixel, slower but the same method. Beams that no pixel point meets within the tolerance (surfaces
seen at grazing angles or stretched by the parallax) report NaN; beams whose surface is hidden from the
camera by a nearer object (disocclusion by the offset) report NaN or the occluder's edge: the images hold no
better answer. Ranges are from the LiDAR origin along each beam, m, float32.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from cosim.scenario.config import Codec
from cosim.world.camera import Rig, beam_directions
from perception_proc.lidar.codec import decode_lut, decode_words, lut_key
from perception_proc.lidar.resample import DISCONTINUITY_REL, words_of

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

__all__ = ["OffsetCamera", "OffsetTable", "build_offset_table", "resample_offset", "NEAR_RANGE_M",
           "TOLERANCE_PIXELS", "is_offset"]

#: nearest range the parallax margin of the pixel window is sized for, m
NEAR_RANGE_M = 1.0
#: angular tolerance between a pixel's point and a beam, in pixel pitches (1/f rad): covers the half-diagonal
TOLERANCE_PIXELS = 0.75
#: a camera centre farther than this from the LiDAR origin makes the rig "offset", m
OFFSET_EPS_M = 1e-9
#: samples of the elevation look-up table over sin(elevation) in [-1, 1]
ELEVATION_LUT_SIZE = 1 << 16
#: pixels per run of the per-frame pass (the run's float32 temporaries stay in the L2 cache)
CHUNK_PIXELS = 1 << 15
#: a pixel selection covering at least this share of its index span is processed as one run (no gather)
DENSE_FRACTION = 0.85
#: rounding of the float32 cosine test, in 1 - cos: it accepts points up to about 2.2e-7 beyond 1 - cos(tol)
#: (measured on the bench and default scenes); the row band is sized for 1 - cos(tol) plus this, so that it
#: drops only pixels the full window would not match either
COS_FUZZ = 5e-7
#: widening of the pre-tests (rad for the row band, columns for the column test) for float32 rounding of
#: the points' direction (arctan2 of x, z), about 1e-7 rad
PRETEST_SLACK = 1e-4


def is_offset(rig: Rig) -> bool:
    """Whether any rig camera's centre is away from the sensor origin."""
    return any(np.linalg.norm(c.sensor_from_camera[:3, 3]) > OFFSET_EPS_M for c in rig.cameras)


@dataclass(frozen=True)
class OffsetCamera:
    """Pixels of one camera worth processing. ``pixel`` (K,) int64 flat indices row * W + col, ascending;
    ``rotation`` (3, 3), ``translation`` (3,) float64 sensor_from_camera (m); image size in pixels and focal
    length ``f`` (pixels); ``kx``, ``ky`` (K,) float32 X/Z and Y/Z of each kept pixel's camera-frame ray (so
    P = Z (kx, ky, 1)); ``ax``, ``az`` (K,) float32 the x and z components of the same ray in the sensor frame,
    a = R (kx, ky, 1), so the sensor-frame point of planar depth Z has x = Z a_x + t_x, z = Z a_z + t_z (the
    column pre-test needs only these two); ``tol_col`` (K,) float32 the pre-test's bound on the distance to the
    nearest beam column, in columns (separable patterns; see :func:`_column_tolerance`), else empty."""

    pixel: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    width: int
    height: int
    f: float

    kx: np.ndarray
    ky: np.ndarray
    ax: np.ndarray
    az: np.ndarray
    tol_col: np.ndarray

    @property
    def start(self) -> int:
        """First flat pixel index."""
        return int(self.pixel[0]) if self.pixel.size else 0

    @property
    def contiguous(self) -> bool:
        """Whether ``pixel`` is a run of consecutive indices (then the words are sliced, not gathered)."""
        store = self.__dict__.setdefault("_derived", {})
        if "contiguous" not in store:
            p = self.pixel
            store["contiguous"] = bool(p.size == 0 or p[-1] - p[0] + 1 == p.size)
        return store["contiguous"]


@dataclass(frozen=True)
class OffsetTable:
    """Tables for the general case. ``directions`` (N, 3) unit beams (sensor frame); for separable patterns
    ``rows`` x ``cols`` with ``elev_rows`` (rows,) rad descending and azimuth ``az0``, ``daz`` (rad, first and
    step, descending); ``tree`` for arbitrary tables; ``cos_tol`` cosine of the angular tolerance ``tol``
    (rad)."""

    directions: np.ndarray
    cameras: tuple[OffsetCamera, ...]
    cos_tol: float
    rows: int
    cols: int
    elev_rows: np.ndarray | None
    az0: float
    daz: float
    tree: cKDTree | None
    tol: float = 0.0

    @property
    def n_beams(self) -> int:
        return int(self.directions.shape[0])

    def _cache(self, key: str, make):
        store = self.__dict__.setdefault("_derived", {})
        if key not in store:
            store[key] = make()
        return store[key]

    @property
    def directions32(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Beam direction components, each (N,) float32 C-contiguous."""
        return self._cache("d32", lambda: tuple(
            np.ascontiguousarray(self.directions[:, i], dtype=np.float32) for i in range(3)))


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


def _elevation_band(a: np.ndarray, t: np.ndarray, w_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest sin(elevation) (K,) of the directions a + w t, 0 <= w <= w_max (a (K, 3), t (3,)).

    sin el(w) = (a_y + w t_y) / |a + w t| has at most one interior extremum, where its derivative's numerator
    t_y |a|^2 - a_y (a.t) + w (t_y (a.t) - a_y |t|^2) vanishes."""
    aa, at, tt = np.einsum("ij,ij->i", a, a), a @ t, float(t @ t)

    def sin_el(w):
        return (a[:, 1] + w * t[1]) / np.sqrt(aa + 2.0 * w * at + w * w * tt)

    num, den = t[1] * aa - a[:, 1] * at, t[1] * at - a[:, 1] * tt
    with np.errstate(divide="ignore", invalid="ignore"):
        w_star = np.clip(np.where(den != 0.0, -num / den, 0.0), 0.0, w_max)
    s = np.stack([sin_el(0.0), sin_el(w_max), sin_el(w_star)])
    return s.min(axis=0), s.max(axis=0)


def build_offset_table(rig: Rig, elevation: np.ndarray, azimuth: np.ndarray,
                       shape: tuple[int, int] | None = None) -> OffsetTable:
    """Precompute the pixel windows, row bands and the beam look-up. ``elevation``, ``azimuth``: (N,) rad;
    ``shape``: (rows, cols) when the table is a row-major grid (``cosim.world.patterns.pattern_shape``)."""
    e = np.asarray(elevation, np.float64)
    a = np.asarray(azimuth, np.float64)
    dirs = beam_directions(e, a)
    pitch = min(1.0 / c.intrinsics.f for c in rig.cameras)
    tol = TOLERANCE_PIXELS * pitch
    sep = _separable(e, a, shape)
    if sep is None:
        from scipy.spatial import cKDTree  # only a pattern that is not a grid needs it (~0.2 s to import)

        rows, cols, er, az0, daz, tree = 0, 0, None, 0.0, 0.0, cKDTree(dirs)
    else:
        (rows, cols, er, az0, daz), tree = sep, None
    base = OffsetTable(dirs, (), math.cos(tol), rows, cols, er, az0, daz, tree, tol)
    # the angle the pre-tests must let through: what the float32 cosine test can still accept
    tol_pre = math.acos(1.0 - ((1.0 - float(np.float32(base.cos_tol))) + COS_FUZZ))
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
        k_cam = r / r[:, 2:3]                                   # (kx, ky, 1)
        a_s = k_cam @ rot.T                                     # sensor frame, P = Z a + t
        if er is not None and er.size > 1:
            band = _row_band(a_s, trans, er, tol_pre)
            if band.sum() < DENSE_FRACTION * (keep[-1] - keep[0] + 1):
                keep, k_cam, a_s = keep[band], k_cam[band], a_s[band]
        if keep.size and keep.size >= DENSE_FRACTION * (keep[-1] - keep[0] + 1):
            keep = np.arange(keep[0], keep[-1] + 1)             # a run: slice the words instead of a gather
            r = rays[keep]
            k_cam = r / r[:, 2:3]
            a_s = k_cam @ rot.T
        tol_col = _column_tolerance(a_s, trans, er, daz, tol) if er is not None else np.zeros(0, np.float32)
        cams.append(OffsetCamera(
            pixel=keep.astype(np.int64), rotation=rot.copy(), translation=trans.copy(),
            width=cam.intrinsics.width, height=cam.intrinsics.height, f=cam.intrinsics.f,
            kx=np.ascontiguousarray(k_cam[:, 0], dtype=np.float32),
            ky=np.ascontiguousarray(k_cam[:, 1], dtype=np.float32),
            ax=np.ascontiguousarray(a_s[:, 0], dtype=np.float32),
            az=np.ascontiguousarray(a_s[:, 2], dtype=np.float32),
            tol_col=tol_col,
        ))
    return OffsetTable(dirs, tuple(cams), base.cos_tol, rows, cols, er, az0, daz, tree, tol)


def _row_band(a_s: np.ndarray, trans: np.ndarray, elev_rows: np.ndarray, tol: float) -> np.ndarray:
    """(K,) bool: pixels whose direction from the LiDAR, for any depth >= NEAR_RANGE_M, comes within ``tol``
    (rad) in elevation of some beam row (a point within ``tol`` of a beam is within ``tol`` of its row)."""
    lo, hi = _elevation_band(a_s, np.asarray(trans, np.float64), 1.0 / NEAR_RANGE_M)
    band = tol + PRETEST_SLACK
    el_lo = np.arcsin(np.clip(lo, -1.0, 1.0)) - band
    el_hi = np.arcsin(np.clip(hi, -1.0, 1.0)) + band
    asc = np.sort(elev_rows)
    return np.searchsorted(asc, el_hi, side="right") > np.searchsorted(asc, el_lo, side="left")


def _column_tolerance(a_s: np.ndarray, trans: np.ndarray, elev_rows: np.ndarray, daz: float,
                      tol: float) -> np.ndarray:
    """Per pixel (K,) float32: the largest azimuth difference, in beam columns, between the pixel's point (at
    any depth >= NEAR_RANGE_M) and a beam within ``tol`` (rad) of it. From 1 - cos(tol) >= 1 - cos(gamma) >=
    cos el1 cos el2 (1 - cos d az) with both elevations at most min(E, E_rows) + tol, E the largest |elevation|
    of the pixel's direction over that depth range and E_rows that of the beam rows."""
    lo, hi = _elevation_band(a_s, np.asarray(trans, np.float64), 1.0 / NEAR_RANGE_M)
    e = np.maximum(np.abs(np.arcsin(np.clip(lo, -1.0, 1.0))), np.abs(np.arcsin(np.clip(hi, -1.0, 1.0))))
    e = np.minimum(np.minimum(e, float(np.max(np.abs(elev_rows)))) + tol, 0.5 * math.pi - 1e-3)
    c = np.cos(e)
    d_az = np.arccos(np.maximum(-1.0, 1.0 - (1.0 - math.cos(tol)) / (c * c)))
    return (d_az / abs(daz) + PRETEST_SLACK).astype(np.float32)


def _grid_tables(table: OffsetTable):
    """Per-table constants of the separable look-up: the row table by sin(elevation) ((ELEVATION_LUT_SIZE,)
    intp) and its scale, and the column scale and shift of arctan2 (column = atan2(x, z) scale + shift)."""
    def make():
        sin_e = np.linspace(-1.0, 1.0, ELEVATION_LUT_SIZE)
        er = table.elev_rows
        if table.rows > 1:
            row = np.searchsorted(-np.sin(0.5 * (er[:-1] + er[1:])), -sin_e)
        else:
            row = np.zeros(ELEVATION_LUT_SIZE, np.int64)
        scale = np.float32((ELEVATION_LUT_SIZE - 1) / 2.0)
        col_scale = np.float32(-1.0 / table.daz)                # az = atan2(-x, z) = -atan2(x, z)
        col_shift = np.float32(-table.az0 / table.daz)
        return row.astype(np.intp), scale, col_scale, col_shift
    return table._cache("grid", make)


#: planar depth the per-frame decode gives invalid pixels instead of NaN, m (negative: never a point;
#: arctan2 and friends run several times slower on NaN)
INVALID_DEPTH_M = -1.0


@lru_cache(maxsize=8)
def _finite_lut(codec: Codec) -> np.ndarray:
    """:func:`perception_proc.lidar.codec.decode_lut` with :data:`INVALID_DEPTH_M` in place of NaN, (2^17,) float32."""
    lut = decode_lut(codec)
    out = np.where(np.isnan(lut), np.float32(INVALID_DEPTH_M), lut).astype(np.float32)
    out.flags.writeable = False
    return out


def _depth(cam: OffsetCamera, words: np.ndarray, lut: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Planar depth Z (hi - lo,) float32 m of the camera's kept pixels lo:hi by ``lut`` (:func:`_finite_lut`:
    negative where invalid)."""
    if cam.contiguous:
        w = words[cam.start + lo:cam.start + hi]
    else:
        w = np.take(words, cam.pixel[lo:hi])
    return np.take(lut, lut_key(w))


def _rotated(cam: OffsetCamera, idx: np.ndarray, z: np.ndarray):
    """Sensor-frame points x, y, z (M,) float32 m of kept pixels ``idx`` at planar depth ``z``: R (Z kx, Z ky,
    Z) + t in float32, in the operation order of the reference per-pixel method (the exact tolerance test
    then accepts the same points bit for bit)."""
    px, py = np.take(cam.kx, idx) * z, np.take(cam.ky, idx) * z
    R, t = cam.rotation.astype(np.float32), cam.translation.astype(np.float32)
    out = []
    for i in range(3):                                  # exact zeros add nothing: skipping them is bit-exact
        terms = [(R[i, j], p) for j, p in enumerate((px, py, z)) if R[i, j] != 0.0]
        acc = terms[0][0] * terms[0][1] if terms else np.zeros_like(z)
        for c, p in terms[1:]:
            acc += c * p
        if t[i] != 0.0:
            acc += t[i]
        out.append(acc)
    return out


def _column_pass(table: OffsetTable, cam: OffsetCamera, words: np.ndarray, lut: np.ndarray):
    """The one pass over every kept pixel (in runs of :data:`CHUNK_PIXELS`, which stay in cache): decode,
    the point's x and z, its azimuth by arctan2 and the column pre-test. Returns the survivors' indices into
    ``cam.pixel`` (M,) intp, their nearest column (M,) intp (may lie outside the pattern) and depth (M,)
    float32 m (negative where invalid)."""
    _, _, col_scale, col_shift = _grid_tables(table)
    tx, tz = np.float32(cam.translation[0]), np.float32(cam.translation[2])
    parts = []
    k = cam.pixel.size
    for lo in range(0, k, CHUNK_PIXELS):
        hi = min(lo + CHUNK_PIXELS, k)
        z_img = _depth(cam, words, lut, lo, hi)
        x = cam.ax[lo:hi] * z_img
        if tx != 0.0:
            x += tx
        z = cam.az[lo:hi] * z_img
        if tz != 0.0:
            z += tz
        colf = np.arctan2(x, z, out=x)
        colf *= col_scale
        colf += col_shift
        col = np.rint(colf, out=z)                               # may lie outside the pattern: see below
        colf -= col
        np.abs(colf, out=colf)
        np.maximum(colf, -z_img, out=colf)                       # invalid depth (negative) -> fails
        i = np.flatnonzero(colf <= cam.tol_col[lo:hi])          # a fifth to a half of the pixels
        parts.append((i + lo, np.take(col, i), np.take(z_img, i)))
    idx, col, zi = (np.concatenate([p[n] for p in parts]) for n in range(3))
    return idx, col.astype(np.intp), zi


def _candidates(table: OffsetTable, cam: OffsetCamera, words: np.ndarray, lut: np.ndarray):
    """Pixels of one camera whose point lies within the tolerance of a beam: (indices into ``cam.pixel`` (M,)
    intp, beam (M,) intp, range (M,) float32 m)."""
    if table.tree is not None:
        z_img = _depth(cam, words, lut, 0, cam.pixel.size)
        idx = np.flatnonzero(z_img > 0)
        x, y, z = _rotated(cam, idx, z_img[idx])
        r = np.sqrt(x * x + y * y + z * z)
        inv_r = np.float32(1.0) / r
        s = np.stack([x * inv_r, y * inv_r, z * inv_r], axis=1)
        beam = _lookup(table, s.astype(np.float64))
        hit = np.flatnonzero(beam >= 0)
        idx, beam, x, y, z, r, inv_r = (v[hit] for v in (idx, beam, x, y, z, r, inv_r))
        dx, dy, dz = table.directions32
        cosang = (x * np.take(dx, beam) + y * np.take(dy, beam) + z * np.take(dz, beam)) * inv_r
        good = np.flatnonzero(cosang >= np.float32(table.cos_tol))
        return np.take(idx, good), np.take(beam, good), np.take(r, good)
    else:
        idx, col, zi = _column_pass(table, cam, words, lut)
        x, y, z = _rotated(cam, idx, zi)
        row_lut, scale = _grid_tables(table)[:2]
        r = x * x
        r += y * y
        r += z * z
        np.sqrt(r, out=r)
        inv_r = np.float32(1.0) / r
        with np.errstate(invalid="ignore"):
            key = ((y * inv_r + np.float32(1.0)) * scale).astype(np.intp)   # sin(elevation) -> row table
        beam = np.take(row_lut, key, mode="clip") * table.cols + col
        # out-of-range columns and invalid depths (negative) are rejected below; clip keeps the takes legal
        dx, dy, dz = table.directions32
        cosang = (x * np.take(dx, beam, mode="clip") + y * np.take(dy, beam, mode="clip")
                  + z * np.take(dz, beam, mode="clip")) * inv_r
        good = np.flatnonzero((cosang >= np.float32(table.cos_tol)) & (col >= 0) & (col < table.cols)
                              & (zi > 0))
        return np.take(idx, good), np.take(beam, good), np.take(r, good)


def _nearest_per_beam(n: int, beam: np.ndarray, rng: np.ndarray) -> np.ndarray:
    """Index (N,) intp of the candidate with the smallest range per beam, -1 where a beam has none.

    Exact without sorting: scatter every candidate index (an arbitrary one of each beam's wins), then scatter
    again only the candidates nearer than their beam's current winner, until none is; every round strictly
    lowers some winner's range, and a candidate not nearer than a winner never becomes nearer later."""
    win = np.full(n, -1, np.intp)
    act = np.arange(beam.size)
    while act.size:
        win[beam[act]] = act
        act = act[rng[act] < rng[win[beam[act]]]]
    return win


def resample_offset(images, table: OffsetTable, codec: Codec) -> np.ndarray:
    """Ranges (N,) float32, m, NaN where no return, for a LiDAR away from the camera centres.

    ``images``: one (H, W, 4) uint8 depth image per rig camera, rig order (linear bytes, Eqs 1-2). Range is
    measured from the LiDAR origin along each beam of ``table.directions`` (sensor frame).
    """
    if len(images) != len(table.cameras):
        raise ValueError(f"expected {len(table.cameras)} images (one per rig camera), got {len(images)}")
    words = [words_of(img) for img in images]
    flut = _finite_lut(codec)
    found = [_candidates(table, cam, wd, flut) for cam, wd in zip(table.cameras, words)]
    cam_of = np.concatenate([np.full(f[0].size, k, np.intp) for k, f in enumerate(found)])
    idx, beam, rng = (np.concatenate([f[n] for f in found]) for n in range(3))
    n = table.n_beams
    win = _nearest_per_beam(n, beam, rng)
    out = np.full(n, np.nan, np.float32)
    hit = np.flatnonzero(win >= 0)
    w = win[hit]
    out[hit] = rng[w]
    _refine(out, hit, cam_of[w], idx[w], words, table, codec)
    return out


def _refine(out: np.ndarray, sel: np.ndarray, cam_of: np.ndarray, idx: np.ndarray, words, table: OffsetTable,
            codec: Codec) -> None:
    """Intersect beams ``sel`` (M,) with the plane through their kept pixel (camera ``cam_of`` (M,), index
    ``idx`` (M,) into its ``pixel``) and that pixel's right and lower neighbours (left and upper at the image
    border) where the three are
    continuous (range spread below DISCONTINUITY_REL of the range plus twice the codec bound) and the hit
    stays within DISCONTINUITY_REL of the kept range; writes the refined ranges into ``out`` (N,) in place.

    Works in each camera's frame, relative to the LiDAR origin o (camera frame): Q = Z (kx, ky, 1) - o for the
    three pixels, range |Q|, normal n = (Q1 - Q0) x (Q2 - Q0) and the hit at range n.Q0 / n.s along the beam
    s (camera frame). float32 throughout (m)."""
    lut = decode_lut(codec)
    parts = []
    for k, cam in enumerate(table.cameras):
        mine = np.flatnonzero(cam_of == k)
        if mine.size == 0:
            continue
        i = idx[mine]
        flat = i + cam.start if cam.contiguous else np.take(cam.pixel, i)      # arithmetic, not gathers:
        col, row = flat % cam.width, flat // cam.width                         # the tables are large
        dh = np.where(col + 1 < cam.width, 1, -1)                       # right neighbour, left at the border
        dv = np.where(row + 1 < cam.height, 1, -1)                      # lower neighbour, upper at the border
        z = decode_words(np.take(words[k], np.stack([flat, flat + dh, flat + dv * cam.width])), lut)   # (3, M)
        o = (-cam.rotation.T @ cam.translation).astype(np.float32)      # LiDAR origin, camera frame
        s = [np.take(c, sel[mine]) for c in _camera_directions(table, k)]
        inv_f = 1.0 / cam.f
        kx = ((col + (0.5 - cam.width / 2.0)) * inv_f).astype(np.float32)
        ky = (((cam.height / 2.0 - 0.5) - row) * inv_f).astype(np.float32)
        parts.append((mine, z, kx, ky, (dh * inv_f).astype(np.float32), (dv * inv_f).astype(np.float32), o, s))
    if not parts:
        return
    mine = np.concatenate([p[0] for p in parts])
    z = np.concatenate([p[1] for p in parts], axis=1)
    kx0, ky0, step_h, step_v = (np.concatenate([p[c] for p in parts]) for c in range(2, 6))
    o = np.concatenate([np.broadcast_to(p[6][:, None], (3, p[0].size)) for p in parts], axis=1)
    sx, sy, sz = (np.concatenate([p[7][c] for p in parts]) for c in range(3))
    sel = sel[mine]
    qx, qy, qz = z * kx0, z * ky0, z - o[2:3]
    qx[1] += step_h * z[1]                                              # right (left) neighbour: kx +- 1/f
    qy[2] -= step_v * z[2]                                              # lower (upper) neighbour: ky -+ 1/f
    qx -= o[0:1]
    qy -= o[1:2]
    r = np.sqrt(qx * qx + qy * qy + qz * qz)
    best = out[sel]
    with np.errstate(invalid="ignore", divide="ignore"):
        lo = r.min(axis=0)                                               # NaN if a pixel is invalid
        smooth = r.max(axis=0) - lo <= np.float32(DISCONTINUITY_REL) * lo + np.float32(2 * codec.bound_m)
        ux, uy, uz = qx[1] - qx[0], qy[1] - qy[0], qz[1] - qz[0]
        vx, vy, vz = qx[2] - qx[0], qy[2] - qy[0], qz[2] - qz[0]
        nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        t = (nx * qx[0] + ny * qy[0] + nz * qz[0]) / (nx * sx + ny * sy + nz * sz)
        good = smooth & (np.abs(t - best) <= np.float32(DISCONTINUITY_REL) * best)   # False where NaN / inf
    g = np.flatnonzero(good)
    out[sel[g]] = t[g]


def _camera_directions(table: OffsetTable, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Beam directions in camera ``k``'s frame, R^T s: three (N,) float32 arrays (cached)."""
    return table._cache(f"cam_dirs_{k}", lambda: tuple(
        np.ascontiguousarray(c, dtype=np.float32) for c in (table.directions @ table.cameras[k].rotation).T))
