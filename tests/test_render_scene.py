"""Scene construction from the dynamics state: cart geometry, grain frame, stream, mesh files, budget."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cosim.config import Scenario
from cosim.geometry import apply, cart_body_from_grid, vehicle_pose
from renderer_proc.meshes import unit_cube, unit_cylinder
from renderer_proc.raycast import raycast
from renderer_proc.sample import sample_frame
from renderer_proc.scene import scene_from_state

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
