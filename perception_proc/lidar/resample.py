"""LiDAR from camera images, co-located case (the paper's Eqs 6-7, corrected; docs/CONTRACTS.md).

Every beam of the pattern is assigned to exactly one rig camera: the one whose optical axis it is closest to
(largest cosine), provided its image point lies inside that camera's image. Within the camera the beam's image
point is, with s_c the unit beam direction in that camera's frame,

    u = f X/Z + w/2,  v = h/2 - f Y/Z        (the corrected Eq 7: X = f cot(phi), Y = f cot(theta) / sin(phi)
                                             for a camera aligned with the LiDAR),

and a hit at planar depth Z lies at range Z r / f = Z / s_c.z (Eq 6). The tables (which camera, which pixels,
which weights, the planar-to-range scale) are computed once per rig; per frame the work is a gather of 32-bit
RGBA words, Eq 3 on the gathered bytes and a multiply.

Two samplers:

* ``nearest`` - the paper's: the pixel whose centre is nearest the beam's image point (pixel centres at
  half-integers, so column floor(u), row floor(v)).
* ``planar`` (default) - inverse depth 1/Z is an affine function of (u, v) on any plane, so bilinear
  interpolation of 1/Z over the 2 x 2 pixel centres around the image point is exact on planes. It is used
  only where the four decoded depths are continuous (spread below :data:`DISCONTINUITY_REL` of the depth plus
  the codec bound); across an edge, or at the image border, the beam falls back to its nearest pixel. Bytes
  are never filtered: each of the four pixels is decoded first.

A LiDAR mounted away from the camera centre is handled by :mod:`perception_proc.lidar.resample_offset`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np

from cosim.scenario.config import Codec
from cosim.world.camera import Rig
from perception_proc.lidar.codec import decode_lut, decode_words

__all__ = [
    "CameraTable", "ResampleTable", "build_table", "gather_depth", "resample", "beam_pixels",
    "paper_pixel", "DISCONTINUITY_REL", "Sampler", "words_of", "beam_words", "depth_from_words", "resample_words",
]

#: two decoded depths of a 2 x 2 neighbourhood farther apart than this fraction of the nearer one are an edge
DISCONTINUITY_REL = 0.05
#: a camera centre within this distance of the LiDAR origin counts as co-located, m
CENTRE_EPS_M = 1e-9
#: cosine below which a beam is behind a camera's image plane (it can never be seen there)
MIN_AXIS_COSINE = 1e-6

Sampler = Literal["nearest", "planar"]


@dataclass(frozen=True)
class CameraTable:
    """The beams one rig camera serves and where to read them.

    ``beams`` (M,) int64 indices into the pattern; ``pixel`` (M,) int64 flat index row * W + col of the nearest
    pixel; ``quad`` (M, 4) int64 flat indices of the 2 x 2 neighbours (00, 10, 01, 11; clamped in the image);
    ``weight`` (M, 4) float32 bilinear weights; ``interp`` (M,) bool whether the full 2 x 2 lies in the image;
    ``scale`` (M,) float32 range per planar depth (1 / s_c.z, dimensionless); ``uv`` (M, 2) float64 image point.
    ``quad_t`` (4, M) and ``weight_t`` (4, M) are C-contiguous transposes for the per-frame gather.
    """

    name: str
    beams: np.ndarray
    pixel: np.ndarray
    quad: np.ndarray
    weight: np.ndarray
    interp: np.ndarray
    scale: np.ndarray
    uv: np.ndarray

    @property
    def quad_t(self) -> np.ndarray:
        return self._cache("quad_t", lambda: np.ascontiguousarray(self.quad.T))

    @property
    def weight_t(self) -> np.ndarray:
        return self._cache("weight_t", lambda: np.ascontiguousarray(self.weight.T))

    @property
    def near_k(self) -> np.ndarray:
        """(M,) int64: which of the four (clamped) neighbours is the nearest pixel."""
        return self._cache("near_k", lambda: np.argmax(self.quad == self.pixel[:, None], axis=1))

    @property
    def near_flat(self) -> np.ndarray:
        """(M,) int64: flat index into a C-contiguous (4, M) array of the nearest of the four neighbours."""
        return self._cache("near_flat", lambda: self.near_k * self.pixel.size + np.arange(self.pixel.size))

    @property
    def max_pixel(self) -> int:
        """The largest flat pixel index any beam reads (an image must have more pixels)."""
        return self._cache("max_pixel", lambda: int(max(self.pixel.max(initial=0), self.quad.max(initial=0))))

    def _cache(self, key: str, make):
        store = self.__dict__.setdefault("_derived", {})
        if key not in store:
            store[key] = make()
        return store[key]


@dataclass(frozen=True)
class ResampleTable:
    """Per-rig tables: ``directions`` (N, 3) float64 unit beams in the sensor frame; ``covered`` (N,) bool."""

    directions: np.ndarray
    cameras: tuple[CameraTable, ...]
    covered: np.ndarray

    @property
    def n_beams(self) -> int:
        return int(self.directions.shape[0])

    @property
    def source(self) -> np.ndarray:
        """(N,) int64: where each beam's range lies in the cameras' ranges laid end to end (rig order, each
        camera's beams in its ``beams`` order), followed by one NaN slot that uncovered beams read."""
        store = self.__dict__.setdefault("_derived", {})
        if "source" not in store:
            src = np.full(self.n_beams, sum(c.beams.size for c in self.cameras), np.int64)
            offset = 0
            for c in self.cameras:
                src[c.beams] = offset + np.arange(c.beams.size)
                offset += c.beams.size
            store["source"] = src
        return store["source"]


def paper_pixel(theta: np.ndarray, phi: np.ndarray, width: int, height: int, f: float) -> tuple[np.ndarray, np.ndarray]:
    """Eqs 6-7 as printed but with cos(phi) in the u term (docs/CONTRACTS.md), before rounding.

    ``theta`` polar angle from +Y, ``phi`` azimuth from +X towards +Z (rad, any shape), LiDAR aligned with the
    camera. r = f / (sin th sin ph); u = r sin th cos ph + w/2; v = h/2 - r cos th. Returns (u, v) in pixels.
    """
    r = f / (np.sin(theta) * np.sin(phi))
    return r * np.sin(theta) * np.cos(phi) + width / 2.0, height / 2.0 - r * np.cos(theta)


def beam_pixels(directions_cam: np.ndarray, width: int, height: int, f: float) -> tuple[np.ndarray, np.ndarray]:
    """Image point (u, v) of camera-frame directions (..., 3); NaN where the direction is not in front."""
    z = directions_cam[..., 2]
    ok = z > MIN_AXIS_COSINE
    zs = np.where(ok, z, 1.0)
    u = np.where(ok, f * directions_cam[..., 0] / zs + width / 2.0, np.nan)
    v = np.where(ok, height / 2.0 - f * directions_cam[..., 1] / zs, np.nan)
    return u, v


def build_table(rig: Rig, directions: np.ndarray) -> ResampleTable:
    """Assign every beam to one camera and precompute its pixels, weights and scale.

    ``directions``: (N, 3) unit beams in the sensor frame. The rig cameras must share the sensor origin (their
    ``sensor_from_camera`` has no translation); use :mod:`perception_proc.lidar.resample_offset` otherwise.
    """
    d = np.asarray(directions, dtype=np.float64)
    n = d.shape[0]
    cams = rig.cameras
    for c in cams:
        if np.linalg.norm(c.sensor_from_camera[:3, 3]) > CENTRE_EPS_M:
            raise ValueError(
                f"camera {c.name!r} is {np.linalg.norm(c.sensor_from_camera[:3, 3]):.3g} m from the LiDAR origin: "
                "build_table needs cameras that share the sensor origin; use resample_offset.build_offset_table"
            )
    # cosine to each camera's optical axis; the axis in the sensor frame is the third rotation column
    axes = np.stack([c.sensor_from_camera[:3, 2] for c in cams])            # (C, 3)
    cosines = d @ axes.T                                                   # (N, C)
    inside = np.zeros((n, len(cams)), dtype=bool)
    uvs = []
    for k, cam in enumerate(cams):
        dc = d @ cam.sensor_from_camera[:3, :3]                            # camera_from_sensor applied
        u, v = beam_pixels(dc, cam.intrinsics.width, cam.intrinsics.height, cam.intrinsics.f)
        inside[:, k] = (u >= 0) & (u < cam.intrinsics.width) & (v >= 0) & (v < cam.intrinsics.height)
        uvs.append((u, v, dc[:, 2]))
    score = np.where(inside, cosines, -np.inf)
    owner = np.argmax(score, axis=1)
    covered = inside.any(axis=1)
    tables = []
    for k, cam in enumerate(cams):
        sel = np.flatnonzero(covered & (owner == k))
        u, v, z = (a[sel] for a in uvs[k])
        w, h = cam.intrinsics.width, cam.intrinsics.height
        col = np.clip(np.floor(u).astype(np.int64), 0, w - 1)
        row = np.clip(np.floor(v).astype(np.int64), 0, h - 1)
        x, y = u - 0.5, v - 0.5
        i0, j0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
        fx, fy = x - i0, y - j0
        interp = (i0 >= 0) & (i0 + 1 <= w - 1) & (j0 >= 0) & (j0 + 1 <= h - 1)
        i0c, i1c = np.clip(i0, 0, w - 1), np.clip(i0 + 1, 0, w - 1)
        j0c, j1c = np.clip(j0, 0, h - 1), np.clip(j0 + 1, 0, h - 1)
        quad = np.stack([j0c * w + i0c, j0c * w + i1c, j1c * w + i0c, j1c * w + i1c], axis=1)
        weight = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1)
        tables.append(CameraTable(
            name=cam.name, beams=sel.astype(np.int64), pixel=row * w + col, quad=quad,
            weight=weight.astype(np.float32), interp=interp, scale=(1.0 / z).astype(np.float32),
            uv=np.stack([u, v], axis=1),
        ))
    return ResampleTable(directions=d, cameras=tuple(tables), covered=covered)


