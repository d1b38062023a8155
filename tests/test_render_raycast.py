"""The exact ray caster against closed forms: box faces, prisms, the triangulated grain surface, meshes."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from cosim.scenario.config import Scenario
from cosim.world.geometry import make_transform, rot_z
from cosim.world.heightfield import grid_triangles, grid_vertices, padded_heights, surface_height
from cosim.world.meshes import CYLINDER_SIDES
from cosim.world.raycast import ray_boxes, ray_cylinders, ray_heightfield, ray_mesh, raycast
from cosim.world.scene import Boxes, Cylinders, HeightField, MeshInstance, scene_from_state
from renderer_proc.sample import sample_frame


def boxes(*specs) -> Boxes:
    """specs: (world_from_box, half_extents)."""
    return Boxes(np.stack([s[0] for s in specs]), np.array([s[1] for s in specs], float),
                 np.zeros((len(specs), 3), np.float32))


def test_axis_aligned_box_face_distance():
    b = boxes((make_transform(np.eye(3), (10.0, 0.0, 0.0)), (1.0, 2.0, 3.0)))
    o = np.zeros((3, 3))
    d = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(ray_boxes(o, d, b), [9.0, np.inf, np.inf])


@settings(max_examples=50, deadline=None)
@given(st.floats(-1.2, 1.2), st.floats(0.5, 20.0), st.floats(-0.6, 0.6))
def test_rotated_box_plane_closed_form(yaw, dist, ray_angle):
    """A face at distance ``dist`` along a direction ``yaw``: a ray at angle a to its normal hits at dist / cos a."""
    n = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    centre = n * (dist + 50.0)
    b = boxes((make_transform(rot_z(yaw), centre), (50.0, 200.0, 200.0)))
    d = np.array([[math.cos(yaw + ray_angle), math.sin(yaw + ray_angle), 0.0]])
    assert ray_boxes(np.zeros((1, 3)), d, b)[0] == pytest.approx(dist / math.cos(ray_angle), rel=1e-12)


def test_origin_inside_box_hits_exit_face():
    b = boxes((np.eye(4), (1.0, 1.0, 1.0)))
    assert ray_boxes(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), b)[0] == pytest.approx(1.0)


def test_prism_flat_and_vertex_distances():
    """The drawn cylinder is a regular prism with vertices on the circle: a ray at a facet's middle meets the
    flat at r cos(pi / n), a ray at a vertex meets it at r."""
    r = 0.5
    cyl = Cylinders(np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, 1.0]]), np.array([r]), np.zeros((1, 3)))
    from cosim.world.meshes import orthonormal_frames
    frame = orthonormal_frames(np.array([[0.0, 0.0, 2.0]]))[0]
    mid = frame @ np.array([math.cos(math.pi / CYLINDER_SIDES), math.sin(math.pi / CYLINDER_SIDES), 0.0])
    vert = frame @ np.array([1.0, 0.0, 0.0])
    o = np.stack([mid * 10.0, vert * 10.0, np.array([0.0, 0.0, 5.0])])
    d = np.stack([-mid, -vert, np.array([0.0, 0.0, -1.0])])
    t = ray_cylinders(o, d, cyl)
    np.testing.assert_allclose(t, [10.0 - r * math.cos(math.pi / CYLINDER_SIDES), 10.0 - r, 4.0], rtol=1e-12)
    assert ray_cylinders(o, -d, cyl)[0] == np.inf


def flat_field(h: np.ndarray, cell=0.1) -> HeightField:
    nx, ny = h.shape
    return HeightField(np.eye(4), h.astype(np.float32), cell, nx * cell, ny * cell)


@settings(max_examples=40, deadline=None)
@given(arrays(np.float32, (7, 5), elements=st.floats(0.0, 2.0, width=32)),
       st.floats(0.0, 0.7), st.floats(0.0, 0.5))
def test_vertical_rays_hit_surface_height(h, x, y):
    hf = flat_field(h)
    t = ray_heightfield(np.array([[x, y, 10.0]]), np.array([[0.0, 0.0, -1.0]]), hf)[0]
    assert 10.0 - t == pytest.approx(surface_height(padded_heights(h), 0.1, x, y), abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(arrays(np.float32, (6, 4), elements=st.floats(0.0, 1.5, width=32)),
       st.floats(-0.3, 0.3), st.floats(-0.3, 0.3))
def test_oblique_rays_first_crossing(h, dx, dy):
    """The hit lies on the surface and no earlier point of the ray is below it (dense check)."""
    hf = flat_field(h)
    o = np.array([[0.3, 0.2, 3.0]])
    d = np.array([[dx, dy, -1.0]]) / math.sqrt(dx * dx + dy * dy + 1.0)
    t = ray_heightfield(o, d, hf)[0]
    hp = padded_heights(h)
    s = np.linspace(0.0, min(t, 10.0), 4001)[:-1]
    p = o + s[:, None] * d
    inside = (p[:, 0] >= 0) & (p[:, 0] <= 0.6) & (p[:, 1] >= 0) & (p[:, 1] <= 0.4)
    assert np.all(p[inside, 2] >= surface_height(hp, 0.1, p[inside, 0], p[inside, 1]) - 1e-9)
    if np.isfinite(t):
        q = o[0] + t * d[0]
        assert q[2] == pytest.approx(surface_height(hp, 0.1, q[0], q[1]), abs=1e-9)


def test_surface_interpolates_cell_centres_and_triangles():
    h = np.array([[0.0, 1.0], [2.0, 4.0]], np.float32)
    hp = padded_heights(h)
    centres = surface_height(hp, 1.0, np.array([0.5, 0.5, 1.5, 1.5]), np.array([0.5, 1.5, 0.5, 1.5]))
    np.testing.assert_allclose(centres, [0.0, 1.0, 2.0, 4.0])
    # middle of the inner quad on the diagonal: mean of h00 and h11; off-diagonal points use their triangle
    assert surface_height(hp, 1.0, 1.0, 1.0) == pytest.approx(2.0)
    assert surface_height(hp, 1.0, 1.25, 0.75) == pytest.approx(0.0 + 0.75 * 2.0 + 0.25 * 2.0)
    # the edge ring is flat across the wall normal
    assert surface_height(hp, 1.0, 0.0, 0.5) == pytest.approx(0.0)


def test_grid_mesh_matches_surface():
    """The GL mesh (vertices, triangles) is the same surface: every triangle's centroid height agrees."""
    rng = np.random.default_rng(3)
    h = rng.uniform(0.0, 2.0, (6, 4)).astype(np.float32)
    xy = grid_vertices(6, 4, 0.1, 0.6, 0.4).astype(np.float64)
    z = padded_heights(h).ravel().astype(np.float64)
    tri = grid_triangles(6, 4)
    c_xy = xy[tri].mean(axis=1)
    np.testing.assert_allclose(z[tri].mean(axis=1), surface_height(padded_heights(h), 0.1, c_xy[:, 0], c_xy[:, 1]),
                               atol=1e-6)


