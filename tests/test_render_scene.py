"""Scene construction from the dynamics state: cart geometry, grain frame, stream, mesh files, budget."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cosim.scenario.config import Scenario
from cosim.world.geometry import apply, cart_body_from_grid, vehicle_pose
from cosim.world.meshes import unit_cube, unit_cylinder
from cosim.world.raycast import raycast
from cosim.world.scene import scene_from_state
from renderer_proc.sample import sample_frame

#: the default scene's triangle budget (one 640 x 480 camera in ~5 ms on llvmpipe)
TRIANGLE_BUDGET = 10_000


def scenario(**kw) -> Scenario:
    """Validated like the loader does (JSON mode, strict)."""
    return Scenario.model_validate_json(json.dumps({"format_version": 1, **kw}))


def test_cart_rim_and_grain_frame_in_world():
    s = Scenario(format_version=1)
    state, h, stream = sample_frame(s)
    state = {**state, "cart_x_m": 3.0, "cart_y_m": 8.0, "cart_yaw_rad": 0.4}
    scene = scene_from_state(s, state, h, stream)
    pose = vehicle_pose(3.0, 8.0, 0.4)
    np.testing.assert_allclose(scene.heightfield.world_from_grid, pose @ cart_body_from_grid(s.cart))
    # straight down onto the rim bar over the left wall: rim top height
    c = s.cart
    top = apply(pose, [0.0, c.interior_width_m / 2 + c.rim_width_m / 2, 10.0])
    t = raycast(scene, top[None], np.array([[0.0, 0.0, -1.0]]))[0]
    assert 10.0 - t == pytest.approx(c.rim_top_m, abs=1e-9)
    # the grid origin is the front-left interior floor corner (cart body x = +L/2, y = +W/2)
    corner = apply(scene.heightfield.world_from_grid, [0.0, 0.0, 0.0])
    np.testing.assert_allclose(corner, apply(pose, [c.interior_length_m / 2, c.interior_width_m / 2, c.floor_height_m]))
    # just inside the front wall, 5 cm from the left wall: the grain surface (edge ring flat)
    p = apply(scene.heightfield.world_from_grid, [0.01, 0.05, 10.0])
    t = raycast(scene, p[None], np.array([[0.0, 0.0, -1.0]]))[0]
    assert p[2] - t == pytest.approx(c.floor_height_m + float(h[0, 0]), abs=1e-6)


def test_stream_segments_follow_valid_rows():
    s = Scenario(format_version=1)
    state, h, stream = sample_frame(s)
    n_static = len(scene_from_state(s, {**state, "stream_points": 0}, h, stream).cylinders)
    full = scene_from_state(s, state, h, stream)
    assert len(full.cylinders) - n_static == int(state["stream_points"]) - 1
    np.testing.assert_allclose(full.cylinders.p0[-1], stream[int(state["stream_points"]) - 2, :3], rtol=1e-6)
    # a ray down the stream's last segment hits the stream, not the grain below
    p0, p1 = full.cylinders.p0[-1], full.cylinders.p1[-1]
    mid = 0.5 * (p0 + p1)
    t = raycast(full, (mid + [0.0, 0.0, 3.0])[None], np.array([[0.0, 0.0, -1.0]]))[0]
    assert t < 3.0 + 0.5


def test_heightmap_shape_is_checked():
    s = Scenario(format_version=1)
    state, h, stream = sample_frame(s)
    with pytest.raises(ValueError, match=r"heightmap shape \(59, 30\) does not match the cart grid \(60, 30\)"):
        scene_from_state(s, state, h[:59], stream)


def test_mesh_file_replaces_procedural_boxes(tmp_path):
    import trimesh
    path = tmp_path / "combine.stl"
    trimesh.creation.box(extents=(8.0, 3.0, 3.0)).export(path)
    base = Scenario(format_version=1)
    s = scenario(combine={"mesh_file": str(path)})
    state, h, stream = sample_frame(s)
    a, b = scene_from_state(base, state, h, stream), scene_from_state(s, state, h, stream)
    assert len(b.meshes) == 1 and b.meshes[0].name == "combine" and len(b.meshes[0].faces) == 12
    assert len(a.boxes) - len(b.boxes) == 3
    np.testing.assert_allclose(b.meshes[0].world_from_mesh, vehicle_pose(state["combine_x_m"], state["combine_y_m"],
                                                                         state["combine_yaw_rad"]))


def test_default_scene_within_triangle_budget():
    s = Scenario(format_version=1)
    state, h, stream = sample_frame(s)
    full = np.zeros((64, 4), np.float32)
    full[:, :3] = np.linspace([0.0, 7.0, 4.6], [0.0, 7.5, 1.5], 64)
    full[:, 3] = 0.15
    sc = scene_from_state(s, {**state, "stream_points": 64}, h, full)
    nx, ny = h.shape
    tris = (len(sc.boxes) * len(unit_cube()[1]) + len(sc.cylinders) * len(unit_cylinder()[1])
            + 2 * (nx + 1) * (ny + 1))
    assert tris <= TRIANGLE_BUDGET, tris


def test_sample_frame_puts_stream_into_cart():
    s = Scenario(format_version=1)
    state, h, stream = sample_frame(s)
    scene = scene_from_state(s, state, h, stream)
    end = stream[int(state["stream_points"]) - 1, :3].astype(float)
    g = np.linalg.inv(scene.heightfield.world_from_grid) @ np.r_[end, 1.0]
    assert 0.0 < g[0] < s.cart.interior_length_m and 0.0 < g[1] < s.cart.interior_width_m
    assert math.isclose(h.max(), s.grain.initial_fill_m + 0.6, abs_tol=0.05)


def test_hidden_top_faces_are_covered():
    """The top faces the GL renderer skips (cart floor and walls) are covered: each point of them lies on the
    grain grid's floor inside the interior (under the grain surface, heights >= 0) or inside another box."""
    from cosim.world.parts import CART_WALL_BOXES

    s = Scenario(format_version=1)
    state, h, stream = sample_frame(s)
    scene = scene_from_state(s, state, h, stream)
    boxes, hidden = scene.boxes, scene.boxes.hidden_top
    assert hidden is not None and hidden.shape == (len(boxes),) and hidden.sum() == 1 + len(CART_WALL_BOXES)
    assert scene.ground_box is not None and not hidden[scene.ground_box]
    rng = np.random.default_rng(3)
    grid_from_world = np.linalg.inv(scene.heightfield.world_from_grid)
    n_grain = 0
    for k in np.flatnonzero(hidden):
        top = boxes.world_from_box[k] @ np.diag([*boxes.half_extents[k], 1.0])
        uv = rng.uniform(-1.0, 1.0, (500, 2))
        pts = apply(top, np.c_[uv, np.ones(len(uv))])             # points on the top face, world
        g = apply(grid_from_world, pts)
        covered = ((np.abs(g[:, 2]) < 1e-9) & (g[:, 0] >= 0) & (g[:, 0] <= s.cart.interior_length_m)
                   & (g[:, 1] >= 0) & (g[:, 1] <= s.cart.interior_width_m))
        n_grain += int(covered.sum())
        for j in range(len(boxes)):
            if j != k:
                local = apply(np.linalg.inv(boxes.world_from_box[j]), pts)
                covered |= np.all(np.abs(local) <= boxes.half_extents[j] + 1e-9, axis=1)
        assert np.all(covered), k
    assert n_grain > 0
    # a rim narrower than the wall leaves the wall tops in view: only the floor's top is skipped
    narrow = scene_from_state(scenario(cart={"rim_width_m": 0.05}), state, h, stream)
    assert np.flatnonzero(narrow.boxes.hidden_top).tolist() == [int(np.flatnonzero(hidden)[0])]


