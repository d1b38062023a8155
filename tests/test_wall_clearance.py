"""Camera points kept clear of the cart's walls by their own error (perception_proc.estimates.pointsigma,
perception_proc.estimates.heightmap): closed forms of the error across a wall, and a far wall's face seen
through depth noise that no longer reads as grain at the wall's height."""
from __future__ import annotations

import numpy as np

from cosim.scenario.config import Cart
from cosim.world.geometry import cart_body_from_grid, vehicle_pose
from perception_proc.estimates.heightmap import height_map
from perception_proc.estimates.pointsigma import wall_sigma_xy

CART = Cart()
CELL = 0.1
L, W = CART.interior_length_m, CART.interior_width_m
LFG = vehicle_pose(0.5, 7.4, 0.3) @ cart_body_from_grid(CART)       # level_from_grid, a yawed cart


def to_level(g: np.ndarray) -> np.ndarray:
    return g @ LFG[:3, :3].T + LFG[:3, 3]


def test_error_across_the_walls_is_sigma_times_the_rays_direction_cosines():
    origin = to_level(np.array([[3.0, -1.5, 5.0]]))[0]
    g = np.array([[3.0, -1.5, 1.0],            # straight below: no component across any wall
                  [7.0, -1.5, 5.0],            # along grid x
                  [3.0, 2.5, 5.0],             # along grid y
                  [6.0, 2.5, 5.0],             # 3-4-5 in the grid plane
                  [np.nan, np.nan, np.nan]])
    s = wall_sigma_xy(to_level(g), origin, np.array([0.1, 0.2, 0.3, 0.5, 0.1]), LFG)
    np.testing.assert_allclose(s[:4], [[0.0, 0.0], [0.2, 0.0], [0.0, 0.3], [0.3, 0.4]], atol=1e-12)
    assert np.isnan(s[4]).all()


def _far_wall_scene(sigma_m: float, shift_sigmas: float):
    """A camera on the near side (grid y < 0) sees the floor's grain at 1.0 m up to y = 2.5 m and the far wall's
    face (y = W) from 1.2 to 2.0 m; each wall point is moved towards the camera along its ray by
    ``shift_sigmas`` sigma (depth noise's tail). Returns (level points, camera origin, per-point sigma)."""
    cam = np.array([3.0, -1.5, 5.0])
    x, y = np.meshgrid(np.arange(0.55, 5.5, 0.04), np.arange(0.55, 2.5, 0.04), indexing="ij")
    floor = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 1.0)])
    x, z = np.meshgrid(np.arange(0.55, 5.5, 0.04), np.arange(1.2, 2.0, 0.04), indexing="ij")
    wall = np.column_stack([x.ravel(), np.full(x.size, W), z.ravel()])
    ray = (wall - cam) / np.linalg.norm(wall - cam, axis=1)[:, None]
    wall = wall - shift_sigmas * sigma_m * ray
    pts = np.vstack([floor, wall])
    return to_level(pts), to_level(cam[None])[0], np.full(len(pts), sigma_m)


def test_noisy_far_wall_reads_as_grain_with_one_sigma_but_not_with_each_points_own():
    sigma = 0.08                                             # a structured-light camera's depth sigma at ~6 m
    pts, origin, s = _far_wall_scene(sigma, 2.5)
    nominal = 0.014                                          # the cameras' typical sigma of the context
    plain = height_map(pts, LFG, CART, CELL, 1, nominal).heights
    own = height_map(pts, LFG, CART, CELL, 1, nominal, wall_sigma_xy=wall_sigma_xy(pts, origin, s, LFG)).heights
    # with one small sigma for every point the wall's face fills the border cells at its own height
    assert np.nanmax(plain[:, 26:]) > 1.2
    # with each point's own error across the wall no cell reads above the floor, and the floor is all there
    assert np.nanmax(own) < 1.0 + 1e-6
    np.testing.assert_array_equal(np.isfinite(own[6:54, 6:25]), True)
    # the cells beside the far wall, where the camera sees no grain, are left without an answer
    assert np.isnan(own[:, 26:]).all()


def test_uniform_wall_sigmas_give_the_scalar_rules_map_bit_for_bit():
    # the wall's points moved 9 sigma in: some lie inside the clearance, some beyond it (border cells read them)
    pts, _, _ = _far_wall_scene(0.02, 9.0)
    a = height_map(pts, LFG, CART, CELL, 1, 0.02).heights
    b = height_map(pts, LFG, CART, CELL, 1, 0.02, wall_sigma_xy=np.full((len(pts), 2), 0.02)).heights
    assert np.nanmax(a[:, 26:]) > 1.2
    np.testing.assert_array_equal(a, b)