def test_mesh_matches_box_primitive():
    import trimesh
    box = trimesh.creation.box(extents=(2.0, 4.0, 1.0))
    pose = make_transform(rot_z(0.4), (5.0, 1.0, 0.5))
    mesh = MeshInstance("m", np.asarray(box.vertices), np.asarray(box.faces), pose, (1.0, 1.0, 1.0))
    rng = np.random.default_rng(0)
    d = rng.normal(size=(500, 3)) * [0.3, 0.3, 0.2] + [1.0, 0.2, 0.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.zeros((500, 3))
    ref = ray_boxes(o, d, boxes((pose, (1.0, 2.0, 0.5))))
    got = ray_mesh(o, d, mesh)
    assert np.isfinite(ref).sum() > 50
    np.testing.assert_allclose(got, ref, rtol=1e-9)


def test_scene_raycast_is_fast_and_sees_cart():
    """A 320 x 240 frame of the default scene well under a second (CPU time: steady on a shared machine), and
    a ray straight down into the cart hits the grain at the sample's heights."""
    import time
    s = Scenario(format_version=1)
    state, h, stream = sample_frame(s)
    scene = scene_from_state(s, state, h, stream)
    rng = np.random.default_rng(1)
    d = rng.normal(size=(320 * 240, 3)) * [0.3, 1.0, 0.3] + [0.0, 1.0, -0.8]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(np.array([state["combine_x_m"] - 2.0, 1.9, 4.6]), d.shape)
    t0 = time.process_time()
    raycast(scene, o, d)
    assert time.process_time() - t0 < 1.0
    hf = scene.heightfield
    grid_pt = np.array([2.05, 1.05, 5.0, 1.0])            # above cell (20, 10)
    world = hf.world_from_grid @ grid_pt
    t = raycast(scene, world[None, :3], np.array([[0.0, 0.0, -1.0]]))[0]
    assert 5.0 - t == pytest.approx(float(h[20, 10]), abs=1e-6)


@pytest.mark.parametrize("level", [0.0, 1.0, 1.37])
def test_flat_fill_never_leaks(level):
    """Regression: on a flat fill the surface equals the slab's bottom; every ray must still hit it."""
    hf = flat_field(np.full((60, 30), level, np.float32))
    rng = np.random.default_rng(7)
    n = 20_000
    target = np.c_[rng.uniform(0.0, 6.0, n), rng.uniform(0.0, 3.0, n), np.full(n, level)]
    o = np.array([-2.0, 7.0, 4.6])
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = ray_heightfield(np.broadcast_to(o, d.shape), d, hf)
    assert np.all(np.isfinite(t))
    np.testing.assert_allclose(o[2] + t * d[:, 2], level, atol=1e-9)
