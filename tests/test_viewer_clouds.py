"""The point-cloud panels in the cart frame: known points land where the cart's geometry says, on flat and on
tilted ground, with several sensors; the outline is drawn where the cart is; the fallback without a scenario."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from cosim.scenario.config import Scenario
from cosim.viewer.clouds import (
    HEIGHT_CMAP,
    HEIGHT_FIRST_LEVEL,
    MARKERS,
    OUTLINE,
    PLOT_BOX,
    PLOT_H,
    PLOT_W,
    TARGET,
    clouds_in_cart,
    height_scale,
    layout,
    lidar_frame,
)
from cosim.viewer.draw import BACKGROUND, Plot, colour_lut
from cosim.viewer.panels import panel_info, render_panel
from cosim.viewer.snapshot import Snapshot
from cosim.viewer.viewinfo import ViewInfo
from cosim.world.geometry import body_from_camera_axes, cart_body_from_grid, entity_pose, invert, mount_transform
from cosim.world.sensors import world_from_sensor

#: a LiDAR on the combine's mast and a depth camera on the tractor (another body, another marker)
SCENARIO = Scenario.model_validate({"format_version": 1, "sensors": {
    "mast": {"kind": "lidar"},
    "tof": {"kind": "depth_camera", "profile": "tof_kinect_class",
            "mount": {"parent": "tractor", "xyz_m": [-1.0, 0.5, 3.5], "rpy_deg": [0.0, 35.0, 180.0]}}}})
VIEW = ViewInfo.of(SCENARIO)
CART = SCENARIO.cart
L, W, D = CART.interior_length_m, CART.interior_width_m, CART.interior_depth_m


def state(tilted: bool) -> dict:
    """dyn_state poses: the cart behind the tractor, the combine beside it; ``tilted``: every body on its own
    plane (terrain), heaved, rolled and pitched differently."""
    s = {"cart_x_m": 20.0, "cart_y_m": 5.0, "cart_yaw_rad": 0.3, "tractor_x_m": 27.6, "tractor_y_m": 7.2,
         "tractor_yaw_rad": 0.28, "combine_x_m": 20.5, "combine_y_m": -2.1, "combine_yaw_rad": 0.32}
    if tilted:
        s.update(cart_z_m=0.4, cart_roll_rad=-0.05, cart_pitch_rad=0.03, tractor_z_m=0.35,
                 tractor_roll_rad=0.02, tractor_pitch_rad=-0.04, combine_z_m=0.1, combine_roll_rad=0.06,
                 combine_pitch_rad=0.01)
    return s


def in_sensor(sensor_name: str, st: dict, grid_points) -> np.ndarray:
    """(N, 4) points block rows (camera axes, range) of the sensor that sees the cart grid points (N, 3)."""
    world_from_grid = entity_pose(st, "cart") @ cart_body_from_grid(CART)
    sensor_from_world = invert(world_from_sensor(SCENARIO.sensor_set[sensor_name] if sensor_name != "mast"
                                                 else SCENARIO.lidar, st))
    g = np.asarray(grid_points, float)
    w = g @ world_from_grid[:3, :3].T + world_from_grid[:3, 3]
    p = w @ sensor_from_world[:3, :3].T + sensor_from_world[:3, 3]
    return np.column_stack([p, np.linalg.norm(p, axis=1)]).astype(np.float32)


def snapshot(st: dict, mast, tof=None) -> Snapshot:
    arrays = {"lidar_points": mast}
    if tof is not None:
        arrays["cam_tof_points"] = tof
    return Snapshot(frame=3, structs={"dyn_state": st}, arrays=arrays, frames={k: 3 for k in arrays})


def decode(png: bytes) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None and img.shape == (PLOT_H, PLOT_W, 3)
    return img


def blobs(img: np.ndarray) -> list[tuple[float, float, int, float]]:
    """(column, row, area px, z m) of each patch of point colours (the height scale's) inside the plot box, left
    to right; z from the patch's colour."""
    x0, y0, x1, y1 = PLOT_BOX
    lut = colour_lut(HEIGHT_CMAP, HEIGHT_FIRST_LEVEL).astype(np.int64) @ np.array([65536, 256, 1])
    codes = img.astype(np.int64) @ np.array([65536, 256, 1])
    lit = np.zeros(img.shape[:2], np.uint8)
    lit[y0 + 1:y1, x0 + 1:x1] = np.isin(codes[y0 + 1:y1, x0 + 1:x1], lut)
    n, labels, stats, centres = cv2.connectedComponentsWithStats(lit, connectivity=8)
    lo, hi = height_scale(VIEW.cart)
    out = []
    for k in range(1, n):
        level = int(np.flatnonzero(lut == codes[labels == k][0])[0])
        out.append((centres[k][0], centres[k][1], int(stats[k, cv2.CC_STAT_AREA]), lo + level / 255 * (hi - lo)))
    return sorted(out)


def inner_rectangle(img: np.ndarray) -> tuple[int, int, int, int]:
    """(left, top, right, bottom) px of the white outline of the cart's interior (the longest white runs)."""
    white = (img == OUTLINE).all(axis=2)
    rows = np.flatnonzero(white.sum(axis=1) > 0.5 * white.sum(axis=1).max())
    cols = np.flatnonzero(white.sum(axis=0) > 0.5 * white.sum(axis=0).max())
    return int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max())


