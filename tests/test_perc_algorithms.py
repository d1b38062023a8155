"""Cart boundary, height map and impact on synthetic point clouds with known answers (exact ray casts)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.scenario.config import Cart, Mount, Noise, Pattern, Sensor
from cosim.testing.synthetic import Box, cart_shapes, raycast
from cosim.world.camera import beam_directions
from cosim.world.geometry import apply, body_from_camera_axes, cart_body_from_grid, mount_transform, vehicle_pose
from cosim.world.patterns import beam_table, pattern_shape
from perception_proc.estimates.heightmap import _cell_index, grid_shape, height_map
from perception_proc.estimates.impact import blank_under_stream, find_impact, line_fits
from perception_proc.estimates.rim import border_beams, find_cart
from perception_proc.lidar.sensor import apply_noise_and_limits, frame_generator

CART = Cart()
CELL = 0.1
POSE = vehicle_pose(0.5, 7.4, 0.06)                 # level_from_cartbody of the true cart
MOUNT = Mount(parent="combine", xyz_m=(0.0, 3.0, 8.0), rpy_deg=(0.0, 55.0, 90.0))
PATTERN = Pattern(preset="grid", elevation_min_deg=-40, elevation_max_deg=30, azimuth_min_deg=-55,
                  azimuth_max_deg=55, elevation_count=110, azimuth_count=160)
L, W = CART.interior_length_m, CART.interior_width_m


#: corn's angle of repose, 23 deg, as a slope
REPOSE_SLOPE = math.tan(math.radians(23.0))


def heap(peak_m, gx0=3.0, gy0=1.5, base_m=0.8, slope=REPOSE_SLOPE):
    """Cone of repose on a flat bed: h = max(base, peak - slope * distance), grid frame, m."""
    return lambda gx, gy: np.maximum(base_m, peak_m - slope * np.hypot(gx - gx0, gy - gy0))


NO_NOISE = Noise()


def scan(shapes, pattern=PATTERN, mount=MOUNT, sensor_noise=NO_NOISE, frame=0):
    """Ranges (N,) float32 of an exact scan, with the sensor's noise; plus the level points and border."""
    e, a = beam_table(pattern)
    d = beam_directions(e, a)
    lfs = mount_transform(mount) @ body_from_camera_axes()
    t = raycast(shapes, lfs[:3, 3], d @ lfs[:3, :3].T)
    r = np.where(np.isfinite(t), t, np.nan).astype(np.float32)
    sensor = Sensor(mount=mount, pattern=pattern, noise=sensor_noise, range_max_m=60.0)
    r = apply_noise_and_limits(r, sensor, frame_generator(7, frame))
    lvl = (d * r[:, None].astype(np.float64)) @ lfs[:3, :3].T + lfs[:3, 3]
    return r, lvl, border_beams(r, pattern_shape(pattern))


def true_corners(pose=POSE):
    zr = CART.interior_depth_m + CART.rim_height_m
    g = np.array([[0, 0, zr], [L, 0, zr], [L, W, zr], [0, W, zr]], float)
    return apply(pose @ cart_body_from_grid(CART), g)


def truth_grid(fn):
    nx, ny = grid_shape(CART, CELL)
    gx, gy = np.meshgrid((np.arange(nx) + 0.5) * CELL, (np.arange(ny) + 0.5) * CELL, indexing="ij")
    return fn(gx, gy)


def run(shapes, **kw):
    r, lvl, border = scan(shapes, **kw)
    sigma = kw.get("sensor_noise", Noise()).range_sigma_m
    cart = find_cart(lvl, border, CART, (1.0, 0.0), sigma)
    hm = height_map(lvl, cart.level_from_grid, CART, CELL, 1, sigma) if cart.valid else None
    return cart, hm


