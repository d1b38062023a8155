"""The exact label cast (cosim.world.labelcast) and the mock camera renderer built on it: distances identical to
the ray caster's, labels against closed forms, depth of a plane."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.scenario.config.cameras import DepthCamera
from cosim.scenario.loader import load_scenario, resolve_scenario_arg
from cosim.scenario.plausibility import _initial_state
from cosim.world.camera import Pinhole
from cosim.world.labelcast import cast_labels
from cosim.world.labels import CART_RIM, CART_WALL, GRAIN, GROUND, LABELS, NONE
from cosim.world.raycast import ray_boxes, raycast
from cosim.world.scene import Boxes, Cylinders, HeightField, Scene, scene_from_state
from cosim.world.sensors import world_from_sensor
from renderer_proc.mock.camera import MockCameraRenderer


@pytest.fixture(scope="module")
def frame0():
    s = load_scenario(resolve_scenario_arg("default"))
    state, heights = _initial_state(s)
    return s, state, scene_from_state(s, state, heights, np.zeros((64, 4), np.float32))


def camera(xyz, rpy, hfov=90.0):
    return DepthCamera(kind="depth_camera", mount={"parent": "combine", "xyz_m": xyz, "rpy_deg": rpy}, hfov_deg=hfov)


def test_labelled_distances_are_the_ray_casters_bit_for_bit(frame0):
    """A camera under the auger tip sees grain, walls, rims and ground; its origin lies inside the bounding
    spheres of the long rim bars, where the shared-origin cull once mis-bounded the entry with a t_max."""
    s, state, scene = frame0
    w = world_from_sensor(camera((-2.0, 6.0, 4.2), (0.0, 80.0, 90.0)), state)
    d = Pinhole(160, 120, np.radians(90.0)).ray_directions().reshape(-1, 3) @ w[:3, :3].T
    t, label = cast_labels(scene, w[:3, 3], d)
    assert np.array_equal(t, raycast(scene, np.broadcast_to(w[:3, 3], d.shape), d))
    seen = set(np.unique(label).tolist())
    assert {GRAIN, CART_WALL, CART_RIM, GROUND} <= seen and NONE not in seen
    # the cull with a nearer bound: a known hit below t_max is never dropped
    o = np.broadcast_to(w[:3, 3], d.shape)
    free = ray_boxes(o, d, scene.boxes)
    bound = np.full(len(d), 1.38)
    assert np.array_equal(ray_boxes(o, d, scene.boxes, t_max=bound), np.minimum(free, bound))


def test_labels_of_a_box_on_the_ground_by_closed_form():
    """Looking straight down from 10 m at a 2 m cube (label cart rim) on the ground: the pixels whose ray meets
    the cube's top at z = 2 are labelled rim with planar depth 8 m, the others ground at 10 m."""
    def box(cx, cy, cz, h):
        t = np.eye(4)
        t[:3, 3] = (cx, cy, cz)
        return t, np.array(h, float)

    (t0, h0), (t1, h1) = box(0, 0, 1.0, (1, 1, 1)), box(0, 0, -0.25, (50, 50, 0.25))
    boxes = Boxes(np.stack([t0, t1]), np.stack([h0, h1]), np.zeros((2, 3), np.float32),
                  label=np.array([CART_RIM, GROUND], np.uint8))
    grid = np.eye(4)
    grid[:3, 3] = (100.0, 100.0, 0.0)                  # the grain far away
    hf = HeightField(grid, np.zeros((2, 2), np.float32), 0.5, 1.0, 1.0)
    scene = Scene(boxes, Cylinders(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.float32)),
                  hf)
    pin = Pinhole(64, 64, np.radians(40.0))
    down = np.array([[1.0, 0, 0, 0], [0, -1.0, 0, 0], [0, 0, -1.0, 10.0], [0, 0, 0, 1]])   # camera Z = world -z
    r = MockCameraRenderer([pin], _lighting(), [True])
    r.set_scene(scene)
    r.draw(0, down)
    z, lab = np.empty((64, 64), np.float32), np.empty((64, 64), np.uint8)
    r.read_depth(0, z)
    r.read_labels(0, lab)
    uu, vv = pin.pixel_centres()
    x, y = (uu - 32) / pin.f * 8.0, (32 - vv) / pin.f * 8.0      # where the ray is at the cube top (Z = 8)
    on_top = (np.abs(x) < 1.0) & (np.abs(y) < 1.0)
    assert np.array_equal(lab == CART_RIM, on_top) and np.all(lab[~on_top] == GROUND)
    np.testing.assert_allclose(z[on_top], 8.0, rtol=0, atol=1e-5)
    np.testing.assert_allclose(z[~on_top], 10.0, rtol=0, atol=1e-5)
    assert LABELS[CART_RIM] == "cart_rim"


