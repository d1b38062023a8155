"""Perception on uneven ground: the level frame put on the cart's ground plane (docs/field.md).

On flat ground the algorithms work in the sensor's parent body frame (the *level frame*, perception_proc.pipeline):
the cart's rim is level there at a known height. On the terrain the combine and the cart tilt and heave apart, and
a rim a few degrees off level in the parent's frame leaves the rim band (perception_proc.estimates.rim). The machines know
their attitude and height (an inclination sensor on each, RTK heights; the cart's come over Machine Sync), so the
points are moved into a frame that stands on the cart's ground plane under the parent, with the parent's heading:

    world_from_level = world_from_cart @ vehicle_pose(p.x, p.y, yaw_rel),   level_from_parent = inv(world_from_level) @ world_from_parent

(p the parent's origin in the cart's body frame, yaw_rel the parent's heading there). In it the cart stands level
at z = 0 as on flat ground; the own-vehicle mask is still applied in the parent's frame. :func:`level_from_parent`
is None when neither body tilts or heaves (flat ground: nothing changes, to the bit) or the sensor rides on the cart.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from cosim.scenario.config import Scenario
from cosim.world.geometry import POSE_3D_FIELDS, entity_pose, invert, vehicle_pose

__all__ = ["level_from_parent"]


def _level(state: Mapping[str, float], name: str) -> bool:
    return all(float(state.get(f"{name}_{f}", 0.0)) == 0.0 for f in POSE_3D_FIELDS)


def level_from_parent(scenario: Scenario, state: Mapping[str, float], parent: str | None = None
                      ) -> np.ndarray | None:
    """level_from_parent (4, 4) of this frame (the module docstring), or None when no correction is needed.
    ``parent``: the body whose frame perception works in (default: the LiDAR's parent)."""
    if parent is None:
        parent = scenario.lidar.mount.parent
    if parent == "cart" or not state or (_level(state, "cart") and (parent == "world" or _level(state, parent))):
        return None
    world_from_cart = entity_pose(state, "cart")
    world_from_parent = np.eye(4) if parent == "world" else entity_pose(state, parent)
    cart_from_parent = invert(world_from_cart) @ world_from_parent
    yaw = math.atan2(float(cart_from_parent[1, 0]), float(cart_from_parent[0, 0]))
    world_from_level = world_from_cart @ vehicle_pose(float(cart_from_parent[0, 3]), float(cart_from_parent[1, 3]), yaw)
    return invert(world_from_level) @ world_from_parent