def test_empty_cart_found_and_floor_at_zero():
    cart, hm = run(cart_shapes(CART, POSE))
    assert cart.valid and not cart.partial
    assert np.max(np.linalg.norm(cart.corners - true_corners(), axis=1)) < 0.03
    assert cart.yaw_rad == pytest.approx(0.06, abs=0.01)
    h = hm.heights
    assert hm.coverage > 0.35                      # the near wall hides the near part of the floor
    assert np.nanmax(np.abs(h)) < 0.03
    imp = find_impact(hm.grid_points, hm.stream, h, (CELL, CELL), 0.6)
    assert not imp.valid and "stream returns" in imp.reason


def test_heaped_cart_heights_match_truth():
    fn = heap(2.35)                                   # peak above the rim top (2.06 m above the floor)
    cart, hm = run(cart_shapes(CART, POSE, grain_height=fn))
    assert cart.valid
    assert np.max(np.linalg.norm(cart.corners - true_corners(), axis=1)) < 0.05
    truth = truth_grid(fn)
    ok = np.isfinite(hm.heights)
    assert ok.mean() > 0.6
    err = hm.heights[ok] - truth[ok]
    # cell statistic vs cell-centre truth: the cone's slope over half a cell bounds the difference
    assert np.sqrt(np.mean(err**2)) < 0.03
    assert np.max(np.abs(err)) < 0.12


def test_stream_occluding_the_pile_gives_impact_and_no_stream_heights():
    fn = heap(1.6, gx0=2.2, gy0=1.4)
    shapes = cart_shapes(CART, POSE, grain_height=fn, stream_xy_grid=(2.2, 1.4), stream_top_m=4.8)
    cart, hm = run(shapes)
    assert cart.valid
    truth = truth_grid(fn)
    lfg = cart.level_from_grid
    sensor = (np.asarray(MOUNT.xyz_m) - lfg[:3, 3]) @ lfg[:3, :3]
    raw = find_impact(hm.grid_points, hm.stream, hm.heights, (CELL, CELL), 0.6)
    imp = find_impact(hm.grid_points, hm.stream, hm.heights, (CELL, CELL), 0.6, tuple(sensor[:2]))
    assert imp.valid and raw.valid
    err, err_raw = np.hypot(imp.xyz[0] - 2.2, imp.xyz[1] - 1.4), np.hypot(raw.xyz[0] - 2.2, raw.xyz[1] - 1.4)
    assert err < 0.06 and err < err_raw                  # the returns lie on the stream's near face
    assert imp.xyz[2] == pytest.approx(1.6, abs=0.2)
    assert imp.radius_m == pytest.approx(0.15, abs=0.1)
    before = np.isfinite(hm.heights).sum()
    assert blank_under_stream(hm.heights, imp, (CELL, CELL)) > 0
    assert np.isfinite(hm.heights).sum() < before
    ok = np.isfinite(hm.heights)
    assert ok.mean() > 0.3
    assert np.max(np.abs(hm.heights[ok] - truth[ok])) < 0.08     # no stream height passed off as grain


def test_noise_and_dropout_degrade_gracefully():
    fn = heap(1.8)
    noise = Noise(range_sigma_m=0.02, dropout=0.3)
    cart, hm = run(cart_shapes(CART, POSE, grain_height=fn), sensor_noise=noise)
    assert cart.valid
    assert np.max(np.linalg.norm(cart.corners - true_corners(), axis=1)) < 0.12
    truth = truth_grid(fn)
    ok = np.isfinite(hm.heights)
    assert ok.mean() > 0.4
    assert np.sqrt(np.mean((hm.heights[ok] - truth[ok]) ** 2)) < 0.05


def test_partly_visible_cart_is_anchored_on_the_seen_end():
    # a narrow azimuth window cuts the cart's rear (right of the view) off
    pat = PATTERN.model_copy(update={"azimuth_min_deg": -20.0})
    cart, _ = run(cart_shapes(CART, POSE), pattern=pat)
    assert cart.valid and cart.partial
    assert np.max(np.linalg.norm(cart.corners - true_corners(), axis=1)) < 0.08


