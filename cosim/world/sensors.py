"""Geometry of the named sensors (docs/cameras.md): each camera's pinhole and pose, and the names of its blocks.

Pure functions of the scenario records (cosim.scenario.config.cameras) and the dynamics state; the renderer,
perception, the plausibility checks and the observers all use them, so they agree by construction.

* Pose: ``world_from_sensor = world_from_parent @ mount_transform(mount) @ body_from_camera_axes()`` (camera
  axes X right, Y up, Z forward; det -1), as for the LiDAR (docs/CONTRACTS.md). ``level_from_sensor`` is the
  same without the parent's pose: the sensor in its parent's body frame (the *level frame* of perception).
* A stereo camera's left camera is the mount; the right camera sits ``baseline_m`` along the left camera's +X
  (to its right), with the same axes: ``left_from_right`` is a pure translation.
* Pinhole: ``width_px`` x ``height_px``, ``hfov_deg``; with the mock renderer every side of a colour or stereo
  camera is scaled by ``render.mock_scale`` (the ray caster costs microseconds per pixel, its shading more), the
  field of view kept; a depth camera keeps its own size (:func:`mock_scaled`).
  ``K = [[f, 0, w/2], [0, f, h/2], [0, 0, 1]]`` maps camera-frame (X, -Y, Z) to pixels (u right, v down).
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from cosim.scenario.config.cameras import Camera, DepthCamera, StereoCamera
from cosim.scenario.config.scenario import Scenario
from cosim.world.camera import Pinhole
from cosim.world.geometry import body_from_camera_axes, entity_pose, make_transform, mount_transform

__all__ = ["MIN_SIDE_PX", "BLOCK_PREFIX", "mock_scaled", "camera_pinhole", "points_stride", "intrinsics_matrix",
           "level_from_sensor", "world_from_parent", "world_from_sensor", "left_from_right", "camera_block", "camera_views", "camera_parts"]

#: smallest image side after the mock's scaling, px
MIN_SIDE_PX = 8
#: every camera block is named ``cam_<sensor>_<part>`` (rig cameras are ``cam<k>_...``: no clash)
BLOCK_PREFIX = "cam_"


def mock_scaled(cam: Camera, scenario: Scenario) -> bool:
    """Whether ``cam`` renders at ``render.mock_scale`` of its size: under the mock renderer, every camera but a
    depth camera. A depth camera keeps its own pixels: its error model (lateral displacement and mixed pixels at
    edges) is per pixel of the device, so a coarser image is another, worse sensor. Its depth alone is cast
    through the run's rigid bodies (microseconds a ray); read with colour or labels it takes the labelled numpy
    cast, about 5 us a pixel (renderer_proc.mock.camera)."""
    return scenario.renderer == "mock" and not isinstance(cam, DepthCamera)


def camera_pinhole(cam: Camera, scenario: Scenario) -> Pinhole:
    """The pinhole the run renders ``cam`` with: its own size, or scaled by ``render.mock_scale`` where
    :func:`mock_scaled` (same horizontal field of view)."""
    w, h = cam.width_px, cam.height_px
    if mock_scaled(cam, scenario):
        k = scenario.render.mock_scale
        w, h = max(MIN_SIDE_PX, round(w * k)), max(MIN_SIDE_PX, round(h * k))
    return Pinhole(w, h, float(np.radians(cam.hfov_deg)))


def points_stride(cam: Camera, scenario: Scenario) -> int:
    """The pixel stride of the camera's points for perception: ``points_stride``, scaled like the image where
    :func:`mock_scaled` (at least 1), so that a camera gives about the same points whichever renderer draws it."""
    if mock_scaled(cam, scenario):
        return max(1, round(cam.points_stride * scenario.render.mock_scale))
    return cam.points_stride


def intrinsics_matrix(pin: Pinhole) -> np.ndarray:
    """K (3, 3) float64 of a pinhole: focal f px, principal point at the image centre (w/2, h/2), v down."""
    return np.array([[pin.f, 0.0, pin.width / 2.0], [0.0, pin.f, pin.height / 2.0], [0.0, 0.0, 1.0]])


def level_from_sensor(sensor) -> np.ndarray:
    """(4, 4) float64: the sensor (camera axes) in its parent's body frame, ``mount @ body_from_camera_axes``."""
    return mount_transform(sensor.mount) @ body_from_camera_axes()


def world_from_parent(parent: str, state: Mapping[str, float]) -> np.ndarray:
    """(4, 4) world_from_body of ``parent`` (``world``, ``combine``, ``tractor`` or ``cart``) from dyn_state (on
    uneven ground with its height, roll and pitch: ``cosim.world.geometry.entity_pose``)."""
    if parent == "world":
        return np.eye(4)
    return entity_pose(state, parent)


def world_from_sensor(sensor, state: Mapping[str, float]) -> np.ndarray:
    """(4, 4) the sensor's pose in the world (camera axes, det -1) at the dynamics state ``state``."""
    return world_from_parent(sensor.mount.parent, state) @ level_from_sensor(sensor)


def left_from_right(baseline_m: float) -> np.ndarray:
    """(4, 4) the right camera of a stereo pair in the left camera's frame: ``baseline_m`` along +X."""
    return make_transform(np.eye(3), (baseline_m, 0.0, 0.0))


def camera_block(name: str, part: str) -> str:
    """The shared-memory block of part ``part`` (``rgb``, ``depth``, ``labels``, ``right``, ...) of camera
    ``name``: ``cam_<name>_<part>``."""
    return f"{BLOCK_PREFIX}{name}_{part}"


def camera_views(name: str, cam: Camera) -> list[tuple[str, np.ndarray]]:
    """The views a camera renders, (label, sensor_from_view (4, 4)): the camera itself (``left`` for a stereo
    pair, which also has ``right``)."""
    if isinstance(cam, StereoCamera):
        return [("left", np.eye(4)), ("right", left_from_right(cam.baseline_m))]
    return [(name, np.eye(4))]


def camera_parts(cam: Camera) -> list[tuple[int, str]]:
    """What the renderer writes for a camera, as (view index into :func:`camera_views`, part): ``rgb`` (the
    colour image: rgb and stereo cameras, a depth camera with ``rgb``), ``right`` (a stereo pair's right image),
    ``depth`` (exact planar depth: the depth camera's input) and ``labels`` (when asked)."""
    parts: list[tuple[int, str]] = []
    if cam.kind in ("rgb_camera", "stereo_camera") or getattr(cam, "rgb", False):
        parts.append((0, "rgb"))
    if isinstance(cam, StereoCamera):
        parts.append((1, "right"))
    if cam.kind == "depth_camera":
        parts.append((0, "depth"))
    if cam.labels:
        parts.append((0, "labels"))
    return parts