#: one level of the height colour scale, m
LEVEL_M = (height_scale(VIEW.cart)[1] - height_scale(VIEW.cart)[0]) / 255
#: a 2 x 2 dot's centre is half a pixel right of and below the pixel of its point
DOT = 0.5


def test_plot_maps_metres_to_pixels_at_one_scale():
    p = Plot.fit((0, 0, 100, 50), (0.0, 10.0), (0.0, 2.0))
    assert p.scale == 10.0 and p.pixel(5.0, 1.0) == (50, 25)
    assert p.pixel(0.0, -1.5) == (0, 50) and p.pixel(10.0, 3.5) == (100, 0), "centred, v up, one scale"


@pytest.mark.parametrize("tilted", [False, True], ids=["flat", "terrain"])
def test_known_points_land_in_the_cart_frame(tilted):
    st = state(tilted)
    corners = [(0.0, 0.0, D), (L, W, D), (L / 2, W / 2, 0.0)]     # rim-side corners, floor centre (grid)
    snap = snapshot(st, in_sensor("mast", st, corners), in_sensor("tof", st, corners[::-1]))
    clouds = clouds_in_cart(VIEW, snap.structs, snap.arrays)
    assert [c.sensor.name for c in clouds] == ["mast", "tof"]
    np.testing.assert_allclose(clouds[0].points, corners, atol=1e-5)  # float32 rows of a few metres
    np.testing.assert_allclose(clouds[1].points, corners[::-1], atol=1e-5)
    # each sensor where its mount puts it, in the cart frame
    grid_from_world = invert(entity_pose(st, "cart") @ cart_body_from_grid(CART))
    mast = grid_from_world @ entity_pose(st, "combine") @ mount_transform(SCENARIO.lidar.mount)
    np.testing.assert_allclose(clouds[0].origin, mast[:3, 3], atol=1e-9)
    assert body_from_camera_axes()[:3, 3].tolist() == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("tilted", [False, True], ids=["flat", "terrain"])
def test_from_above_the_points_sit_where_the_drawn_outline_says(tilted):
    """Points at the rim's height near the front-left and rear-right corners and on the floor's centre are drawn
    where the white interior outline (drawn from the cart's dimensions) puts them: x to the right, y up, one
    scale; coloured by their height."""
    st = state(tilted)
    pts = [(0.25, 0.25, D), (L - 0.25, W - 0.25, D), (L / 2, W / 2, 0.0)]
    img = decode(render_panel(snapshot(st, in_sensor("mast", st, pts)), "lidar_top", view=VIEW))
    left, top, right, bottom = inner_rectangle(img)
    scale = (right - left) / L
    assert abs((bottom - top) - W * scale) <= 1, "one scale on both axes"
    found = blobs(img)
    assert len(found) == 3 and all(f[2] == len(MARKERS[0]) for f in found), found
    a, c, b = found                                             # left to right
    assert abs(a[0] - DOT - (left + 0.25 * scale)) <= 1 and abs(a[1] - DOT - (bottom - 0.25 * scale)) <= 1
    assert abs(b[0] - DOT - (right - 0.25 * scale)) <= 1 and abs(b[1] - DOT - (top + 0.25 * scale)) <= 1
    assert abs(c[0] - DOT - (left + right) / 2) <= 1 and abs(c[1] - DOT - (top + bottom) / 2) <= 1
    assert abs(a[3] - D) <= LEVEL_M and abs(b[3] - D) <= LEVEL_M and abs(c[3]) <= LEVEL_M, "colour = height"


def test_from_the_side_ground_floor_and_target_are_where_the_cart_stands():
    st = state(True)
    target, floor_h = VIEW.target_fill_m, CART.floor_height_m
    pts = [(-1.0, W / 2, target), (L / 2, W / 2, 0.3), (L + 1.5, W + 1.0, -floor_h)]
    img = decode(render_panel(snapshot(st, in_sensor("mast", st, pts)), "lidar_side", view=VIEW))
    left, top, right, bottom = inner_rectangle(img)
    scale = (right - left) / L
    assert abs((bottom - top) - D * scale) <= 1, "the interior is D high, at the same scale"
    at_target, inside, ground = blobs(img)
    assert abs(inside[0] - DOT - (left + right) / 2) <= 1 and abs(inside[1] - DOT - (bottom - 0.3 * scale)) <= 1
    target_rows = np.flatnonzero((img[:, left + 3] == TARGET).all(axis=1))
    assert len(target_rows) == 1 and abs(at_target[1] - DOT - target_rows[0]) <= 1, "on the target line"
    assert abs(ground[1] - DOT - (bottom + floor_h * scale)) <= 1.5, "on the ground line"
    assert abs(ground[0] - DOT - (right + 1.5 * scale)) <= 1.5
    assert abs(ground[3] + floor_h) <= LEVEL_M


