"""The machines on the terrain: heave, roll and pitch of each body from the ground under its wheels.

The planar motion (dynamics_proc.vehicles.motion: x, y, yaw) is the projection of the motion on the ground; the terrain
(cosim.world.terrain) adds, per body, the plane through its contact points (cosim.world.parts.wheel_contacts,
body frame): least squares ``z = z0 + a xb + b yb`` over the contacts' ground heights, the pseudo-inverse of the
body's contact matrix computed once. A rigid body on four wheels touches only three of them on uneven ground:
the least-squares plane is the average a compliant suspension takes (exact on a plane). The plane gives the
body's pose (cosim.world.geometry.body_pose, R = Rz(yaw) Ry(pitch) Rx(roll)): its z axis is the plane's normal
(-a, -b, 1) / |.|, its x axis stays in the vertical plane of the heading, so

    pitch = -atan(a),   roll = atan2(b, sqrt(1 + a^2)),   z = z0 (the body origin is on the ground).

The cart stands on its two wheels and on its tongue tip, which rests on the tractor's hitch: the third support
point is the hitch (the tractor's pose applied to its hitch point, ``HITCH_HEIGHT_M`` up its body z axis) moved
back down ``HITCH_HEIGHT_M`` along that axis, and the cart's plane passes through it and its two wheels' ground
points: exact on a plane (cart and tractor share the normal); on rough ground off by ``HITCH_HEIGHT_M`` times the
difference of the two normals (under a tenth of a millimetre at 3 degrees).
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

import numpy as np

from cosim.scenario.config import Scenario
from cosim.world.geometry import body_pose, invert
from cosim.world.parts import HITCH_HEIGHT_M, wheel_contacts
from cosim.world.terrain import Terrain, terrain_of
from dynamics_proc.vehicles.motion import CX, CY, CYAW, cart_pose, tractor_pose

__all__ = ["Stance", "Pose3", "stance_of", "plane_pose", "machine_poses", "planar_poses", "spout_on_terrain"]

#: a body's full pose: (x m, y m, yaw rad, z m, roll rad, pitch rad), world
Pose3 = tuple[float, float, float, float, float, float]


@dataclass(frozen=True)
class Stance:
    """Where the machines touch the terrain: the terrain, each body's contact points (K, 2) body xy m and the
    pseudo-inverse (3, K) of its contact matrix [1, xb, yb]; the tractor's hitch point (body frame, m)."""

    terrain: Terrain
    contacts: dict
    pinv: dict
    hitch_body: np.ndarray
    #: the last :func:`machine_poses` asked ("key": its planar poses' bytes, "poses": its answer): a frame asks
    #: it for the same planar poses more than once (the spout, the recorded signals)
    _last: dict = field(default_factory=dict, compare=False, repr=False)


def stance_of(s: Scenario, hitch_x_m: float) -> Stance | None:
    """The scenario's :class:`Stance` (``hitch_x_m``: the hitch's tractor body x, m), None on flat ground."""
    terrain = terrain_of(s)
    if terrain is None:
        return None
    contacts = wheel_contacts(s)
    pinv = {k: np.linalg.pinv(np.column_stack([np.ones(len(c)), c])) for k, c in contacts.items()}
    return Stance(terrain, contacts, pinv, np.array([hitch_x_m, 0.0, HITCH_HEIGHT_M]))


def plane_pose(heights: np.ndarray, pinv: np.ndarray) -> tuple[float, float, float]:
    """(z m, roll rad, pitch rad) of a body whose contacts stand at ground ``heights`` (K,) m (the module
    docstring)."""
    z0, a, b = (float(v) for v in pinv @ heights)
    return z0, math.atan2(b, math.sqrt(1.0 + a * a)), -math.atan(a)


def _ground_under(st: Stance, name: str, x: float, y: float, yaw: float) -> np.ndarray:
    c, sn = math.cos(yaw), math.sin(yaw)
    xy = st.contacts[name]
    return st.terrain.height(x + c * xy[:, 0] - sn * xy[:, 1], y + sn * xy[:, 0] + c * xy[:, 1])


def machine_poses(st: Stance, combine: tuple[float, float, float], tractor: tuple[float, float, float],
                  cart: tuple[float, float, float]) -> tuple[Pose3, Pose3, Pose3]:
    """Full poses of the combine, the tractor and the cart from their planar poses (x m, y m, yaw rad); the
    last answer again when asked for the same poses, bit for bit (:attr:`Stance._last`)."""
    key = struct.pack("9d", *combine, *tractor, *cart)
    if st._last.get("key") == key:
        return st._last["poses"]
    poses = _machine_poses(st, combine, tractor, cart)
    st._last.update(key=key, poses=poses)
    return poses


def _machine_poses(st: Stance, combine: tuple[float, float, float], tractor: tuple[float, float, float],
                   cart: tuple[float, float, float]) -> tuple[Pose3, Pose3, Pose3]:
    """:func:`machine_poses` computed."""
    out = []
    for name, (x, y, yaw) in (("combine", combine), ("tractor", tractor)):
        out.append((x, y, yaw, *plane_pose(_ground_under(st, name, x, y, yaw), st.pinv[name])))
    tractor_pose3 = body_pose(*out[1])
    x, y, yaw = cart
    wheels = _ground_under(st, "cart", x, y, yaw)[:2]
    # the tongue tip stands HITCH_HEIGHT_M above its support along the body's z axis (the tractor's: exact on a
    # plane, where both share the normal), under the hitch's true position
    n = tractor_pose3[:3, 2]
    support_world = tractor_pose3[:3, :3] @ st.hitch_body + tractor_pose3[:3, 3] - HITCH_HEIGHT_M * n
    c, sn = math.cos(yaw), math.sin(yaw)
    dx, dy = float(support_world[0]) - x, float(support_world[1]) - y
    xy = np.vstack([st.contacts["cart"][:2], [c * dx + sn * dy, -sn * dx + c * dy]])
    m = np.column_stack([np.ones(3), xy])
    out.append((x, y, yaw, *plane_pose(np.append(wheels, float(support_world[2])), np.linalg.inv(m))))
    return out[0], out[1], out[2]


def planar_poses(x: np.ndarray, vp) -> tuple[tuple[float, float, float], ...]:
    """(combine, tractor, cart) planar poses (x m, y m, yaw rad), world, of the vehicle state ``x`` (9,)
    (dynamics_proc.vehicles.motion)."""
    return (float(x[CX]), float(x[CY]), float(x[CYAW])), tractor_pose(x, vp), cart_pose(x, vp)


def spout_on_terrain(x: np.ndarray, vp, auger, grid_from_cart_body: np.ndarray, st: Stance):
    """(spout world (3,), exit velocity world (3,), spout grid (3,), grid_from_world (4, 4)) with the combine and
    the cart standing on the terrain: the spout and its exit velocity turn with the combine's full pose, the
    grid frame with the cart's (dynamics_proc.model.spout_grid on flat ground)."""
    combine, _, cart = machine_poses(st, *planar_poses(x, vp))
    wc = body_pose(*combine)
    spout_body = np.add(auger.pivot, auger.arm)
    sp = wc[:3, :3] @ spout_body + wc[:3, 3]
    vel = wc[:3, :3] @ (auger.exit_speed_mps * np.asarray(auger.exit_dir))
    g = grid_from_cart_body @ invert(body_pose(*cart))
    return sp, vel, g[:3, :3] @ sp + g[:3, 3], g

