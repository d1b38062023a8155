"""Cart boundary: the rim rectangle found in the LiDAR points, hence the cart pose.

Works in the *level frame* (the sensor's parent vehicle body frame: x forward, y left, z up from flat ground;
``body_from_sensor`` is the mount, known like the GNSS pose). The cart's dimensions are known; its pose is not.

1. Rim candidates: valid points within :data:`RIM_BAND_M` (plus 3 sigma of range noise) of the rim-top height.
2. Top-down occupancy raster (:data:`RASTER_M` cells), dilated so that points closer than :data:`CLOSE_M`
   connect; connected components (OpenCV); each gets ``cv2.minAreaRect`` of its points. The rim ring still
   breaks into pieces where the auger or the stream hides it, so pieces are merged greedily while the union
   stays cart-sized.
3. A component is a cart candidate when its rectangle is no larger than the cart's outer rim (plus
   :data:`SIZE_TOL_M`), spans at least :data:`MIN_SPAN_FRACTION` of the cart length, and few points inside it
   lie well above the rim (a tractor cab or roof would). The candidate with most rim points wins.
4. Orientation from the rectangle's long side, its sign from the heading hint (the cart is towed forward).
   Per axis, a span matching the known outer size fixes the centre; a shorter span means a partly visible cart:
   the end whose points come from beams at the pattern's border or next to an occluder is the cut one and the
   other end anchors the known size. If both ends are cut, or the cut end cannot be told, there is no answer.

Corners are the interior corners at rim-top height, in grid-frame order k = 0..3: front-left (grid (0, 0)),
rear-left (L, 0), rear-right (L, W), front-right (0, W).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from cosim.config import Cart
from cosim.geometry import cart_body_from_grid, make_transform, rot_z

__all__ = ["CartEstimate", "find_cart", "border_beams", "RIM_BAND_M", "RASTER_M", "SIZE_TOL_M", "NO_CART"]

#: half-height of the slab around the rim top in which points count as rim candidates, m
RIM_BAND_M = 0.10
#: top-down raster cell for the component search, m
RASTER_M = 0.05
#: dilation kernel that joins rim points across small gaps, m
CLOSE_M = 0.40
#: slack on the known outer rim size, m
SIZE_TOL_M = 0.30
#: a span within this of the known outer size counts as fully seen, m
FULL_SPAN_TOL_M = 0.15
#: smallest long-side span, as a fraction of the outer length, for a candidate
MIN_SPAN_FRACTION = 0.35
#: width of the strip at each end examined for border/occlusion points, m
END_STRIP_M = 0.20
#: fraction of end-strip points from border beams that marks the end as cut
CUT_FRACTION = 0.15
#: points this far above the rim top inside a rectangle count against it (a cab roof, not a stream), m
ABOVE_RIM_M = 0.20
#: largest fraction of inside points allowed above the rim
MAX_ABOVE_FRACTION = 0.3
#: fewest rim points for an answer
MIN_RIM_POINTS = 30
#: a neighbouring beam nearer by this fraction of the range marks an occluder, dimensionless
OCCLUDER_REL = 0.10


@dataclass(frozen=True)
class CartEstimate:
    """Result of :func:`find_cart`. ``corners`` (4, 3) float64 m, level frame (NaN when not ``valid``);
    ``level_from_grid`` (4, 4); ``yaw_rad`` cart heading in the level frame; ``partial`` whether an end was
    anchored from the known size; ``reason`` why there is no answer ('' when valid)."""

    valid: bool
    corners: np.ndarray
    level_from_grid: np.ndarray
    yaw_rad: float
    centre_xy: tuple[float, float]
    n_points: int
    partial: bool
    reason: str


NO_CART = CartEstimate(False, np.full((4, 3), np.nan), np.full((4, 4), np.nan), math.nan, (math.nan, math.nan),
                       0, False, "not evaluated")


def _none(reason: str, n: int = 0) -> CartEstimate:
    return CartEstimate(False, NO_CART.corners, NO_CART.level_from_grid, math.nan, (math.nan, math.nan), n, False,
                        reason)


def border_beams(ranges: np.ndarray, shape: tuple[int, int] | None) -> np.ndarray:
    """(N,) bool: beams on the pattern's outer rows/columns, or next to a beam nearer by more than
    :data:`OCCLUDER_REL` of the range (an occluder). ``ranges`` (N,) m, NaN invalid; ``shape`` (rows, cols) of
    a row-major grid pattern, None for a table without layout (then every beam counts as a border beam)."""
    if shape is None:
        return np.ones(ranges.shape[0], bool)
    rows, cols = shape
    r = ranges.reshape(rows, cols)
    out = np.zeros((rows, cols), bool)
    out[0, :] = out[-1, :] = out[:, 0] = out[:, -1] = True
    pad = np.pad(r, 1, constant_values=np.nan)
    with np.errstate(invalid="ignore"):
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                if di == dj == 0:
                    continue
                nb = pad[1 + di:1 + di + rows, 1 + dj:1 + dj + cols]
                out |= nb < r * (1.0 - OCCLUDER_REL)
    return out.ravel()


def _outer(cart: Cart) -> tuple[float, float, float]:
    rw = cart.rim_width_m
    return cart.interior_length_m + 2 * rw, cart.interior_width_m + 2 * rw, rw


def _components(xy: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the connected groups of top-down points (OpenCV connected components on a raster)."""
    lo = xy.min(axis=0) - 2 * CLOSE_M
    ij = np.floor((xy - lo) / RASTER_M).astype(np.int64)
    h, w = int(ij[:, 1].max()) + int(3 * CLOSE_M / RASTER_M), int(ij[:, 0].max()) + int(3 * CLOSE_M / RASTER_M)
    img = np.zeros((h, w), np.uint8)
    img[ij[:, 1], ij[:, 0]] = 255
    # dilation (not closing: a disc's rim slips into one-pixel gaps of a dotted line) joins points closer
    # than CLOSE_M; labels are read back at the points themselves
    k = max(3, int(round(CLOSE_M / RASTER_M)) | 1)
    img = cv2.dilate(img, np.ones((k, k), np.uint8))
    n, labels = cv2.connectedComponents(img, connectivity=8)
    lab = labels[ij[:, 1], ij[:, 0]]
    order = np.argsort(lab, kind="stable")
    bounds = np.searchsorted(lab[order], np.arange(1, n + 1))
    return [g for g in np.split(order, bounds[:-1])[1:] if g.size]