def test_cart_cut_at_both_ends_says_no_answer():
    pat = PATTERN.model_copy(update={"azimuth_min_deg": -12.0, "azimuth_max_deg": 12.0, "azimuth_count": 60})
    cart, _ = run(cart_shapes(CART, POSE), pattern=pat)
    assert not cart.valid
    assert "no answer" in cart.reason or "rim" in cart.reason
    assert np.isnan(cart.corners).all()


def test_no_cart_in_view_says_no_answer():
    cart, _ = run(cart_shapes(CART, vehicle_pose(40.0, 7.4, 0.0)))
    assert not cart.valid and np.isnan(cart.level_from_grid).all()


def test_roofed_box_beside_the_cart_is_not_taken_for_it():
    # a tractor-sized box ahead of the cart whose roof is above the rim: its walls cross the rim band
    tractor = Box((6.5, 6.1, 0.5), (11.0, 8.7, 3.3))
    cart, _ = run(cart_shapes(CART, POSE) + [tractor])
    assert cart.valid
    assert np.max(np.linalg.norm(cart.corners - true_corners(), axis=1)) < 0.05


def test_lone_wall_at_rim_height_is_not_a_cart():
    # e.g. the combine's own side crossing the rim band: long enough, but a line, not a rectangle
    wall = Box((-2.5, 6.0, 0.5), (1.5, 6.3, 3.1))
    r, lvl, border = scan([wall, Box((-50, -50, -1), (50, 50, 0))])
    cart = find_cart(lvl, border, CART, (1.0, 0.0))
    assert not cart.valid and "rim-sized" in cart.reason


def test_height_map_rejects_bad_pose_input_shapes():
    hm = height_map(np.full((5, 3), np.nan), np.eye(4), CART, CELL)
    assert hm.coverage == 0.0 and np.isnan(hm.heights).all() and hm.heights.shape == grid_shape(CART, CELL)


def test_returns_on_the_sensors_own_vehicle_are_masked():
    from cosim.scenario.config import Scenario
    from cosim.testing.synthetic import stitched_rig
    from perception_proc.pipeline import OWN_BOX_MARGIN_M, Perception

    # a sensor on a mast above the combine's right half, looking left and down across its own roof
    sc = Scenario(format_version=1, sensor=Sensor(mount=Mount(parent="combine", xyz_m=(0.0, -1.0, 5.0),
                                                              rpy_deg=(0.0, 45.0, 90.0))))
    p = Perception(sc, stitched_rig(1, 32, 32, 60.0))
    r = np.random.default_rng(0).uniform(0.2, 12.0, p.n_beams).astype(np.float32)
    lvl = p.level_points(r)
    raw = p.level_directions * r[:, None].astype(np.float64) + p.level_from_sensor[:3, 3]
    c = sc.combine
    inside = ((np.abs(raw[:, 0]) <= c.length_m / 2 + OWN_BOX_MARGIN_M)
              & (np.abs(raw[:, 1]) <= c.width_m / 2 + OWN_BOX_MARGIN_M) & (raw[:, 2] <= c.height_m + OWN_BOX_MARGIN_M)
              & (raw[:, 2] >= -OWN_BOX_MARGIN_M))
    assert 0 < inside.sum() < inside.size
    assert np.isnan(lvl[inside]).all() and np.isfinite(lvl[~inside]).all()


OWN_BOX_MOUNTS = [((0.0, -1.0, 5.0), (0.0, 45.0, 90.0)), ((3.0, 0.0, 4.0), (0.0, 30.0, 0.0)),
                  ((-1.0, 1.5, 4.5), (0.0, 60.0, -90.0))]


