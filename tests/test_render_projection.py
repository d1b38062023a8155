"""GL view / projection against the pinhole closed forms (docs/architecture.md), and the sensor pose chain."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.scenario.config import Scenario
from cosim.world.camera import Pinhole, Rig, RigCamera, yaw_transform
from cosim.world.geometry import apply, body_from_camera_axes, mount_transform, vehicle_pose
from renderer_proc.projection import GL_FROM_CAMERA, camera_poses, gl_projection, gl_view, pixel_rays, world_from_sensor

CAM = Pinhole(640, 480, math.radians(70.0))
NEAR, FAR = 0.05, 52.5


def window(points_cam: np.ndarray, cam: Pinhole = CAM) -> np.ndarray:
    """Camera-frame points (N, 3) -> GL window (x, y, depth01) through view (identity pose) and projection."""
    view = gl_view(np.eye(4))    # world_from_camera = identity: world coordinates are camera coordinates
    p = np.c_[points_cam, np.ones(len(points_cam))] @ (gl_projection(cam, NEAR, FAR) @ view).T
    ndc = p[:, :3] / p[:, 3:4]
    return np.c_[(ndc[:, 0] + 1) * cam.width / 2, (ndc[:, 1] + 1) * cam.height / 2, (ndc[:, 2] + 1) / 2]


@pytest.mark.parametrize("u,v", [(320.0, 240.0), (0.5, 0.5), (639.5, 0.5), (0.5, 479.5), (639.5, 479.5),
                                 (320.0, 0.5), (0.5, 240.0), (639.5, 240.0), (320.0, 479.5)])
@pytest.mark.parametrize("z", [0.3, 4.0, 37.0])
def test_window_coordinates_are_image_pixels(u, v, z):
    """Eq 5 back-projection then the GL pipeline lands on the same (u, v): window y is image row v (top-down
    memory order), at the image centre, edges and corners."""
    p = CAM.backproject(np.array([u]), np.array([v]), np.array([z]))
    w = window(p)
    assert w[0, 0] == pytest.approx(u, abs=1e-9)
    assert w[0, 1] == pytest.approx(v, abs=1e-9)
    assert 0.0 < w[0, 2] < 1.0


def test_depth_range_maps_near_and_far():
    w = window(np.array([[0.0, 0.0, NEAR], [0.0, 0.0, FAR]]))
    np.testing.assert_allclose(w[:, 2], [0.0, 1.0], atol=1e-9)


def test_closed_form_focal_and_corners():
    f = 640 / (2 * math.tan(math.radians(35.0)))
    assert CAM.f == pytest.approx(f)
    # the top-left image corner (0, 0) is at X = -w/2 Z/f, Y = +h/2 Z/f: left and up
    w = window(np.array([[-320 / f, 240 / f, 1.0]]))
    np.testing.assert_allclose(w[0, :2], [0.0, 0.0], atol=1e-9)


def test_gl_view_is_proper_rotation_with_minus_z_forward():
    pose = vehicle_pose(3.0, -2.0, 0.7) @ mount_transform(Scenario(format_version=1).sensor.mount) \
        @ body_from_camera_axes()
    assert np.linalg.det(pose[:3, :3]) == pytest.approx(-1.0)
    v = gl_view(pose)
    assert np.linalg.det(v[:3, :3]) == pytest.approx(1.0)
    ahead = apply(pose, np.array([0.0, 0.0, 5.0]))        # 5 m along the optical axis
    assert apply(v, ahead) == pytest.approx(np.array([0.0, 0.0, -5.0]))
    assert np.all(GL_FROM_CAMERA == np.diag([1.0, 1.0, -1.0, 1.0]))


def test_bad_clip_planes():
    with pytest.raises(ValueError, match="near < far"):
        gl_projection(CAM, 1.0, 0.5)


def test_camera_pose_chain_follows_contract():
    s = Scenario(format_version=1)
    state = {"combine_x_m": 10.0, "combine_y_m": 2.0, "combine_yaw_rad": 0.3}
    rig = Rig((RigCamera("cam0", CAM, yaw_transform(0.2)),))
    expect = vehicle_pose(10.0, 2.0, 0.3) @ mount_transform(s.sensor.mount) @ body_from_camera_axes() \
        @ yaw_transform(0.2)
    np.testing.assert_allclose(camera_poses(s, state, rig)[0], expect)
    np.testing.assert_allclose(world_from_sensor(s, state), expect @ np.linalg.inv(yaw_transform(0.2)), atol=1e-12)


def test_pixel_rays_planar_cosine():
    small = Pinhole(8, 6, math.radians(90.0))
    o, d, cos = pixel_rays(small, np.eye(4))
    assert o == pytest.approx(np.zeros(3))
    np.testing.assert_allclose(np.linalg.norm(d, axis=2), 1.0)
    np.testing.assert_allclose(cos, d[..., 2])
    # top-left pixel centre (0.5, 0.5) looks left and up
    assert d[0, 0, 0] < 0 and d[0, 0, 1] > 0
