"""Cart boundary: the rim rectangle found in the LiDAR points, hence the cart pose.

Works in the *level frame* (the sensor's parent vehicle body frame: x forward, y left, z up from flat ground;
``body_from_sensor`` is the mount, known like the GNSS pose). The cart's dimensions are known; its pose is not.

1. Rim candidates: valid points within :data:`RIM_BAND_M` (plus :data:`BAND_NOISE_SIGMAS` sigma of range noise) of the rim-top height
   with nothing in the :data:`UNDER_SLAB_M` slab right above them within :data:`UNDER_RADIUS_M` (that would be
   the stream or a cab wall rising from the band).
2. Top-down occupancy raster (:data:`RASTER_M` cells), dilated so that points closer than :data:`CLOSE_M`
   connect; connected components (OpenCV); each gets ``cv2.minAreaRect`` of its points. The rim ring still
   breaks into pieces where the auger or the stream hides it, so pieces are merged greedily while the union
   stays cart-sized.
3. A component is a cart candidate when its rectangle is no larger than the cart's outer rim (plus
   :data:`SIZE_TOL_M`), spans at least :data:`MIN_SPAN_FRACTION` of the cart length and
   :data:`MIN_WIDTH_FRACTION` of its width (a lone line is not a cart), and is not roofed: points
   well above the rim cover little of its area (a tractor cab covers most of its own; the auger tube and the
   stream over an open cart cover a thin strip; :mod:`perception_proc.estimates.roof`). The candidate with most rim
   points wins.
4. Orientation from the rectangle's long side, its sign from the heading hint (the cart is towed forward); a
   long side more than :data:`ACROSS_HEADING_DEG` off the heading is the cart's width (a piece seen over less
   of the cart's length than its width), and the long axis is taken across it.
   Per axis, a span matching the known outer size fixes the centre; a shorter span means a partly visible cart:
   an end whose points come from beams at the pattern's edge, or which lies next to an occluder and covers
   little of its own length (a seen end shows the end rim running across it), is cut, and the other end
   anchors the known size. If both ends
   are cut, or neither is, there is no answer.

Corners are the interior corners at rim-top height, in grid-frame order k = 0..3: front-left (grid (0, 0)),
rear-left (L, 0), rear-right (L, W), front-right (0, W).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from cosim.scenario.config import Cart
from cosim.world.geometry import cart_body_from_grid, make_transform, rot_z
from perception_proc.estimates.neighbours import has_neighbour as _has_neighbour
from perception_proc.estimates.roof import roof_cells_bound, roofed
from perception_proc.orderstats import percentiles

__all__ = ["CartEstimate", "find_cart", "border_beams", "RIM_BAND_M", "RASTER_M", "SIZE_TOL_M", "NO_CART",
           "FOV_EDGE", "OCCLUDED", "BAND_NOISE_SIGMAS"]

#: a rim rectangle whose long side is more than this off the towing direction is a cart seen over less of its
#: length than its width, deg
ACROSS_HEADING_DEG = 45.0
#: half-height of the slab around the rim top in which points count as rim candidates, m
RIM_BAND_M = 0.10
#: the rim band widens by this many sigmas of range noise. One, not three: a grain surface filled near the
#: target lies only some 0.2 m under the rim top, and a 3-sigma band (0.25 m at sigma = 5 cm) let its points
#: join the rim and moved a partly seen cart by up to 0.6 m (heavy_noise); the rim has points to spare
BAND_NOISE_SIGMAS = 1.0
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
#: smallest short-side span, as a fraction of the outer width (a lone wall line, e.g. the combine's own side
#: crossing the rim band, is not a cart)
MIN_WIDTH_FRACTION = 0.5
#: width of the strip at each end examined for border/occlusion points, m
END_STRIP_M = 0.20
#: bit of :func:`border_beams`: the beam is on the pattern's outer rows or columns
FOV_EDGE = 1
#: bit of :func:`border_beams`: a neighbouring beam is nearer (an occluder)
OCCLUDED = 2
#: share of end-strip points next to an occluder above which the end may be hidden rather than seen
OCCLUDED_FRACTION = 0.2
#: bins along an end used to measure how much of it is seen, m
END_BIN_M = 0.20
#: a seen end covers at least this share of its bins (the auger tube may hide a strip of it)
MIN_END_COVER = 0.5
#: fraction of end-strip points from pattern-edge beams that marks the end as cut
CUT_FRACTION = 0.15
#: points this far above the rim top inside a rectangle may be a roof over it, m
ABOVE_RIM_M = 0.20
#: rim candidates with a point well above them within this horizontal distance belong to a vertical structure
#: (the stream, a cab wall), not to the rim, m
UNDER_RADIUS_M = 0.25
#: height of the slab right above the rim band searched for such structures, m
UNDER_SLAB_M = 0.30
#: strip along each long edge used for the line fits, m
EDGE_STRIP_M = 0.25
#: fewest points on an edge for a line fit
MIN_EDGE_POINTS = 15
#: largest correction of the hull-based direction by the line fits, deg
MAX_REFINE_DEG = 5.0
#: largest turn of the rectangle's long side when a piece is merged into a group, deg
MAX_MERGE_TURN_DEG = 10.0
#: fewest rim points for an answer
MIN_RIM_POINTS = 30
#: line fits remembered (_fit_line): the two edges of the last few frames
LINE_FIT_MEMO = 8
#: a neighbouring beam nearer by this fraction of the range marks an occluder, dimensionless
OCCLUDER_REL = 0.10
_KERNEL_3X3 = np.ones((3, 3), np.uint8)
#: largest 16-bit label (connected components)
_U16_MAX = int(np.iinfo(np.uint16).max)
#: the dilation that joins raster cells closer than CLOSE_M (odd side, at least 3 cells)
_CLOSE_KERNEL = np.ones((max(3, int(round(CLOSE_M / RASTER_M)) | 1),) * 2, np.uint8)
#: slack of find_cart's first selection under the band's computed lower edge, far above the rounding of
#: |z - top| <= band (so the selection holds every candidate), m
_PREFILTER_MARGIN_M = 0.01


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
    """(N,) uint8 flags: :data:`FOV_EDGE` for beams on the pattern's outer rows/columns, :data:`OCCLUDED` for
    beams next to a beam nearer by more than :data:`OCCLUDER_REL` of the range. ``ranges`` (N,) m, NaN
    invalid; ``shape`` (rows, cols) of a row-major grid pattern, None for a table without layout (then every
    beam counts as on the edge: a partly seen cart gets no answer)."""
    if shape is None:
        return np.full(ranges.shape[0], FOV_EDGE, np.uint8)
    rows, cols = shape
    r = np.asarray(ranges, np.float32).reshape(rows, cols)
    # nearest neighbour (3 x 3 minimum, OpenCV erosion) with invalid beams counting as infinitely far (fmin
    # drops the NaN of an invalid beam, ranges are never above +inf)
    nearest = cv2.erode(np.fmin(r, np.float32(np.inf)), _KERNEL_3X3, borderType=cv2.BORDER_REPLICATE)
    with np.errstate(invalid="ignore"):
        occluded = np.less(nearest, r * np.float32(1.0 - OCCLUDER_REL))
    out = occluded.view(np.uint8)                                # True is 1: scaled to the OCCLUDED bit
    out *= np.uint8(OCCLUDED)
    out[0, :] |= FOV_EDGE
    out[-1, :] |= FOV_EDGE
    out[:, 0] |= FOV_EDGE
    out[:, -1] |= FOV_EDGE
    return out.ravel()


def _xy(x: np.ndarray, y: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """(K, 2) float64 C-contiguous rows (x, y) of the points ``idx`` (K,) from coordinate rows ``x``, ``y`` (N,)."""
    out = np.empty((idx.size, 2))
    out[:, 0] = x[idx]
    out[:, 1] = y[idx]
    return out


def _end_is_cut(flags: np.ndarray, other: np.ndarray, other_lo: float, other_hi: float) -> bool:
    """Whether one end of the rim is cut off rather than seen: many of its points come from beams at the
    pattern's edge; or many lie next to an occluder *and* they cover little of the cart's extent across that
    end (a seen end shows the end rim running across it, even with the auger tube in front of a strip of it;
    an end seen edge-on from afar shows little of it too, but no occluder). ``flags`` (K,) uint8 and
    ``other`` (K,) m: the end strip's points, their coordinate along the end."""
    if flags.size == 0:
        return True
    if np.mean((flags & FOV_EDGE) > 0) >= CUT_FRACTION:
        return True
    if np.mean((flags & OCCLUDED) > 0) < OCCLUDED_FRACTION:
        return False
    nbins = max(1, int(math.ceil((other_hi - other_lo) / END_BIN_M)))
    b = np.clip(((other - other_lo) / END_BIN_M).astype(np.int64), 0, nbins - 1)
    return np.unique(b).size < MIN_END_COVER * nbins