def _own_mask_case(xyz, rpy) -> tuple[int, int, int]:
    """Check level_points' own-vehicle mask against the box test of every point; returns the axis order."""
    from cosim.scenario.config import Scenario
    from cosim.testing.synthetic import stitched_rig
    from perception_proc.pipeline import Perception, own_vehicle_box

    sc = Scenario(format_version=1, sensor=Sensor(mount=Mount(parent="combine", xyz_m=xyz, rpy_deg=rpy)))
    p = Perception(sc, stitched_rig(1, 48, 48, 90.0))
    r = np.random.default_rng(1).uniform(0.2, 15.0, p.n_beams).astype(np.float32)
    r[::17] = np.nan
    raw = p.level_directions * r[:, None].astype(np.float64) + p.level_from_sensor[:3, 3]
    lo, hi = own_vehicle_box(sc)
    with np.errstate(invalid="ignore"):
        inside = np.all((raw >= lo) & (raw <= hi), axis=1)
    lvl = p.level_points(r)
    assert 0 < inside.sum() < np.isfinite(r).sum()
    np.testing.assert_array_equal(np.isnan(lvl[:, 0]), inside | np.isnan(r))
    np.testing.assert_array_equal(lvl[~inside], raw[~inside])
    return p._own_axes


@pytest.mark.parametrize("xyz, rpy", OWN_BOX_MOUNTS)
def test_own_vehicle_mask_is_the_box_whatever_axis_goes_first(xyz, rpy):
    """The own-box test runs axis by axis, the most selective axis first (it depends on where the sensor
    looks): the mask is the box test of every point."""
    _own_mask_case(xyz, rpy)


def test_own_box_axis_order_follows_the_view():
    firsts = {_own_mask_case(*m)[0] for m in OWN_BOX_MOUNTS}
    assert len(firsts) >= 2                          # looking sideways and looking ahead start elsewhere


def test_border_flags_match_their_definition():
    """FOV_EDGE on the pattern's outer rows and columns; OCCLUDED where a 3 x 3 neighbour (edge-replicated) is
    nearer by more than OCCLUDER_REL of the range, invalid neighbours never nearer."""
    from perception_proc.estimates.rim import FOV_EDGE, OCCLUDED, OCCLUDER_REL

    rng = np.random.default_rng(3)
    r = rng.uniform(2.0, 20.0, (30, 40)).astype(np.float32)
    r[rng.random(r.shape) < 0.1] = np.nan
    got = border_beams(r.ravel(), r.shape).reshape(r.shape)
    pad = np.pad(np.where(np.isnan(r), np.inf, r), 1, mode="edge")
    nearest = np.min([pad[i:i + 30, j:j + 40] for i in range(3) for j in range(3)], axis=0)
    with np.errstate(invalid="ignore"):
        want = np.where(nearest < r * np.float32(1.0 - OCCLUDER_REL), OCCLUDED, 0).astype(np.uint8)
    want[[0, -1], :] |= FOV_EDGE
    want[:, [0, -1]] |= FOV_EDGE
    np.testing.assert_array_equal(got, want)
    assert (got & OCCLUDED).any() and not (got[np.isnan(r)] & OCCLUDED).any()