def _surface_checks(h: np.ndarray, cell: float, block: int) -> int:
    """Build the merged draw mesh of ``h`` and check it: counter-clockwise, area L x W, every interior edge
    shared by exactly two triangles in opposite directions (no T-junction, no crack), the same surface as
    ``surface_height``. Returns the triangle count."""
    from cosim.world.heightfield import padded_heights, surface_height
    from renderer_proc.gl.hfmesh import SurfaceMesh

    nx, ny = h.shape
    length, width = nx * cell, ny * cell
    mesh = SurfaceMesh(nx, ny, cell, length, width, block)
    hp = padded_heights(h)
    tri, changed = mesh.triangles(hp)
    assert changed and tri.dtype == np.int32
    xy, z = mesh.vertices.astype(np.float64), mesh.heights(hp).astype(np.float64)
    p = xy[tri]
    area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    assert np.all(area > 0.0)
    assert math.isclose(area.sum(), length * width, rel_tol=1e-6)
    directed = {}
    for t in tri:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            directed[(a, b)] = directed.get((a, b), 0) + 1
    assert max(directed.values()) == 1
    for a, b in directed:
        if (b, a) not in directed:         # a boundary edge: both ends on the interior's outline
            (xa, ya), (xb, yb) = xy[a], xy[b]
            assert (xa == xb and xa in (0.0, np.float32(length))) or (ya == yb and ya in (0.0, np.float32(width)))
    bary = np.random.default_rng(0).dirichlet([1.0, 1.0, 1.0], len(tri))
    q = np.einsum("tk,tkd->td", bary, p)
    # vertex positions are float32 (~1e-8 m), which on a 7 m/m plateau edge moves the height ~1e-6 m
    np.testing.assert_allclose(np.einsum("tk,tk->t", bary, z[tri]), surface_height(hp, cell, q[:, 0], q[:, 1]),
                               atol=1e-5)
    assert not mesh.triangles(hp)[1]       # same flat blocks: the index buffer need not be written again
    return len(tri)


@pytest.mark.parametrize("block", [1, 3, 4, 8])
def test_merged_grain_surface_is_watertight_and_exact(block):
    s = Scenario(format_version=1)
    _, h, _ = sample_frame(s)                        # flat fill with a cone under the impact point
    h = h.copy()
    h[:7] = 0.0                                      # an empty strip at the front
    h[40:44, 5:9] = 1.7                              # a raised plateau
    n = _surface_checks(h, s.grain.cell_m, block)
    nx, ny = h.shape
    if block == 1:
        assert n == 2 * (nx + 1) * (ny + 1)          # block 1 is the plain grid
    else:
        assert n < (nx + 1) * (ny + 1)               # mostly flat: far fewer triangles than the grid


def test_rough_grain_surface_keeps_every_grid_triangle():
    h = np.random.default_rng(5).uniform(0.0, 1.0, (13, 7)).astype(np.float32)
    assert _surface_checks(h, 0.1, 4) == 2 * 14 * 8
