"""Pinhole camera of the paper's Eqs 4-5 (docs/architecture.md).

Camera frame X right, Y up, Z forward. Image u right, v down, origin at the top-left corner of the image,
pixel (col i, row j) has its centre at (u, v) = (i + 0.5, j + 0.5). f = w / (2 tan(hfov / 2)) in pixels, square
pixels, principal point at the image centre (w/2, h/2).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Pinhole", "beam_directions", "paper_angles", "RigCamera", "Rig", "yaw_transform"]


@dataclass(frozen=True)
class Pinhole:
    """Intrinsics of one camera: ``width`` x ``height`` pixels and horizontal field of view ``hfov_rad``."""

    width: int
    height: int
    hfov_rad: float

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise ValueError(f"image size must be positive, got {self.width} x {self.height}")
        if not 0.0 < self.hfov_rad < math.pi:
            raise ValueError(f"hfov must lie in (0, pi) rad, got {self.hfov_rad}")

    @property
    def f(self) -> float:
        """Focal length in pixels."""
        return self.width / (2.0 * math.tan(self.hfov_rad / 2.0))

    @property
    def vfov_rad(self) -> float:
        """Vertical field of view, rad."""
        return 2.0 * math.atan(self.height / (2.0 * self.f))

    def project(self, points: np.ndarray) -> np.ndarray:
        """Camera-frame points (..., 3) in m to image coordinates (..., 2) (u, v) in pixels. Z must be > 0."""
        p = np.asarray(points, dtype=np.float64)
        z = p[..., 2]
        u = self.f * p[..., 0] / z + self.width / 2.0
        v = self.height / 2.0 - self.f * p[..., 1] / z
        return np.stack([u, v], axis=-1)

    def backproject(self, u: np.ndarray, v: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Eq 5: P = (Z/f) (u - w/2, h/2 - v, f) for planar depth Z (m); returns (..., 3) camera-frame m."""
        z = np.asarray(depth, dtype=np.float64)
        s = z / self.f
        return np.stack(
            [s * (np.asarray(u) - self.width / 2.0), s * (self.height / 2.0 - np.asarray(v)), z], axis=-1
        )

    def pixel_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(u, v) of every pixel centre, each (height, width) float64."""
        u = np.arange(self.width, dtype=np.float64) + 0.5
        v = np.arange(self.height, dtype=np.float64) + 0.5
        uu, vv = np.meshgrid(u, v)
        return uu, vv

    def rays_through(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Unit ray direction through the image points ``u``, ``v`` (px, float64, one shape), (..., 3) float64,
        camera frame."""
        d = np.stack([u - self.width / 2.0, self.height / 2.0 - v, np.full_like(u, self.f)], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def ray_directions(self) -> np.ndarray:
        """Unit ray direction through every pixel centre, (height, width, 3) float64, camera frame."""
        return self.rays_through(*self.pixel_centres())

    def ray_directions_at(self, pixels: np.ndarray) -> np.ndarray:
        """Unit ray directions (K, 3) float64, camera frame, through the centres of ``pixels`` (K,) (flat,
        row-major): the rows ``pixels`` of :meth:`ray_directions`, bit for bit, made for those pixels alone."""
        v, u = np.divmod(np.asarray(pixels, np.int64), self.width)
        return self.rays_through(u + 0.5, v + 0.5)


def beam_directions(elevation_rad: np.ndarray, azimuth_rad: np.ndarray) -> np.ndarray:
    """Unit beam directions (..., 3) in the LiDAR frame (X right, Y up, Z forward).

    ``elevation`` is the angle above the X-Z plane (towards +Y); ``azimuth`` is measured from +Z (forward)
    towards the left (-X), so positive azimuth turns left like a positive body yaw:
    s = (-cos e sin a, sin e, cos e cos a).
    """
    e = np.asarray(elevation_rad, dtype=np.float64)
    a = np.asarray(azimuth_rad, dtype=np.float64)
    ce = np.cos(e)
    return np.stack([-ce * np.sin(a), np.sin(e), ce * np.cos(a)], axis=-1)


def paper_angles(elevation_rad: np.ndarray, azimuth_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The paper's (theta, phi) for (elevation, azimuth): theta from +Y, phi from +X towards +Z.

    theta = pi/2 - elevation, phi = pi/2 + azimuth; then s = (sin th cos ph, cos th, sin th sin ph).
    """
    return np.pi / 2.0 - np.asarray(elevation_rad), np.pi / 2.0 + np.asarray(azimuth_rad)


def yaw_transform(yaw_left_rad: float) -> np.ndarray:
    """sensor_from_camera (4 x 4) for a rig camera turned ``yaw_left_rad`` to the left about the shared Y axis.

    A left turn is a rotation about +Y by -yaw: it takes the optical axis +Z to (-sin yaw, 0, cos yaw).
    """
    c, s = math.cos(yaw_left_rad), math.sin(yaw_left_rad)
    t = np.eye(4)
    t[:3, :3] = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    return t


@dataclass(frozen=True)
class RigCamera:
    """One camera of a rig: its intrinsics and its pose in the LiDAR (sensor) frame.

    ``sensor_from_camera`` is 4 x 4; rig cameras share the sensor origin and differ by yaw (and, for a tilted
    rig, pitch). ``name`` is the stem of its shared-memory image blocks (``<name>_depth``, ``<name>_rgb``).
    """

    name: str
    intrinsics: Pinhole
    sensor_from_camera: np.ndarray


@dataclass(frozen=True)
class Rig:
    """The cameras that together cover a LiDAR pattern."""

    cameras: tuple[RigCamera, ...]

    def __len__(self) -> int:
        return len(self.cameras)