def test_upright_grid_transform_gives_the_full_products():
    """For a yaw-only cart pose the height map's grid coordinates skip the terms that are exact zeros: the
    same numbers as the full R^T (p - t), the same selection."""
    from perception_proc.estimates.heightmap import _interior_points

    rng = np.random.default_rng(4)
    lfg = vehicle_pose(1.3, 6.2, 0.37) @ cart_body_from_grid(CART)
    g0 = rng.uniform((-1.0, -1.0, -1.0), (L + 1.0, W + 1.0, 4.0), (5000, 3))     # around the cart, grid frame
    p = apply(lfg, g0)
    p[::50] = np.nan
    box = (0.1, L - 0.1, 0.1, W - 0.1)
    g = _interior_points(p, lfg, -0.5, 3.0, box)
    r, t = lfg[:3, :3], lfg[:3, 3]
    with np.errstate(invalid="ignore"):
        full = (p - t) @ r                                   # row k: R^T (p_k - t), by BLAS
        keep = ((full[:, 2] > -0.5) & (full[:, 2] < 3.0) & (full[:, 0] > box[0]) & (full[:, 0] < box[1])
                & (full[:, 1] > box[2]) & (full[:, 1] < box[3]))
    assert g.shape == (3, keep.sum()) and keep.sum() > 100
    np.testing.assert_allclose(g.T, full[keep], rtol=0, atol=1e-12)
    tilted = lfg @ mount_transform(Mount(parent="world", xyz_m=(0.0, 0.0, 0.0), rpy_deg=(2.0, 0.0, 0.0)))
    gt = _interior_points(p, tilted, -0.5, 3.0, box)          # the general path still selects and transforms
    with np.errstate(invalid="ignore"):
        ft = (p - tilted[:3, 3]) @ tilted[:3, :3]
        kt = ((ft[:, 2] > -0.5) & (ft[:, 2] < 3.0) & (ft[:, 0] > box[0]) & (ft[:, 0] < box[1]) & (ft[:, 1] > box[2])
              & (ft[:, 1] < box[3]))
    np.testing.assert_allclose(gt.T, ft[kt], rtol=0, atol=1e-12)


def test_edge_line_fit_memo_returns_the_fit():
    """The rim edge fits are memoised on their exact input bytes: the same answer as cv2.fitLine, computed once
    for repeated input, and a changed point is a new fit."""
    import cv2

    from perception_proc.estimates.rim import _fit_line

    rng = np.random.default_rng(5)
    pts = np.stack([np.linspace(0, 6, 300), 0.1 * np.linspace(0, 6, 300) + rng.normal(0, 0.01, 300)], 1)
    pts = pts.astype(np.float32)
    vx, vy, _, _ = cv2.fitLine(pts, cv2.DIST_HUBER, 0, 0.01, 0.01).ravel()
    _fit_line.cache_clear()
    assert _fit_line(pts.tobytes()) == (float(vx), float(vy))
    assert _fit_line(pts.copy().tobytes()) == (float(vx), float(vy))
    assert _fit_line.cache_info().hits == 1
    moved = pts.copy()
    moved[7, 1] += 0.5
    _fit_line(moved.tobytes())
    assert _fit_line.cache_info().misses == 2


@pytest.mark.parametrize("x0", [1.6, 2.6])
def test_tube_hiding_part_of_the_rim_never_gives_a_wrong_cart(x0):
    # an auger-like bar between the sensor and the cart's front part: answer right, or no answer
    tube = Box((x0, 3.5, 5.0), (x0 + 0.5, 9.5, 5.4))
    cart, hm = run(cart_shapes(CART, POSE, grain_height=heap(1.5)) + [tube])
    if cart.valid:
        assert np.max(np.linalg.norm(cart.corners - true_corners(), axis=1)) < 0.1
    else:
        assert "no answer" in cart.reason or "rim" in cart.reason


def test_heavy_range_noise_leaves_the_height_map_unbiased():
    """5 cm range noise on a level fill: the lower cluster spans the noise, so the cell medians are unbiased
    (a fixed 10 cm cluster cut the upper tail and read about 1 cm low, which the controller turned into
    overfill)."""
    fn = lambda gx, gy: np.full_like(gx, 1.5)                       # noqa: E731
    dense = PATTERN.model_copy(update={"elevation_count": 330, "azimuth_count": 480})
    cart, hm = run(cart_shapes(CART, POSE, grain_height=fn), pattern=dense,
                   sensor_noise=Noise(range_sigma_m=0.05))
    assert cart.valid
    ok = np.isfinite(hm.heights) & (hm.counts >= 4)
    assert ok.sum() > 300
    assert abs(float(np.mean(hm.heights[ok])) - 1.5) < 0.004