def test_each_sensor_has_its_marker_and_both_views_share_x():
    st = state(False)
    snap = snapshot(st, in_sensor("mast", st, [(1.0, 1.0, D)]), in_sensor("tof", st, [(5.0, 2.0, D)]))
    img = decode(render_panel(snap, "lidar_top", view=VIEW))
    assert [f[2] for f in blobs(img)] == [len(MARKERS[0]), len(MARKERS[1])], "a 2 x 2 dot, a plus"
    info = panel_info(snap)["lidar_top"]
    assert info["available"] and info["note"] == "cam_tof_points, lidar_points"
    top, side = layout(VIEW.cart, [c.origin for c in clouds_in_cart(VIEW, snap.structs, snap.arrays)])
    assert top.scale == side.scale and top.col(2.5) == side.col(2.5)


def test_without_a_scenario_or_poses_the_lidar_frame_is_drawn():
    pts = np.full((3, 4), np.nan, np.float32)
    pts[0] = (0.0, 0.0, 5.0, 5.0)   # camera axes X right, Y up, Z forward: 5 m ahead
    pts[1] = (1.0, 0.0, 6.0, 6.1)   # 6 m ahead, 1 m to the right (lidar y = -1)
    np.testing.assert_array_equal(lidar_frame(pts[:2, :3]), [[5, 0, 0], [6, -1, 0]])
    for snap, view in ((Snapshot(arrays={"lidar_points": pts}), None),
                       (Snapshot(arrays={"lidar_points": pts}, structs={"dyn_state": {"t_s": 0.0}}), VIEW)):
        top = decode(render_panel(snap, "lidar_top", view=view))
        lit = [(r, c) for c, r, _ in blobs_any(top)]
        (r0, c0), (r1, c1) = sorted(lit, key=lambda rc: rc[1])
        # from above: x forward up the picture, y left to the left; one scale on both axes
        assert c1 > c0 and r1 < r0 and abs((c1 - c0) - (r0 - r1)) <= 1
        side = decode(render_panel(snap, "lidar_side", view=view))
        (r0, c0), (r1, c1) = sorted([(r, c) for c, r, _ in blobs_any(side)], key=lambda rc: rc[1])
        assert c1 > c0 and abs(r1 - r0) <= 0.5, "from the side: x forward to the right, both at z = 0"


def blobs_any(img: np.ndarray) -> list[tuple[float, float, int]]:
    x0, y0, x1, y1 = PLOT_BOX
    lit = np.zeros(img.shape[:2], np.uint8)
    lit[y0 + 1:y1, x0 + 1:x1] = (img[y0 + 1:y1, x0 + 1:x1] != BACKGROUND).any(axis=2)
    n, _, stats, centres = cv2.connectedComponentsWithStats(lit)
    return [(centres[k][0], centres[k][1], int(stats[k, cv2.CC_STAT_AREA])) for k in range(1, n)]


def test_view_record_round_trips_and_refuses_bad_records(tmp_path):
    from cosim.runtime.outputs import write_scenario

    assert ViewInfo.from_json(VIEW.to_json()) == VIEW and ViewInfo.from_dict(VIEW.to_dict()) == VIEW
    short = VIEW.to_dict()
    short["sensors"][0]["parent_from_sensor"] = [1.0] * 15
    nan = VIEW.to_dict()
    nan["cart"]["floor_height_m"] = float("nan")
    missing = VIEW.to_dict()
    del missing["cart"]
    for bad, why in ((short, "16 per sensor pose"), (nan, "finite numbers"), (missing, "not a view record")):
        with pytest.raises(ValueError, match=why):
            ViewInfo.from_dict(bad)
    with pytest.raises(ValueError, match="not a view record"):
        ViewInfo.from_json("{")
    assert ViewInfo.from_scenario_yaml(tmp_path / "scenario.yaml") is None
    write_scenario(tmp_path, SCENARIO)
    assert ViewInfo.from_scenario_yaml(tmp_path / "scenario.yaml") == VIEW


def test_a_camera_only_run_without_a_scenario_draws_the_cameras_points():
    pts = np.array([[0.0, 0.0, 5.0, 5.0], [1.0, 0.0, 6.0, 6.1]], np.float32)
    snap = Snapshot(arrays={"cam_tof_points": pts}, frames={"cam_tof_points": 1})
    assert panel_info(snap)["lidar_top"] == {"available": True, "frame": 1, "note": "cam_tof_points"}
    assert len(blobs_any(decode(render_panel(snap, "lidar_top")))) == 2