def words_of(rgba: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8 C-contiguous image -> flat (H*W,) uint32 view (no copy), one RGBA word per pixel."""
    if not rgba.flags.c_contiguous:
        rgba = np.ascontiguousarray(rgba)
    return rgba.reshape(-1).view(np.uint32)


def beam_words(rgba: np.ndarray, table: CameraTable, sampler: Sampler = "planar") -> np.ndarray:
    """The raw RGBA words the camera's beams read, a copy: (4, M) uint32 (the 2 x 2 patches) for ``planar``,
    (M,) for ``nearest``. The only read of the image: the rest (:func:`depth_from_words`) can run after the
    image has been overwritten."""
    words = words_of(rgba)
    if words.size <= table.max_pixel:
        raise ValueError(f"camera {table.name!r}: image of {words.size} pixels, the table reads pixel "
                         f"{table.max_pixel}")
    # mode "wrap": every index lies in the image (checked above), and the wrapping gather skips the
    # per-index range check of the default (a fifth of the gather's instructions)
    return np.take(words, table.pixel if sampler == "nearest" else table.quad_t, mode="wrap")


def depth_from_words(words: np.ndarray, table: CameraTable, codec: Codec, sampler: Sampler = "planar") -> np.ndarray:
    """Planar depth Z (M,) float32, m, NaN where invalid, from :func:`beam_words`' words."""
    z = decode_words(words, decode_lut(codec))                             # planar: (4, M), one decode
    if sampler == "nearest":
        return z
    with np.errstate(invalid="ignore", divide="ignore"):
        # the four rows' minimum and maximum (what z.min(axis=0) does, in two-operand steps: half the work);
        # NaN propagates: no interpolation
        zmin, zmax = np.minimum(z[0], z[1]), np.maximum(z[0], z[1])
        for k in (2, 3):
            np.minimum(zmin, z[k], out=zmin)
            np.maximum(zmax, z[k], out=zmax)
        smooth = zmax - zmin <= np.float32(DISCONTINUITY_REL) * zmin + np.float32(2.0 * codec.bound_m)
        smooth &= table.interp
        z_lin = np.float32(1.0) / (table.weight_t / z).sum(axis=0)
    z_near = np.take(z, table.near_flat, mode="wrap")                      # nearest pixel is one of the four
    return np.where(smooth, z_lin, z_near)


def gather_depth(rgba: np.ndarray, table: CameraTable, codec: Codec, sampler: Sampler = "planar") -> np.ndarray:
    """Planar depth Z (M,) float32, m, at the camera's beams; NaN where invalid. ``rgba``: (H, W, 4) uint8."""
    return depth_from_words(beam_words(rgba, table, sampler), table, codec, sampler)


def resample(images: Sequence[np.ndarray], table: ResampleTable, codec: Codec, sampler: Sampler = "planar",
             out: np.ndarray | None = None) -> np.ndarray:
    """Ranges of every beam, (N,) float32, m, NaN where no valid return.

    ``images``: one (H, W, 4) uint8 depth image per rig camera, in rig order. ``out``: optional (N,) float32
    destination, filled in place and returned.
    """
    if len(images) != len(table.cameras):
        raise ValueError(f"expected {len(table.cameras)} images (one per rig camera), got {len(images)}")
    return resample_words([beam_words(img, cam, sampler) for img, cam in zip(images, table.cameras)], table, codec,
                          sampler, out)


def resample_words(words: Sequence[np.ndarray], table: ResampleTable, codec: Codec, sampler: Sampler = "planar",
                   out: np.ndarray | None = None) -> np.ndarray:
    """:func:`resample` from each camera's :func:`beam_words`, in rig order."""
    # each camera's ranges end to end, then one gather into pattern order (cheaper than a scatter per camera)
    parts = np.empty(sum(c.beams.size for c in table.cameras) + 1, np.float32)
    parts[-1] = np.nan                                                     # the slot uncovered beams read
    offset = 0
    for w, cam in zip(words, table.cameras):
        np.multiply(depth_from_words(w, cam, codec, sampler), cam.scale, out=parts[offset:offset + cam.beams.size])
        offset += cam.beams.size
    rng = np.empty(table.n_beams, dtype=np.float32) if out is None else out
    return np.take(parts, table.source, out=rng, mode="wrap")            # indices valid by construction