@pytest.mark.parametrize("seed", range(4))
def test_neighbour_grid_matches_a_kd_tree(seed):
    """The rim's "anything right above" test (a grid of radius-sized cells) against scipy's k-d tree on random
    clouds, including points on the cell lines and pairs exactly one radius apart (strictly closer counts)."""
    from scipy.spatial import cKDTree

    from perception_proc.estimates.rim import _has_neighbour

    rng = np.random.default_rng(seed)
    for trial in range(200):
        k, m = int(rng.integers(1, 400)), int(rng.integers(1, 200))
        xy = rng.uniform(-3.0, 3.0, (k, 2))
        others = rng.uniform(-1.0, 2.0, (m, 2)) * rng.uniform(0.1, 2.0)
        radius = (0.25, 0.1, 0.5)[trial % 3]
        if trial % 2:   # on the grid: cell lines and exact-radius pairs
            xy, others = np.round(xy * 4) / 4, np.round(others * 4) / 4
        d, _ = cKDTree(others).query(xy, k=1, distance_upper_bound=radius)
        np.testing.assert_array_equal(_has_neighbour(xy, others, radius), np.isfinite(d))


@pytest.mark.parametrize("seed", range(2))
def test_neighbour_pairs_and_grid_agree(seed):
    """The two kernels of the "anything right above" test: every pair (few pairs) and the grid (many) give the
    same flags, on cell lines and at exactly one radius too."""
    from perception_proc.estimates.neighbours import near_in_grid, near_pairs

    rng = np.random.default_rng(seed)
    flags = []
    for trial in range(100):
        others = rng.uniform(-1.0, 2.0, (int(rng.integers(1, 150)), 2))
        radius = (0.25, 0.1, 0.5)[trial % 3]
        lo = others.min(axis=0) - radius
        q = rng.uniform(lo, others.max(axis=0) + radius, (int(rng.integers(1, 300)), 2))
        if trial % 2:
            q, others = np.round(q * 4) / 4, np.round(others * 4) / 4
            lo = others.min(axis=0) - radius
        want = near_in_grid(q, others, lo, radius)
        np.testing.assert_array_equal(near_pairs(q, others, radius), want)
        flags.append(want)
    assert 0.1 < np.mean(np.concatenate(flags)) < 0.9          # both answers well represented


@pytest.mark.parametrize("seed", range(3))
def test_neighbour_grid_shortcuts_give_the_plain_searchs_answers(seed):
    """The grid kernel's half-cell shortcut and early exit against its plain form and every pair, on dense clouds
    (a dust cloud's returns: thousands of points in a few cells), sparse ones, and points on the cell lines."""
    from perception_proc.estimates.neighbours import near_in_grid, near_in_grid_plain, near_pairs

    rng = np.random.default_rng(seed)
    flags = []
    for trial in range(12):
        radius = (0.25, 0.1, 0.5)[trial % 3]
        spread = (0.3, 3.0)[trial % 2]
        others = rng.normal(0.0, spread, (int(rng.integers(500, 1500)), 2))
        q = rng.normal(0.2, spread * 1.5, (int(rng.integers(500, 2000)), 2))
        if trial % 4 == 3:                                           # on the cell lines, exact radii apart
            q, others = np.round(q * 8) / 8, np.round(others * 8) / 8
        lo = others.min(axis=0) - radius
        q = q[np.all((q >= lo) & (q <= others.max(axis=0) + radius), axis=1)]
        want = near_pairs(q, others, radius)
        np.testing.assert_array_equal(near_in_grid(q, others, lo, radius), want)
        np.testing.assert_array_equal(near_in_grid_plain(q, others, lo, radius), want)
        flags.append(want)
    assert 0.1 < np.mean(np.concatenate(flags)) < 0.95              # both answers well represented