def _outer(cart: Cart) -> tuple[float, float, float]:
    rw = cart.rim_width_m
    return cart.interior_length_m + 2 * rw, cart.interior_width_m + 2 * rw, rw


def _components(xy: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the connected groups of top-down points (OpenCV connected components on a raster)."""
    # raster cells per coordinate (column by column: the same numbers as on the (K, 2) array, without
    # broadcasting a (2,) offset over short rows)
    col, row = (np.floor((xy[:, a] - (xy[:, a].min() - 2 * CLOSE_M)) / RASTER_M).astype(np.int64) for a in (0, 1))
    pad = int(3 * CLOSE_M / RASTER_M)
    h, w = int(row.max()) + pad, int(col.max()) + pad
    cell = row * w + col                                        # flat raster index of each point
    img = np.zeros((h, w), np.uint8)
    np.put(img, cell, 255)
    # dilation (not closing: a disc's rim slips into one-pixel gaps of a dotted line) joins points closer
    # than CLOSE_M; labels are read back at the points themselves. Every component holds a point, so 16-bit
    # labels do when there are fewer points than that (the same labelling, at under half the cost)
    img = cv2.dilate(img, _CLOSE_KERNEL)
    ltype = cv2.CV_16U if xy.shape[0] < _U16_MAX else cv2.CV_32S
    n, labels = cv2.connectedComponents(img, connectivity=8, ltype=ltype)
    lab = np.take(labels, cell)
    order = np.argsort(lab, kind="stable")
    bounds = np.searchsorted(lab[order], np.arange(1, n + 1)).tolist()
    return [g for a, b in zip(bounds[:-1], bounds[1:]) if (g := order[a:b]).size]


def _hull(xy32: np.ndarray) -> np.ndarray:
    """Convex hull vertices (H, 2) float32 of points (K, 2) float32: ``cv2.minAreaRect`` of a union of pieces
    only needs the union of their hulls (it takes the hull of its input first)."""
    return cv2.convexHull(xy32).reshape(-1, 2)


def _best_group(xy: np.ndarray, above: np.ndarray, lo_len: float, lo_wid: float):
    """(index array into ``xy``, unit long-side direction (2,)) of the best cart-sized group, or None.

    The rim ring breaks into pieces (sparse rows, occlusion by the auger or the stream): each piece, largest
    first, is grown by every other piece that keeps the union cart-sized and unroofed; the largest union
    that spans enough of the cart's length and width wins. ``above`` (2, K): x and y rows of the points well
    above the rim, m.
    Rectangles are fitted to the union of the pieces' convex hulls (the same rectangle as of their points)."""
    above_rows = np.ascontiguousarray(np.asarray(above, np.float64).reshape(2, -1))
    roof_bound = roof_cells_bound(above_rows)

    def fits(hull: np.ndarray):
        """(long side direction, long side m, short side m) if cart-sized and not roofed, else None."""
        box = cv2.boxPoints(cv2.minAreaRect(hull)).astype(np.float64)
        e1, e2 = box[1] - box[0], box[2] - box[1]
        n1, n2 = float(np.hypot(*e1)), float(np.hypot(*e2))
        long_side, short_side = max(n1, n2), min(n1, n2)
        if long_side > lo_len + SIZE_TOL_M or short_side > lo_wid + SIZE_TOL_M:
            return None
        u_long = (e1 / max(n1, 1e-12)) if n1 >= n2 else (e2 / max(n2, 1e-12))
        if roofed(above_rows, box.mean(axis=0), u_long, long_side, short_side, roof_bound):
            return None
        return u_long, long_side, short_side

    comps = sorted((g for g in _components(xy) if g.size >= 3), key=lambda g: -g.size)
    xy32 = xy.astype(np.float32)
    hulls = [_hull(np.take(xy32, g, axis=0)) for g in comps]
    best, best_n = None, 0
    turn = math.cos(math.radians(MAX_MERGE_TURN_DEG))
    total = sum(g.size for g in comps)
    for i, seed in enumerate(comps):
        # a later seed wins only with more points than the best group: none can once that holds every piece
        if seed.size < MIN_RIM_POINTS // 3 or seed.size <= best_n // 4 or best_n == total:
            break
        if (first := fits(hulls[i])) is None:
            continue
        group, hull, u_seed, group_fit = [seed], hulls[i], first[0], first
        for j, other in enumerate(comps):
            # a union whose rectangle axes turn (modulo 90 deg: a square seed may swap its long side) is a
            # diagonal join of unrelated pieces, not more of the rim
            if j != i and (res := fits(merged := _hull(np.concatenate([hull, hulls[j]])))) is not None \
                    and max(abs(res[0] @ u_seed), abs(res[0][0] * u_seed[1] - res[0][1] * u_seed[0])) >= turn:
                group.append(other)
                hull, group_fit = merged, res              # the union's rectangle: no second fit needed
        res = group_fit
        n = sum(g.size for g in group)
        if res is None or n < MIN_RIM_POINTS or res[1] < MIN_SPAN_FRACTION * lo_len \
                or res[2] < MIN_WIDTH_FRACTION * lo_wid:
            continue
        if n > best_n:
            best, best_n = (np.concatenate(group), res[0]), n
    return best


@lru_cache(maxsize=LINE_FIT_MEMO)
def _fit_line(points_f32: bytes) -> tuple[float, float]:
    """Direction (vx, vy) of ``cv2.fitLine`` (Huber, the settings of :func:`_refine_direction`) through the
    (K, 2) float32 points whose bytes are given. Memoised on those bytes: the fit is deterministic (a fixed
    seed for its restarts) and costs more than the rest of the cart search together, and an edge strip often
    returns bit for bit from one frame to the next (the codec quantises small relative motion away)."""
    pts = np.frombuffer(points_f32, np.float32).reshape(-1, 2)
    vx, vy, _, _ = cv2.fitLine(pts, cv2.DIST_HUBER, 0, 0.01, 0.01).ravel()
    return float(vx), float(vy)


def _refine_direction(xy: np.ndarray, u_long: np.ndarray) -> np.ndarray:
    """Long-side direction refined by robust line fits (``cv2.fitLine``, Huber) to the points along the two
    long edges (within :data:`EDGE_STRIP_M` of the extremes across); the rectangle's hull-based angle is
    kept where an edge has fewer than :data:`MIN_EDGE_POINTS` points."""
    across = xy @ np.array([-u_long[1], u_long[0]])
    lo, hi = across.min(), across.max()
    dirs, weights = [], []
    for sel in (across <= lo + EDGE_STRIP_M, across >= hi - EDGE_STRIP_M):
        if (n := np.count_nonzero(sel)) < MIN_EDGE_POINTS:
            continue
        edge = np.compress(sel, xy, axis=0).astype(np.float32)
        d = np.array(_fit_line(edge.tobytes()), dtype=np.float64)
        dirs.append(d if d @ u_long >= 0 else -d)
        weights.append(float(n))
    if not dirs:
        return u_long
    # the weighted mean and the norm written out: the operations of np.average and np.linalg.norm (the same
    # numbers), without their argument handling (~50 us a call)
    w = np.array(weights)
    d = (np.array(dirs) * w[:, None]).sum(axis=0) / w.sum()
    d /= math.sqrt(d @ d)
    return d if abs(d @ u_long) > math.cos(math.radians(MAX_REFINE_DEG)) else u_long


def find_cart(points: np.ndarray, border: np.ndarray, cart: Cart, heading_xy=(1.0, 0.0),
              noise_sigma_m: float = 0.0) -> CartEstimate:
    """Find the cart rim in level-frame points.

    ``points`` (N, 3) float, m, level frame, NaN rows invalid (a row is all NaN or all finite); ``border`` (N,)
    uint8 flags from :func:`border_beams`; ``heading_xy`` direction the cart faces (the towing direction, level
    frame); returns a :class:`CartEstimate`.
    """
    p = np.asarray(points, dtype=np.float64)
    # coordinate rows (contiguous, no copy, for the column-major points of Perception.level_points)
    x, y, z = (np.ascontiguousarray(p[:, k]) for k in range(3))   # invalid beams are whole NaN rows
    band = RIM_BAND_M + BAND_NOISE_SIGMAS * noise_sigma_m
    top = cart.rim_top_m
    with np.errstate(invalid="ignore"):                         # NaN compares False: invalid rows drop out
        # one pass over every beam keeps the points from just under the band up (a small share); the exact
        # tests below then run on those alone
        high = np.flatnonzero(z >= top - band - _PREFILTER_MARGIN_M)
        z_high = z[high]
        cand = high[np.abs(z_high - top) <= band]
        if cand.size < MIN_RIM_POINTS:
            return _none(f"{cand.size} points at rim height, need {MIN_RIM_POINTS}", int(cand.size))
        over = z_high > top + band                              # above the band: the slab and higher
        above = high[over & (z_high > top + band + ABOVE_RIM_M)]
        slab = high[over & (z_high <= top + band + UNDER_SLAB_M)]
    lo_len, lo_wid, _ = _outer(cart)
    xy = _xy(x, y, cand)
    if slab.size:
        # a rim point has nothing right above it; a falling stream or a cab wall rising from the rim band does
        # (the auger tube passes higher over the rim, above the slab, and does not count)
        open_above = ~_has_neighbour(xy, _xy(x, y, slab), UNDER_RADIUS_M)
        # rows of (K, 2) arrays here and below by np.take / np.compress (the same rows): numpy's fancy
        # indexing of a 2-D array costs several times more per call at these sizes
        keep = np.flatnonzero(open_above)
        cand, xy = cand[keep], np.take(xy, keep, axis=0)
        if cand.size < MIN_RIM_POINTS:
            return _none(f"{cand.size} open points at rim height, need {MIN_RIM_POINTS}", int(cand.size))
    best = _best_group(xy, np.stack((x[above], y[above])), lo_len, lo_wid)
    if best is None:
        return _none("no rim-sized group of points at rim height", int(cand.size))
    g, ux = best
    pts = np.take(xy, g, axis=0)
    ux = _refine_direction(pts, ux)
    hx = np.asarray(heading_xy, dtype=np.float64)
    if abs(ux @ hx) < math.cos(math.radians(ACROSS_HEADING_DEG)) * math.sqrt(hx @ hx):
        # the seen piece is wider than long: a cart seen over less of its length than its width (a camera
        # over the spout); its long axis follows the towing direction, not the piece's long side
        ux = np.array([-ux[1], ux[0]])
    if ux @ hx < 0:
        ux = -ux
    uy = np.array([-ux[1], ux[0]])                              # left of forward
    s, t = pts @ ux, pts @ uy
    bd = border[cand[g]]
    centre = []
    partial = False
    # each coordinate's 0.5 and 99.5 percentiles once: an axis's span, and the other axis's for its ends
    axes = ((s, lo_len), (t, lo_wid))
    spans = [percentiles(coord, (0.5, 99.5)) for coord, _ in axes]
    for a, (coord, known) in enumerate(axes):
        lo, hi = spans[a]
        if hi - lo >= known - FULL_SPAN_TOL_M:
            centre.append(0.5 * (lo + hi))
            continue
        partial = True
        other, (o_lo, o_hi) = axes[1 - a][0], spans[1 - a]
        at_lo, at_hi = coord <= lo + END_STRIP_M, coord >= hi - END_STRIP_M
        cut_lo = _end_is_cut(bd[at_lo], other[at_lo], o_lo, o_hi)
        cut_hi = _end_is_cut(bd[at_hi], other[at_hi], o_lo, o_hi)
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