def _lighting():
    from cosim.scenario.config.rendering import Lighting

    return Lighting()


def test_the_depth_only_view_with_the_rigid_bodies_built_once_is_the_per_frame_casts(frame0):
    """A depth-only view (no labels, no colour) of a run's scene casts through the rigid bodies built once for the
    run (``parts``) and gives the per-frame cast's depth to within 1e-9 m, with the same pixels valid."""
    pytest.importorskip("embreex")
    from cosim.world.parts import entity_parts

    s, state, scene = frame0
    w = world_from_sensor(camera((-2.0, 6.0, 4.2), (0.0, 80.0, 90.0)), state)
    pin = Pinhole(160, 120, np.radians(90.0))
    fast, plain = MockCameraRenderer([pin], _lighting(), [False], parts=entity_parts(s)), \
        MockCameraRenderer([pin], _lighting(), [False])
    assert (fast.caster.name, plain.caster.name) == ("embree-static", "embree")
    z = []
    for r in (fast, plain):
        r.set_scene(scene)
        r.draw(0, w)
        z.append(np.empty((120, 160), np.float32))
        r.read_depth(0, z[-1])
        r.close()
    assert np.array_equal(np.isfinite(z[0]), np.isfinite(z[1])) and np.isfinite(z[0]).mean() > 0.9
    np.testing.assert_allclose(z[0], z[1], rtol=0, atol=1e-9, equal_nan=True)


def _frame(name: str):
    s = load_scenario(resolve_scenario_arg(name))
    state, heights = _initial_state(s)
    return state, scene_from_state(s, state, heights, np.zeros((64, 4), np.float32))


@pytest.mark.parametrize(("name", "xyz", "rpy", "size"), [
    ("default", (-2.0, 6.0, 4.2), (0.0, 80.0, 90.0), (160, 120)),          # grain, walls, rims, ground
    ("default", (-2.0, 7.45, 6.0), (0.0, 90.0, -90.0), (160, 120)),        # from the spout: the combine, the auger
    ("default", (-8.0, 14.0, 5.0), (0.0, 25.0, 0.0), (160, 120)),          # the tractor, the sky
    ("rough_terrain", (-8.0, 14.0, 5.0), (0.0, 25.0, 0.0), (40, 30)),      # the terrain patch: a mesh
])
def test_the_embree_label_cast_gives_the_numpy_label_cast(name, xyz, rpy, size):
    """The labelled cast through the scene's triangles in Embree (the mock's, where Embree is installed) gives the
    numpy label cast's labels pixel for pixel, the same pixels hit and the ranges to 1e-9 m."""
    pytest.importorskip("embreex")
    from cosim.world.fastcast import embree_cast_labels, make_caster

    state, scene = _frame(name)
    w = world_from_sensor(camera(xyz, rpy), state)
    d = Pinhole(*size, np.radians(90.0)).ray_directions().reshape(-1, 3) @ w[:3, :3].T
    t0, lab0 = cast_labels(scene, w[:3, 3], d)
    t1, lab1 = embree_cast_labels(scene, w[:3, 3], d)
    assert len(set(np.unique(lab0).tolist())) >= 4                        # several parts in view
    np.testing.assert_array_equal(lab1, lab0)
    np.testing.assert_array_equal(np.isfinite(t1), np.isfinite(t0))
    hit = np.isfinite(t0)
    np.testing.assert_allclose(t1[hit], t0[hit], rtol=0, atol=1e-9)
    assert make_caster(None).label_name == "embree" and make_caster(None, "numpy").label_name == "numpy"
