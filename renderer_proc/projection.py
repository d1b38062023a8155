"""Camera poses and the GL view / projection matrices, written once (docs/architecture.md).

The paper's camera frame (X right, Y up, Z forward) is left-handed; GL view space is right-handed with -z
forward. ``GL_FROM_CAMERA = diag(1, 1, -1)`` converts between them, so GL view z = -Z and planar camera depth
is ``-z_view``. The projection maps a pixel centre (u, v) = (i + 0.5, j + 0.5) of our top-down image to GL
window (x, y) = (i + 0.5, j + 0.5): the image is flipped in the projection (clip y = -y), so GL's bottom-up
framebuffer row j is our image row j and ``glReadPixels`` fills a top-down (H, W, 4) array with no copy.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from cosim.scenario.config.scenario import Scenario
from cosim.world.camera import Pinhole, Rig
from cosim.world.geometry import body_from_camera_axes, entity_pose, invert, mount_transform

__all__ = [
    "FAR_MARGIN",
    "GL_FROM_CAMERA",
    "NEAR_M",
    "camera_poses",
    "far_plane_m",
    "gl_projection",
    "gl_view",
    "pixel_rays",
    "world_from_sensor",
]

#: camera frame (X right, Y up, Z forward) -> GL view frame (x right, y up, -z forward), 4 x 4
GL_FROM_CAMERA = np.diag([1.0, 1.0, -1.0, 1.0])
#: near clipping plane, m (nothing in the scene comes this close to a sensor)
NEAR_M = 0.05
#: far plane = FAR_MARGIN * codec range: everything beyond the codec's range is invalid anyway
FAR_MARGIN = 1.05


def far_plane_m(max_depth_m: float) -> float:
    """Far clipping plane, m, a little beyond the largest encodable depth ``max_depth_m``."""
    return FAR_MARGIN * max_depth_m


def world_from_sensor(scenario: Scenario, state: Mapping[str, float]) -> np.ndarray:
    """4 x 4 pose of the LiDAR (camera-convention axes) in the world: parent pose @ mount @ axes."""
    m = scenario.lidar.mount
    if m.parent == "world":
        parent = np.eye(4)
    else:
        parent = entity_pose(state, m.parent)
    return parent @ mount_transform(m) @ body_from_camera_axes()


def camera_poses(scenario: Scenario, state: Mapping[str, float], rig: Rig) -> list[np.ndarray]:
    """world_from_camera (4 x 4, det -1: camera axes are left-handed) of every rig camera, in rig order."""
    ws = world_from_sensor(scenario, state)
    return [ws @ c.sensor_from_camera for c in rig.cameras]


def gl_view(world_from_camera: np.ndarray) -> np.ndarray:
    """GL view matrix (world -> right-handed GL view space, -z forward), 4 x 4 float64, a proper rotation."""
    return GL_FROM_CAMERA @ invert(world_from_camera)


def gl_projection(cam: Pinhole, near_m: float, far_m: float) -> np.ndarray:
    """4 x 4 float64 projection of a centred pinhole (focal f px, w x h) with the image flipped vertically.

    For a view-space point (x, y, z), z < 0: NDC x = 2 f x / (w (-z)), NDC y = -2 f y / (h (-z)), so window
    x = u and window y = v of the top-down image (docs/architecture.md); depth maps [near, far] to [-1, 1]."""
    if not 0.0 < near_m < far_m:
        raise ValueError(f"need 0 < near < far, got {near_m}, {far_m}")
    f, w, h = cam.f, cam.width, cam.height
    p = np.zeros((4, 4))
    p[0, 0] = 2.0 * f / w
    p[1, 1] = -2.0 * f / h
    p[2, 2] = -(far_m + near_m) / (far_m - near_m)
    p[2, 3] = -2.0 * far_m * near_m / (far_m - near_m)
    p[3, 2] = -1.0
    return p


def pixel_rays(cam: Pinhole, world_from_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays through every pixel centre: origin (3,) world m, unit directions (H, W, 3) world, and the cosine
    between each ray and the optical axis (H, W) (planar depth Z = t * cos)."""
    d_cam = cam.ray_directions()
    d_world = d_cam @ world_from_camera[:3, :3].T
    return world_from_camera[:3, 3].copy(), d_world, d_cam[..., 2]