@pytest.mark.parametrize("seed", range(2))
def test_roof_cell_bound_holds_and_changes_no_answer(seed):
    """The bound on the roof cells that points above the rim can cover (their bounding box grown by a cell
    diagonal) is never below the cells they do cover, in any rectangle, so using it changes no answer; dense
    patches, thin strips and scattered points, roofs and open carts both."""
    from perception_proc.estimates.roof import roof_cells, roof_cells_bound, roofed

    rng = np.random.default_rng(seed)
    answers = []
    for trial in range(150):
        kind = trial % 3
        if kind == 0:                                           # a dense patch (a cab roof)
            above = rng.uniform((-1.0, -1.0), rng.uniform(0.5, 4.0, 2), (int(rng.integers(50, 3000)), 2)).T
        elif kind == 1:                                         # a thin strip (the auger tube)
            t = rng.uniform(0.0, 4.0, int(rng.integers(10, 3000)))
            a = rng.uniform(0.0, np.pi)
            above = np.stack([t * np.cos(a), t * np.sin(a)]) + rng.normal(0.0, 0.1, (2, t.size))
        else:                                                   # a few scattered points
            above = rng.uniform(-4.0, 4.0, (2, int(rng.integers(0, 40))))
        above = np.ascontiguousarray(above)
        a = rng.uniform(0.0, np.pi)
        u = np.array([np.cos(a), np.sin(a)])
        centre, sides = rng.uniform(-1.0, 2.0, 2), np.sort(rng.uniform(0.3, 8.0, 2))[::-1]
        bound = roof_cells_bound(above)
        covered, cells = roof_cells(above, centre, u, sides[0], sides[1])
        assert covered <= bound
        plain = roofed(above, centre, u, sides[0], sides[1])
        assert roofed(above, centre, u, sides[0], sides[1], bound) == plain
        answers.append(plain)
    assert 0 < sum(answers) < len(answers)


def test_cell_index_matches_the_integer_reference():
    """The height map's float64 cell index against its integer form (truncate, clip to the last cell,
    i * ny + j), at cell edges, the far walls, tiny and one-point inputs."""
    nx, ny, length, width = 60, 30, 6.3, 3.1
    rng = np.random.default_rng(3)
    edges_x = np.arange(nx + 1) * (length / nx)
    edges_y = np.arange(ny + 1) * (width / ny)
    gx = np.concatenate([rng.random(5000) * length, edges_x, np.nextafter(edges_x, 0), [length, 1e-300]])
    gy = np.concatenate([rng.random(5000) * width, np.resize(edges_y, edges_x.size),
                         np.resize(np.nextafter(edges_y, np.inf), edges_x.size), [width, 0.0]])
    for sl in (slice(None), slice(0, 1), slice(0, 0)):
        x, y = gx[sl], gy[sl]
        ref = np.minimum((x * (nx / length)).astype(np.int64), nx - 1) * ny \
            + np.minimum((y * (ny / width)).astype(np.int64), ny - 1)
        got = _cell_index(x, y, nx / length, ny / width, (nx, ny))
        assert got.dtype == np.float64
        np.testing.assert_array_equal(got.astype(np.int64), ref)
        np.testing.assert_array_equal(got, ref.astype(np.float64))


@pytest.mark.parametrize("m", [2, 3, 6, 57, 400])
def test_line_fits_are_numpys_polyfits(m):
    """The stream's shared-matrix line fits against ``np.polyfit`` one by one: the same float64 bits, signed
    zeros, a steep and a level line included."""
    rng = np.random.default_rng(m)
    z = 1.0 + rng.random(m) * (0.3 if m % 2 else 2.0)
    x = 0.05 * rng.normal(size=m) + 2.0
    y = 3.0 * z - 1.0
    z[0], x[-1] = -0.0, -0.0
    for ys in ((x, y), (y,), (np.full(m, 0.5), x)):
        got = line_fits(z, ys)
        want = [tuple(np.polyfit(z, v, 1)) for v in ys]
        assert np.array(got).tobytes() == np.array(want).tobytes()