def find_cart(points: np.ndarray, border: np.ndarray, cart: Cart, heading_xy=(1.0, 0.0),
              noise_sigma_m: float = 0.0) -> CartEstimate:
    """Find the cart rim in level-frame points.

    ``points`` (N, 3) float, m, level frame, NaN rows invalid; ``border`` (N,) bool from :func:`border_beams`;
    ``heading_xy`` direction the cart faces (the towing direction, level frame); returns a :class:`CartEstimate`.
    """
    p = np.asarray(points, dtype=np.float64)
    ok = np.isfinite(p).all(axis=1)
    band = RIM_BAND_M + 3.0 * noise_sigma_m
    top = cart.rim_top_m
    cand = np.flatnonzero(ok & (np.abs(p[:, 2] - top) <= band))
    if cand.size < MIN_RIM_POINTS:
        return _none(f"{cand.size} points at rim height, need {MIN_RIM_POINTS}", int(cand.size))
    lo_len, lo_wid, rw = _outer(cart)
    xy = p[cand, :2]
    above = np.flatnonzero(ok & (p[:, 2] > top + band + ABOVE_RIM_M))
    def fits(g: np.ndarray):
        """(long side direction, n points) if the group's rectangle is cart-sized and not roofed, else None."""
        rect = cv2.minAreaRect(xy[g].astype(np.float32))
        box = cv2.boxPoints(rect).astype(np.float64)             # 4 corners in order
        e1, e2 = box[1] - box[0], box[2] - box[1]
        n1, n2 = float(np.hypot(*e1)), float(np.hypot(*e2))
        long_side, short_side = max(n1, n2), min(n1, n2)
        if long_side > lo_len + SIZE_TOL_M or short_side > lo_wid + SIZE_TOL_M:
            return None
        u_long = (e1 / max(n1, 1e-12)) if n1 >= n2 else (e2 / max(n2, 1e-12))
        if above.size:
            d = p[above, :2] - box.mean(axis=0)
            along, across = d @ u_long, d @ np.array([-u_long[1], u_long[0]])
            n_in = int(np.count_nonzero((np.abs(along) <= long_side / 2) & (np.abs(across) <= short_side / 2)))
            if n_in > MAX_ABOVE_FRACTION * (g.size + n_in):
                return None
        return u_long, long_side

    # the rim ring breaks into pieces (sparse rows, occlusion by the auger or the stream): grow each piece,
    # largest first, by every other piece that keeps the union cart-sized; keep the largest union
    comps = sorted((g for g in _components(xy) if g.size >= 3), key=lambda g: -g.size)
    best, best_n = None, 0
    for i, seed in enumerate(comps):
        if seed.size < MIN_RIM_POINTS // 3 or seed.size <= best_n // 4:
            break
        if fits(seed) is None:
            continue
        group = seed
        for j, other in enumerate(comps):
            if j != i and fits(merged := np.concatenate([group, other])) is not None:
                group = merged
        res = fits(group)
        if res is None or group.size < MIN_RIM_POINTS or res[1] < MIN_SPAN_FRACTION * lo_len:
            continue
        if group.size > best_n:
            best, best_n = (group, res[0]), group.size
    if best is None:
        return _none("no rim-sized group of points at rim height", int(cand.size))
    g, ux = best
    hx = np.asarray(heading_xy, dtype=np.float64)
    if ux @ hx < 0:
        ux = -ux
    uy = np.array([-ux[1], ux[0]])                              # left of forward
    pts = xy[g]
    s, t = pts @ ux, pts @ uy
    bd = border[cand[g]]
    centre = []
    partial = False
    for coord, known in ((s, lo_len), (t, lo_wid)):
        lo, hi = np.percentile(coord, [0.5, 99.5])
        if hi - lo >= known - FULL_SPAN_TOL_M:
            centre.append(0.5 * (lo + hi))
            continue
        partial = True
        cut_lo = bd[coord <= lo + END_STRIP_M].mean() >= CUT_FRACTION
        cut_hi = bd[coord >= hi - END_STRIP_M].mean() >= CUT_FRACTION
        if cut_lo == cut_hi:
            why = "both ends cut" if cut_lo else "short span with no cut end"
            return _none(f"cart only partly visible ({why}); no answer", int(g.size))
        centre.append(hi - known / 2.0 if cut_lo else lo + known / 2.0)
    c = centre[0] * ux + centre[1] * uy
    yaw = math.atan2(ux[1], ux[0])
    level_from_body = make_transform(rot_z(yaw), (c[0], c[1], 0.0))
    level_from_grid = level_from_body @ cart_body_from_grid(cart)
    L, W = cart.interior_length_m, cart.interior_width_m
    zr = cart.interior_depth_m + cart.rim_height_m
    grid_corners = np.array([[0, 0, zr], [L, 0, zr], [L, W, zr], [0, W, zr]], dtype=np.float64)
    corners = grid_corners @ level_from_grid[:3, :3].T + level_from_grid[:3, 3]
    return CartEstimate(True, corners, level_from_grid, yaw, (float(c[0]), float(c[1])), int(g.size), partial, "")
