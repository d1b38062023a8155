"""Rigid transforms and the project's frame conventions (docs/architecture.md).

* World and body frames: x forward, y left, z up; vehicle origin on the ground.
* Camera / LiDAR frame (the paper's): X right, Y up, Z forward along the optical axis. This frame is
  left-handed (as in Unreal), so ``BODY_FROM_CAMERA`` is a reflection (det -1), not a rotation; every
  transform here stays orthogonal, and ``invert`` (transpose) remains exact.
* Cart grid frame: origin at the front-left corner of the interior floor, x from the front inner wall towards
  the rear (0..L), y across from the left wall towards the right (0..W), z up from the floor. It is the cart
  body frame turned by 180 degrees about z, so it stays right-handed.

All transforms are 4 x 4 float64 homogeneous matrices named ``a_from_b``: ``p_a = a_from_b @ p_b``.
"""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config.base import Mount
from cosim.scenario.config.machines import Cart

__all__ = [
    "rot_x", "rot_y", "rot_z", "rpy_matrix", "make_transform", "invert", "apply",
    "vehicle_pose", "body_pose", "entity_pose", "POSE_3D_FIELDS", "mount_transform", "BODY_FROM_CAMERA", "body_from_camera_axes",
    "cart_body_from_grid", "cart_grid_from_body",
]


def rot_x(a: float) -> np.ndarray:
    """Rotation by ``a`` rad about +x, 3 x 3."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """Rotation by ``a`` rad about +y, 3 x 3. In a y-left body frame positive angles tip +x downwards."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """Rotation by ``a`` rad about +z, 3 x 3 (positive turns +x towards +y, i.e. to the left)."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), angles in rad, 3 x 3."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def _identity4() -> np.ndarray:
    """A new 4 x 4 identity (float64), for transforms whose upper rows are overwritten: the values of
    ``np.eye(4)`` at a third of its cost (the dynamics builds a few transforms every frame)."""
    t = np.zeros((4, 4))
    t[3, 3] = 1.0
    return t


def make_transform(rotation: np.ndarray, translation) -> np.ndarray:
    """4 x 4 homogeneous transform from a 3 x 3 rotation and a 3-vector translation."""
    t = _identity4()
    t[:3, :3] = rotation
    t[:3, 3] = np.asarray(translation, dtype=np.float64)
    return t


def invert(t: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4 x 4 transform."""
    out = _identity4()
    r = t[:3, :3]
    out[:3, :3] = r.T
    out[:3, 3] = -r.T @ t[:3, 3]
    return out


def apply(t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4 x 4 transform to points of shape (..., 3); returns the same shape."""
    p = np.asarray(points, dtype=np.float64)
    return p @ t[:3, :3].T + t[:3, 3]


def vehicle_pose(x_m: float, y_m: float, yaw_rad: float, z_m: float = 0.0) -> np.ndarray:
    """world_from_body for a vehicle on flat ground at (x, y) with heading ``yaw`` (rad from world +x)."""
    return make_transform(rot_z(yaw_rad), (x_m, y_m, z_m))


def body_pose(x_m: float, y_m: float, yaw_rad: float, z_m: float = 0.0, roll_rad: float = 0.0,
              pitch_rad: float = 0.0) -> np.ndarray:
    """world_from_body of a vehicle standing on the terrain: R = Rz(yaw) Ry(pitch) Rx(roll), origin (x, y, z).
    Level (roll = pitch = 0) it is :func:`vehicle_pose` to the bit."""
    if roll_rad == 0.0 and pitch_rad == 0.0:
        return vehicle_pose(x_m, y_m, yaw_rad, z_m)
    return make_transform(rpy_matrix(roll_rad, pitch_rad, yaw_rad), (x_m, y_m, z_m))


#: the dyn_state fields of an entity's pose beyond the planar (x, y, yaw) (docs/CONTRACTS.md)
POSE_3D_FIELDS = ("z_m", "roll_rad", "pitch_rad")


def entity_pose(state, name: str) -> np.ndarray:
    """world_from_body (4 x 4) of entity ``name`` (combine, tractor, cart) from the ``dyn_state`` fields
    ``<name>_{x_m, y_m, yaw_rad}`` and, where the state has them, ``<name>_{z_m, roll_rad, pitch_rad}`` (a
    mapping of field names to numbers)."""
    extra = [float(state[f"{name}_{f}"]) if f"{name}_{f}" in state else 0.0 for f in POSE_3D_FIELDS]
    return body_pose(float(state[f"{name}_x_m"]), float(state[f"{name}_y_m"]), float(state[f"{name}_yaw_rad"]),
                     *extra)


def mount_transform(mount: Mount) -> np.ndarray:
    """parent_from_mount for a :class:`~cosim.scenario.config.base.Mount` (body-convention axes, x forward)."""
    r, p, y = (math.radians(a) for a in mount.rpy_deg)
    return make_transform(rpy_matrix(r, p, y), mount.xyz_m)


#: body_from_camera axes: camera X right = -y_body, Y up = +z_body, Z forward = +x_body (3 x 3, columns are the
#: camera axes expressed in the body frame).
BODY_FROM_CAMERA = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def body_from_camera_axes() -> np.ndarray:
    """4 x 4 transform that re-expresses camera-convention axes (X right, Y up, Z fwd) in body axes."""
    return make_transform(BODY_FROM_CAMERA, (0.0, 0.0, 0.0))


def cart_body_from_grid(cart: Cart) -> np.ndarray:
    """cart_body_from_grid: the grid origin is the front-left interior floor corner, axes turned 180 deg."""
    return make_transform(
        rot_z(math.pi), (cart.interior_length_m / 2.0, cart.interior_width_m / 2.0, cart.floor_height_m)
    )


def cart_grid_from_body(cart: Cart) -> np.ndarray:
    """Inverse of :func:`cart_body_from_grid`."""
    return invert(cart_body_from_grid(cart))
