"""The point-cloud panels: every depth-giving sensor's points in the cart frame, from above and from the side.

Frame: the cart grid frame of the height maps (docs/CONTRACTS.md): x from the front wall's inner face towards
the rear, y from the left wall's inner face towards the right, z above the cart floor, m. It rides on the cart,
so on uneven ground it stands on the cart's plane. Each sensor's points (its block's rows X, Y, Z, range in its
camera axes) are moved into it with the machines' poses of the snapshot's ``dyn_state``::

    grid_from_sensor = grid_from_cart_body @ inv(world_from_cart) @ world_from_parent @ parent_from_sensor

From above, x runs to the right and y up (the front wall at the left, the left wall at the bottom, as seen from
above); from the side, x to the right and z up (seen from the cart's left). Both views share one scale (px per
m) and the x range, so the two pictures line up. Drawn from the cart's dimensions: the interior (inner wall
faces, white), the outer edge of walls and rim (grey), the section numbers (from above), the target fill level
and the ground at z = -floor height (from the side). Points are coloured by z on one fixed scale, the ground to
HEIGHT_HEADROOM_M above the rim; each sensor has its marker shape (legend) and its position marked. Higher
points are drawn over lower ones from above, nearer over farther from the side.

Without the cart's geometry or the machines' poses, one sensor's points (the LiDAR's, else the first camera's)
are drawn in its own frame (x forward, y left, z up), coloured by range, extents from their percentiles
(:func:`sensor_frame_view`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import cv2
import numpy as np

from cosim.world.geometry import cart_grid_from_body, entity_pose, invert

from .draw import AXIS, FONT, FONT_SCALE, TEXT, Plot, axes, canvas, colour_lut, colourbar, text
from .viewinfo import CartShape, SensorMount, ViewInfo

__all__ = ["PLOT_W", "PLOT_H", "PLOT_BOX", "MARKERS", "Cloud", "grid_from_sensor", "clouds_in_cart", "layout",
           "height_level", "cart_view", "sensor_frame_view", "lidar_frame"]

#: size of the point-cloud drawings, px, and their plot area (x0, y0, x1, y1): room for the legend above, the
#: ticks and labels below and left, the colour scale right
PLOT_W, PLOT_H = 560, 440
PLOT_BOX = (48, 58, PLOT_W - 80, PLOT_H - 44)
#: baselines of the legend's two lines above the plot, px
LEGEND_ROWS = (16, 33)
#: ground shown around the cart's outer edge, m; room around a sensor's position, m; extents are rounded out to
#: EXTENT_STEP_M (the picture holds still while the machines move a little)
VIEW_MARGIN_M = 1.0
SENSOR_MARGIN_M = 0.6
EXTENT_STEP_M = 1.0
#: the height scale's top above the rim, m (higher points take its top colour)
HEIGHT_HEADROOM_M = 1.0
#: the colour map of heights and of ranges, from this level of OpenCV's turbo (its darkest end is left out: the
#: dark background swallows it)
HEIGHT_CMAP, HEIGHT_FIRST_LEVEL = cv2.COLORMAP_TURBO, 40
#: each sensor's marker, (row, column) pixel offsets, in the order of the view's sensors (cycled): a 2 x 2 dot,
#: a plus, a cross, a ring
MARKERS = (((0, 0), (0, 1), (1, 0), (1, 1)),
           ((0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)),
           ((0, 0), (-1, -1), (1, 1), (-1, 1), (1, -1)),
           ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)))
OUTLINE, OUTLINE_OUTER, TARGET, GROUND = (255, 255, 255), (150, 150, 150), (96, 192, 240), (60, 110, 150)
#: about how many metre ticks along x and along y or z (and on the colour scale)
AXIS_TICKS = (8, 6)
#: the ticks between sections on the long walls (from above), m; a sensor's position mark, px
SECTION_TICK_M, SENSOR_MARK_PX = 0.15, 10
#: points the fallback drawing's extents (robust percentiles) are taken from, at most
EXTENT_SAMPLE = 4096
#: the dyn_state struct that holds the machines' poses (docs/CONTRACTS.md)
STATE_STRUCT = "dyn_state"


@dataclass(frozen=True)
class Cloud:
    """One sensor's points in the cart grid frame: ``points`` (N, 3) float32 m (finite rows only), the sensor's
    position ``origin`` (3,) m, and its index in the view (its marker)."""

    sensor: SensorMount
    index: int
    points: np.ndarray
    origin: np.ndarray


def grid_from_sensor(cart: CartShape, sensor: SensorMount, state: Mapping[str, float] | None) -> np.ndarray | None:
    """(4, 4) float64: the sensor (its points' camera axes) in the cart grid frame at the machines' poses of
    ``state`` (dyn_state fields, cosim.world.geometry.entity_pose); None when the state lacks a pose it needs or
    a pose is not finite."""
    grid_from_body = cart_grid_from_body(cart)
    if sensor.parent == "cart":
        return grid_from_body @ sensor.matrix
    try:
        world_from_cart = entity_pose(state, "cart")
        world_from_parent = np.eye(4) if sensor.parent == "world" else entity_pose(state, sensor.parent)
    except (KeyError, TypeError, ValueError):
        return None
    m = grid_from_body @ invert(world_from_cart) @ world_from_parent @ sensor.matrix
    return m if np.isfinite(m).all() else None


def clouds_in_cart(view: ViewInfo, structs: Mapping[str, dict], arrays: Mapping[str, np.ndarray]) -> list[Cloud]:
    """Every sensor of ``view`` whose points block is in ``arrays`` and whose pose is known, in the cart grid
    frame (an empty list when none is)."""
    state = structs.get(STATE_STRUCT)
    out = []
    for k, s in enumerate(view.sensors):
        pts = arrays.get(s.block)
        if pts is None:
            continue
        g = grid_from_sensor(view.cart, s, state)
        if g is None:
            continue
        # float32 (the block's precision; the drawing needs millimetres at most): a quarter of the float64 cost
        p = np.asarray(pts, np.float32).reshape(-1, pts.shape[-1])[:, :3] @ g[:3, :3].T.astype(np.float32)
        p += g[:3, 3].astype(np.float32)
        out.append(Cloud(s, k, p[np.isfinite(p).all(axis=1)], g[:3, 3].copy()))
    return out


def _round_out(lo: float, hi: float) -> tuple[float, float]:
    return float(np.floor(lo / EXTENT_STEP_M) * EXTENT_STEP_M), float(np.ceil(hi / EXTENT_STEP_M) * EXTENT_STEP_M)


def layout(cart: CartShape, origins: list[np.ndarray]) -> tuple[Plot, Plot]:
    """(from above, from the side): the plots of the cart (with VIEW_MARGIN_M of ground around its outer edge,
    the ground line) and the sensors' positions ``origins`` (3,) m, sharing the x range and one scale."""
    o = cart.outer_m + VIEW_MARGIN_M
    xs = [-o, cart.interior_length_m + o] + [p[0] + d for p in origins for d in (-SENSOR_MARGIN_M, SENSOR_MARGIN_M)]
    ys = [-o, cart.interior_width_m + o] + [p[1] + d for p in origins for d in (-SENSOR_MARGIN_M, SENSOR_MARGIN_M)]
    zs = [-cart.floor_height_m - VIEW_MARGIN_M / 2, cart.rim_above_floor_m + VIEW_MARGIN_M] + \
        [p[2] + SENSOR_MARGIN_M for p in origins]
    u, v, w = _round_out(min(xs), max(xs)), _round_out(min(ys), max(ys)), _round_out(min(zs), max(zs))
    top, side = Plot.fit(PLOT_BOX, u, v), Plot.fit(PLOT_BOX, u, w)
    scale = min(top.scale, side.scale)
    return Plot.fit(PLOT_BOX, u, v, scale), Plot.fit(PLOT_BOX, u, w, scale)


def height_scale(cart: CartShape) -> tuple[float, float]:
    """(lowest, highest) z of the colour scale, m above the cart floor: the ground to HEIGHT_HEADROOM_M above the
    rim."""
    return -cart.floor_height_m, cart.rim_above_floor_m + HEIGHT_HEADROOM_M


def height_level(z: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """(N,) uint8 rows of the colour table of heights ``z`` (N,) m on the scale lo .. hi (clipped)."""
    return np.clip((np.asarray(z) - lo) * (255.0 / max(hi - lo, 1e-9)), 0, 255).round().astype(np.uint8)


def _points(img, plot: Plot, u, v, level, key, marker) -> int:
    """Draw points (u, v) m in the colours of table rows ``level``, in the order of ``key`` (last on top), each
    as ``marker``; returns how many fell inside the plot box."""
    x0, y0, x1, y1 = plot.box
    px = np.rint(plot.col(u)).astype(np.int64)
    py = np.rint(plot.row(v)).astype(np.int64)
    ok = (px > x0 + 1) & (px < x1 - 1) & (py > y0 + 1) & (py < y1 - 1)
    px, py = px[ok], py[ok]
    order = np.argsort(key[ok], kind="stable")                 # a radix sort of uint8 / uint16 keys
    px, py, col = px[order], py[order], colour_lut(HEIGHT_CMAP, HEIGHT_FIRST_LEVEL)[level[ok][order]]
    for dy, dx in marker:
        img[py + dy, px + dx] = col
    return int(ok.sum())


def _rect(img, plot: Plot, u0, v0, u1, v1, colour) -> None:
    cv2.rectangle(img, plot.pixel(u0, v0), plot.pixel(u1, v1), colour, 1)


def _legend(img, clouds: list[Cloud], drawn: list[int]) -> None:
    """Each sensor's marker (drawn twice its size), name, kind and points (in view, of those valid) on the lines
    above the plot, a new line when one is full."""
    x, row = PLOT_BOX[0], 0
    for c, n in zip(clouds, drawn):
        label = f"{c.sensor.name} ({c.sensor.kind}): {n}" + (f" of {len(c.points)}" if n != len(c.points) else "") \
            + " points in view"
        width = cv2.getTextSize(label, FONT, FONT_SCALE, 1)[0][0] + 14
        if x + width > PLOT_W and x > PLOT_BOX[0] and row + 1 < len(LEGEND_ROWS):
            x, row = PLOT_BOX[0], row + 1
        y = LEGEND_ROWS[row]
        for dy, dx in MARKERS[c.index % len(MARKERS)]:
            img[y - 5 + 2 * dy:y - 3 + 2 * dy, x + 2 + 2 * dx:x + 4 + 2 * dx] = TEXT
        text(img, label, (x + 12, y))
        x += width + 16


def _outline_top(img, plot: Plot, cart: CartShape, sections: int) -> None:
    """The cart from above: outer edge of walls and rim (grey), interior (white), section numbers under the left
    wall (where no sensor looks) and ticks between sections on the long walls."""
    length, width, o = cart.interior_length_m, cart.interior_width_m, cart.outer_m
    _rect(img, plot, -o, -o, length + o, width + o, OUTLINE_OUTER)
    _rect(img, plot, 0.0, 0.0, length, width, OUTLINE)
    for k in range(sections):
        cx, cy = plot.pixel((k + 0.5) * length / sections, -o)
        text(img, str(k + 1), (cx - 4, cy + 14), colour=OUTLINE_OUTER)
        if k:
            x = k * length / sections
            cv2.line(img, plot.pixel(x, 0.0), plot.pixel(x, SECTION_TICK_M), OUTLINE_OUTER, 1)
            cv2.line(img, plot.pixel(x, width), plot.pixel(x, width - SECTION_TICK_M), OUTLINE_OUTER, 1)


def _outline_side(img, plot: Plot, cart: CartShape, target_m: float) -> None:
    """The cart from its left: outer edge from the floor's underside to the rim top (grey), interior (white), the
    target fill level (yellow) and the ground's label (its line is drawn under the points)."""
    length, o = cart.interior_length_m, cart.outer_m
    _, ground = plot.pixel(0.0, -cart.floor_height_m)
    text(img, "ground", (plot.box[0] + 4, ground + 14), colour=GROUND)
    _rect(img, plot, -o, -cart.wall_thickness_m, length + o, cart.rim_above_floor_m, OUTLINE_OUTER)
    _rect(img, plot, 0.0, 0.0, length, cart.interior_depth_m, OUTLINE)
    cv2.line(img, plot.pixel(0.0, target_m), plot.pixel(length, target_m), TARGET, 1)
    tx, ty = plot.pixel(length, target_m)
    text(img, "target", (tx + 4, ty + 4), colour=TARGET)


def cart_view(view: ViewInfo, clouds: list[Cloud], which: str, sections: int = 0) -> np.ndarray:
    """The PLOT_H x PLOT_W BGR drawing of ``clouds`` in the cart frame, ``which`` "top" (from above) or "side"
    (from the cart's left), with the cart's outline; ``sections``: how many section numbers to write (0: none)."""
    cart = view.cart
    top, side = layout(cart, [c.origin for c in clouds])
    plot = top if which == "top" else side
    img = canvas(PLOT_H, PLOT_W)
    lo, hi = height_scale(cart)
    if which == "side":                                        # the ground under the points
        _, ground = plot.pixel(0.0, -cart.floor_height_m)
        cv2.line(img, (plot.box[0] + 1, ground), (plot.box[2] - 1, ground), GROUND, 1)
    y_near, y_far = top.v_lim
    drawn = []
    for c in clouds:
        p, marker = c.points, MARKERS[c.index % len(MARKERS)]
        level = height_level(p[:, 2], lo, hi)
        if which == "top":                                     # higher over lower
            drawn.append(_points(img, plot, p[:, 0], p[:, 1], level, level, marker))
        else:                                                  # nearer (smaller y) over farther
            key = np.clip((y_far - p[:, 1]) * (65535 / (y_far - y_near)), 0, 65535).astype(np.uint16)
            drawn.append(_points(img, plot, p[:, 0], p[:, 2], level, key, marker))
    if which == "top":
        _outline_top(img, plot, cart, sections)
        labels = ("x from the front wall (m)", "y from the left wall (m)")
    else:
        _outline_side(img, plot, cart, view.target_fill_m)
        labels = ("x from the front wall (m)", "z above the cart floor (m)")
    for c in clouds:                                           # where each sensor is
        cx, cy = plot.pixel(c.origin[0], c.origin[1] if which == "top" else c.origin[2])
        if plot.box[0] < cx < plot.box[2] and plot.box[1] < cy < plot.box[3]:
            cv2.drawMarker(img, (cx, cy), OUTLINE, cv2.MARKER_TRIANGLE_UP, SENSOR_MARK_PX, 1)
            text(img, c.sensor.name, (cx + 7, cy - 4))
    axes(img, plot.box, plot.u_lim, plot.v_lim, *labels, ticks=AXIS_TICKS)
    x1 = plot.box[2]
    colourbar(img, (x1 + 22, plot.box[1] + 18, x1 + 36, plot.box[3]), lo, hi,
              colour_lut(HEIGHT_CMAP, HEIGHT_FIRST_LEVEL), "z (m)", ticks=AXIS_TICKS[1])
    _legend(img, clouds, drawn)
    if not any(len(c.points) for c in clouds):
        text(img, "no valid points", (PLOT_W // 3, PLOT_H // 2), 0.5)
    return img


def lidar_frame(points: np.ndarray) -> np.ndarray:
    """(N, 3) points of the LiDAR block (camera axes: X right, Y up, Z forward) in the lidar frame the README
    and the recording use: x forward, y left, z up."""
    p = np.asarray(points, dtype=np.float32)
    return np.stack([p[:, 2], -p[:, 0], p[:, 1]], axis=1)


def sensor_frame_view(points: np.ndarray, which: str, why: str, block: str = "lidar_points") -> np.ndarray:
    """The fallback drawing of one sensor's points block ``block`` (N, 4) (camera axes, range) in the sensor's own
    frame with body axes: from above ("top": x forward up the picture, y left to the left) or from its right side
    ("side": x forward to the right, z up), colour = range; ``why`` says on the picture why the cart frame is not
    used."""
    p = np.asarray(points, dtype=np.float32).reshape(-1, points.shape[-1])
    p = p[np.isfinite(p[:, :3]).all(axis=1)]
    rng = p[:, 3] if p.shape[1] > 3 else np.linalg.norm(p[:, :3], axis=1)
    q = lidar_frame(p[:, :3])
    img = canvas(PLOT_H, PLOT_W)
    text(img, f"{block} in its sensor's frame ({why}): {len(q)} points", (PLOT_BOX[0], LEGEND_ROWS[0]), colour=AXIS)
    if not len(q):
        text(img, "no valid points", (PLOT_W // 3, PLOT_H // 2), 0.5)
        return img
    # extents from the 0.5 and 99.5 percentiles of at most EXTENT_SAMPLE evenly spaced points
    u, v, labels = ((-q[:, 1], q[:, 0], ("y left (m)", "x forward (m)")) if which == "top" else
                    (q[:, 0], q[:, 2], ("x forward (m)", "z up (m)")))
    step = max(1, len(u) // EXTENT_SAMPLE)
    lim_u, lim_v = np.percentile(u[::step], (0.5, 99.5)), np.percentile(v[::step], (0.5, 99.5))
    plot = Plot.fit(PLOT_BOX, lim_u, lim_v)
    plot = Plot.fit(PLOT_BOX, lim_u, lim_v, plot.scale * 0.94)
    lo, hi = float(rng.min()), float(rng.max())
    level = height_level(rng, lo, hi)
    _points(img, plot, u, v, level, np.zeros(len(u), np.uint8), MARKERS[0])
    (ul0, ul1), v_lim = plot.u_lim, plot.v_lim
    if which == "top":                                         # the axis shows y (left), which is -u
        axes(img, plot.box, (-ul1, -ul0), v_lim, *labels, u_reversed=True)
    else:
        axes(img, plot.box, (ul0, ul1), v_lim, *labels)
    x1 = plot.box[2]
    colourbar(img, (x1 + 22, plot.box[1] + 18, x1 + 36, plot.box[3]), lo, hi,
              colour_lut(HEIGHT_CMAP, HEIGHT_FIRST_LEVEL), "range m")
    return img
