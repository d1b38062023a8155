"""A rectified stereo pair of a textured plane, rendered by the GL camera renderer, for tests of the stereo
camera's matcher (its error law, its failure in dust).

The plane is the ground at z = 0 covered by the grain material (a procedural texture the matcher can lock on),
seen from ``height_m`` above it, pitched ``pitch_deg`` down; the right camera sits ``baseline_m`` along the left
camera's x axis (the rectified pair). Nothing else is in view.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from cosim.scenario.config.rendering import Lighting
from cosim.world.camera import Pinhole
from cosim.world.geometry import body_from_camera_axes, make_transform, rpy_matrix
from cosim.world.labels import GRAIN_MAT, GROUND
from cosim.world.scene import Boxes, Cylinders, HeightField, Scene

__all__ = ["textured_plane_pair", "profile_plane"]


def _plane_scene() -> Scene:
    """The ground slab (100 x 100 m, top at z = 0, the grain material) and an empty grain grid far away."""
    slab = make_transform(np.eye(3), (0.0, 0.0, -0.5))
    boxes = Boxes(slab[None], np.array([[100.0, 100.0, 0.5]]), np.array([[0.85, 0.7, 0.2]], np.float32),
                  label=np.array([GROUND], np.uint8), material=np.array([GRAIN_MAT], np.uint8))
    far = make_transform(np.eye(3), (500.0, 500.0, 0.0))
    return Scene(boxes, Cylinders(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.float32)),
                 HeightField(far, np.zeros((2, 2), np.float32), 0.5, 1.0, 1.0))


def textured_plane_pair(ctx: Any, pin: Pinhole, baseline_m: float, pitch_deg: float = 40.0,
                        height_m: float = 3.0, roll_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left, right, depth): the pair's RGBA8 images (H, W, 4) uint8 and the left camera's exact planar depth
    (H, W) float32 m (NaN: sky), drawn in the moderngl context ``ctx`` (lent: nothing of it is released).
    ``pitch_deg`` 90 looks straight down (a plane facing the camera, one depth); less slants the plane along the
    image's vertical, and ``roll_deg`` 90 (the pair turned about its optical axis) slants it along the image's
    rows, the direction the matcher searches (a wall seen obliquely)."""
    from renderer_proc.gl.camera import GLCameraRenderer

    left = make_transform(rpy_matrix(math.radians(roll_deg), math.radians(pitch_deg), 0.0), (0.0, 0.0, height_m)) @ body_from_camera_axes()
    right = left @ make_transform(np.eye(3), (baseline_m, 0.0, 0.0))
    r = GLCameraRenderer([pin, pin], Lighting(), context=ctx)
    try:
        r.set_scene(_plane_scene())
        img = [np.empty((pin.height, pin.width, 4), np.uint8) for _ in range(2)]
        for k, pose in enumerate((left, right)):
            r.draw(k, pose)
            r.read_rgb(k, img[k])
        z = np.empty((pin.height, pin.width), np.float32)
        r.draw(0, left)                                  # the left view's depth: drawn last
        r.read_depth(0, z)
    finally:
        r.close()
    return img[0], img[1], z


def profile_plane(profile: str, **plane) -> tuple[Any, Pinhole, np.ndarray, np.ndarray, np.ndarray]:
    """(camera, pinhole, left, right, depth): the packaged stereo ``profile``'s camera (a
    :class:`~cosim.scenario.config.cameras.StereoCamera` on the world), its eyes' pinhole and
    :func:`textured_plane_pair` seen by it (``plane``: that function's pose keywords), in a GL context of its own."""
    from cosim.scenario.config.cameras import StereoCamera
    from renderer_proc.gl.backend import create_gl_context

    cam = StereoCamera(kind="stereo_camera", profile=profile, mount={"parent": "world"})
    pin = Pinhole(cam.width_px, cam.height_px, math.radians(cam.hfov_deg))
    ctx = create_gl_context()
    try:
        return (cam, pin, *textured_plane_pair(ctx, pin, cam.baseline_m, **plane))
    finally:
        ctx.release()
