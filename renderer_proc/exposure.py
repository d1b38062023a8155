"""A view's motion over its exposure (docs/cameras.md, "Motion blur"): the poses at the exposure's start, from the
dynamics states of the previous and this frame, and the blurred image (renderer_proc.motion_blur).

The exposure of ``exposure_ms`` ends at the frame's time. The machines' poses at its start are interpolated
linearly (yaw the short way round) between the previous frame's state and this one's: their motion over one frame
period is uniform to well within the blur's needs. The camera's pose at the start is its mount on its parent at
that pose. Each pixel's body comes from the view's labels: the ground is still in the world; the cart's walls,
rim and grain move with the cart, the combine and its auger with the combine, the tractor with the tractor; the
grain stream is taken as moving with the combine (its fall within the exposure is not modelled).
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from cosim.world import labels as lb
from cosim.world.camera import Pinhole
from cosim.world.geometry import POSE_3D_FIELDS, entity_pose
from cosim.world.sensors import world_from_sensor
from renderer_proc.motion_blur import blur, pixel_displacement

__all__ = ["BODIES", "BODY_OF_LABEL", "state_at", "view_displacement", "blurred"]

#: the moving bodies, in the order of a pixel's body index
BODIES = ("combine", "tractor", "cart")
#: label code -> body index into BODIES (len(BODIES): still in the world)
BODY_OF_LABEL = np.full(256, len(BODIES), np.int64)
for _label, _body in ((lb.COMBINE, 0), (lb.AUGER, 0), (lb.STREAM, 0), (lb.TRACTOR, 1), (lb.CART_WALL, 2),
                      (lb.CART_RIM, 2), (lb.GRAIN, 2)):
    BODY_OF_LABEL[_label] = _body
_POSE = ("x_m", "y_m", "yaw_rad") + POSE_3D_FIELDS


def state_at(before: Mapping[str, float], now: Mapping[str, float], t_s: float) -> dict[str, float]:
    """``now`` with the machines' pose fields at time ``t_s`` (s): linear between ``before`` and ``now`` (their
    ``t_s``), the yaw the short way round; ``now`` itself when the two share a time."""
    t0, t1 = float(before.get("t_s", 0.0)), float(now.get("t_s", 0.0))
    if t1 == t0:
        return dict(now)
    a = (t_s - t0) / (t1 - t0)
    out = dict(now)
    for body in BODIES:
        for f in _POSE:
            key = f"{body}_{f}"
            if key in now and key in before:
                step = float(now[key]) - float(before[key])
                if f == "yaw_rad":
                    step = math.remainder(step, 2.0 * math.pi)
                out[key] = float(before[key]) + a * step
    return out


def view_displacement(depth: np.ndarray, label: np.ndarray, pin: Pinhole, spec, view_pose: np.ndarray,
                      before: Mapping[str, float], now: Mapping[str, float]) -> np.ndarray:
    """(H, W, 2) float32 px: each pixel's image motion over camera ``spec``'s exposure (``exposure_ms``) ending at
    state ``now`` (renderer_proc.motion_blur.pixel_displacement); ``depth`` (H, W) planar m and ``label`` (H, W)
    uint8 of the view, ``view_pose`` its sensor_from_view (4, 4), ``before`` the previous frame's state."""
    start = state_at(before, now, float(now.get("t_s", 0.0)) - spec.exposure_ms * 1e-3)
    cam_end = world_from_sensor(spec, now) @ view_pose
    cam_start = world_from_sensor(spec, start) @ view_pose
    motions = [entity_pose(start, b) @ np.linalg.inv(entity_pose(now, b)) for b in BODIES]
    return pixel_displacement(depth, pin, cam_end, cam_start, BODY_OF_LABEL[label], motions)


def blurred(image: np.ndarray, depth: np.ndarray, label: np.ndarray, pin: Pinhole, spec, view_pose: np.ndarray,
            before: Mapping[str, float], now: Mapping[str, float]) -> np.ndarray:
    """View image (H, W, 4) uint8 blurred over the exposure (:func:`view_displacement`'s arguments)."""
    return blur(image, view_displacement(depth, label, pin, spec, view_pose, before, now))
