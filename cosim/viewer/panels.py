"""The dashboard's panels: which exist for a snapshot, their frame numbers, and their PNG renderings.

Image panels are drawn here (server side, cv2) and cached per frame; the auger chart and the fullness bars are
sent as numbers and drawn by the page. A panel whose blocks the run does not have is *absent* (with the reason),
never an error.

Frames of the drawings: the LiDAR block is in the sensor frame with camera axes (X right, Y up, Z forward); the
drawings turn it into the lidar frame the README and the recording name (x forward, y left, z up): "from above"
plots x (forward, up the picture) against y (left, to the left), "from the side" z (up) against x (forward, to
the right), one scale on both axes, metre ticks, colour = range with its scale. Height maps are drawn with cart
grid x (front wall to rear wall) to the right and y downwards, in metres when the cart's size is known, truth
and perceived on one colour scale with its bar, grey = no value (legend).
"""
from __future__ import annotations

import functools
import threading
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from .snapshot import Snapshot, auger_now, fullness

__all__ = ["PANELS", "IMAGE_PANELS", "panel_info", "PanelRenderer", "render_panel", "lidar_frame", "depth_colour"]

#: panel id -> title shown on the page
PANELS = {
    "rgb": "Shaded camera image",
    "depth": "Depth-encoded image",
    "cameras": "Camera sensors: colour | measured depth",
    "lidar_top": "LiDAR point cloud, from above",
    "lidar_side": "LiDAR point cloud, from the side",
    "heightmaps": "Height map: ground truth | perceived",
    "auger": "Auger location vs desired (cart grid x)",
    "fullness": "Fullness per section",
}
IMAGE_PANELS = ("rgb", "depth", "cameras", "lidar_top", "lidar_side", "heightmaps")
#: size of the LiDAR drawings, px, and their plot area (x0, y0, x1, y1): room for ticks, labels, colour bar
PLOT_W, PLOT_H = 560, 420
PLOT_BOX = (48, 30, PLOT_W - 80, PLOT_H - 44)
#: points the LiDAR drawings' extents (robust percentiles) are taken from, at most
EXTENT_SAMPLE = 4096
#: width of each height map drawing, px (its height follows the cart's aspect, at most MAP_MAX_H)
MAP_W, MAP_MAX_H = 560, 420
#: margins around the height maps (ticks and labels), px, and the width of the colour bar column
MAP_MARGIN_LEFT, MAP_MARGIN_TOP, MAP_MARGIN_BOTTOM, MAP_BAR_W = 50, 30, 46, 90
#: lowest top of the height maps' colour scale, m (an empty cart still gets a readable scale)
MAP_MIN_TOP_M = 0.1
MAP_CMAP = cv2.COLORMAP_VIRIDIS
#: largest camera panel drawing, px: camera images are shrunk to it (INTER_AREA) before PNG encoding, which
#: keeps the viewer's CPU time per refresh small; the browser shows them at panel width anyway
CAMERA_MAX_W, CAMERA_MAX_H = 880, 330
BACKGROUND = (24, 24, 28)
UNKNOWN = (90, 90, 90)
TEXT = (230, 230, 230)
AXIS = (150, 150, 150)
FONT = cv2.FONT_HERSHEY_SIMPLEX
FONT_SCALE = 0.42
#: pixel offsets of one drawn LiDAR point
POINT_PX = ((0, 0), (0, 1), (1, 0), (1, 1))


def _cams(snap: Snapshot, suffix: str) -> list[str]:
    return sorted(n for n in snap.names if n.endswith(suffix) and n not in snap.structs)


def _camera_sensors(snap: Snapshot) -> list[str]:
    """The camera sensors a snapshot knows of (``cam_<name>`` of their colour or measured-depth blocks)."""
    return sorted({n.rpartition("_")[0] for n in snap.names if n.startswith("cam_")
                   and n.endswith(("_rgb", "_measured")) and n not in snap.structs})


def _heightmaps(snap: Snapshot) -> tuple[str | None, str | None]:
    maps = [n for n in snap.names if n.startswith("heightmap")]
    truth = "heightmap_truth" if "heightmap_truth" in maps else None
    perc = "heightmap_perceived" if "heightmap_perceived" in maps else None
    return truth, perc


def panel_info(snap: Snapshot, stamps: bool = True) -> dict[str, dict]:
    """Panel id -> {available, frame, note} for ``snap`` (frame None: not written yet).

    ``stamps``: the frames the blocks have now (the page's refresh cue), else those of the copies held.
    """
    out: dict[str, dict] = {}

    def put(pid, blocks, note_absent):
        blocks = [b for b in blocks if b]
        if not blocks:
            out[pid] = {"available": False, "frame": None, "note": note_absent}
            return
        frames = [snap.block_frame(b, stamps) for b in blocks]
        frames = [f for f in frames if f is not None]
        out[pid] = {"available": True, "frame": max(frames) if frames else None,
                    "note": ", ".join(blocks)}

    put("rgb", _cams(snap, "_rgb"), "absent: this run renders no RGB image (start it with --viewer)")
    put("depth", [n for n in _cams(snap, "_depth") if not n.startswith("cam_")], "absent: this run has no renderer")
    put("cameras", [f"{c}_{part}" for c in _camera_sensors(snap) for part in ("rgb", "measured")
                    if f"{c}_{part}" in snap.names], "absent: this run has no camera sensor (sensors:)")
    lidar = ["lidar_points"] if "lidar_points" in snap.names else []
    put("lidar_top", lidar, "absent: this run has no perception (lidar_points)")
    put("lidar_side", lidar, "absent: this run has no perception (lidar_points)")
    put("heightmaps", list(_heightmaps(snap)), "absent: this run has no height map block")
    hit = auger_now(snap.structs)
    put("auger", [hit[0]] if hit else [], "absent: no desired_auger_x_m / actual_auger_x_m field")
    full = fullness(snap.structs)
    put("fullness", [full[0]] if full else [], "absent: no section<k>_fullness fields")
    return out


#: PNG settings of the panels: fastest deflate and the SUB row filter. libpng's default adaptive filtering tries
#: every filter on every row and cost ~3x the time (5.2 against 1.7 ms for an 880 x 330 camera panel, same size)
PNG_PARAMS = (cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB)


def _png(bgr: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", bgr, PNG_PARAMS)
    if not ok:
        raise ValueError(f"PNG encoding failed for shape {bgr.shape}")
    return buf.tobytes()


def depth_colour(depth: np.ndarray, top_m: float | None = None) -> np.ndarray:
    """(H, W, 3) RGB uint8 of a planar depth image (H, W) m: near red to far blue (turbo), 0 .. ``top_m`` (the
    image's largest depth when None), grey where invalid (NaN)."""
    z = np.asarray(depth, np.float32)
    ok = np.isfinite(z)
    top = top_m if top_m is not None else (float(z[ok].max()) if ok.any() else 1.0)
    level = np.zeros(z.shape, np.uint8)
    level[ok] = 255 - np.clip(z[ok] / max(top, 1e-6) * 255, 0, 255).astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(level, cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
    rgb[~ok] = UNKNOWN
    return rgb


def _camera_rows(snap: Snapshot) -> np.ndarray | None:
    """Each camera sensor a row: its colour image and its measured depth side by side, rows stacked (BGR)."""
    rows = []
    for cam in _camera_sensors(snap):
        parts = []
        if f"{cam}_rgb" in snap.images:
            parts.append(snap.images[f"{cam}_rgb"])
        if f"{cam}_measured" in snap.arrays:
            parts.append(depth_colour(snap.arrays[f"{cam}_measured"]))
        if parts:
            rows.append(_camera_strip(parts))
    if not rows:
        return None
    width = max(r.shape[1] for r in rows)
    rows = [cv2.copyMakeBorder(r, 0, 4, 0, width - r.shape[1], cv2.BORDER_CONSTANT, value=BACKGROUND) for r in rows]
    return cv2.vconcat(rows) if len(rows) > 1 else rows[0]


def _camera_strip(images: list[np.ndarray]) -> np.ndarray:
    """Images side by side, each (H, W, 3 or 4) RGB(A) uint8, at the first one's height, shrunk (INTER_AREA) to
    fit CAMERA_MAX_W x CAMERA_MAX_H; BGR out. Each image is resized first and converted after, so the colour
    conversion and the concatenation touch only the small images."""
    h0 = images[0].shape[0]
    widths = [im.shape[1] * h0 / im.shape[0] for im in images]
    s = min(1.0, CAMERA_MAX_W / sum(widths), CAMERA_MAX_H / h0)
    height = max(1, round(h0 * s))
    parts = []
    for im, w in zip(images, widths):
        size = (max(1, round(w * s)), height)
        if size != (im.shape[1], im.shape[0]):
            im = cv2.resize(im, size, interpolation=cv2.INTER_AREA if s < 1.0 else cv2.INTER_NEAREST)
        parts.append(cv2.cvtColor(im, cv2.COLOR_RGBA2BGR if im.shape[2] == 4 else cv2.COLOR_RGB2BGR))
    return cv2.hconcat(parts) if len(parts) > 1 else parts[0]


@functools.lru_cache(maxsize=8)
def _blank(h: int, w: int) -> np.ndarray:
    """A (h, w, 3) BACKGROUND image, kept: callers draw on a copy (40x cheaper than np.full with a colour)."""
    img = np.full((h, w, 3), BACKGROUND, np.uint8)
    img.setflags(write=False)
    return img


def _canvas(h: int, w: int) -> np.ndarray:
    """A fresh (h, w, 3) BGR image filled with BACKGROUND."""
    return _blank(h, w).copy()


def _nice_ticks(lo: float, hi: float, n: int = 5) -> np.ndarray:
    """About ``n`` round tick values (1, 2 or 5 x 10^k apart) within [lo, hi]."""
    span = max(hi - lo, 1e-9)
    raw = span / max(n, 1)
    mag = 10.0 ** np.floor(np.log10(raw))
    step = next(m * mag for m in (1, 2, 5, 10) if m * mag >= raw)
    first = np.ceil(lo / step - 1e-9) * step
    return np.arange(first, hi + step * 1e-6, step)


def _text(img, s: str, org: tuple[int, int], scale: float = FONT_SCALE, colour=TEXT) -> None:
    cv2.putText(img, s, (int(org[0]), int(org[1])), FONT, scale, colour, 1, cv2.LINE_AA)


def _axes(img, box, u_lim, v_lim, xlabel: str, ylabel: str, u_reversed: bool = False,
          v_down: bool = False) -> None:
    """Frame ``box`` (x0, y0, x1, y1 px) with metre ticks: u from u_lim[0] at the left to u_lim[1] at the right
    (reversed: at the right to the left), v from v_lim[0] at the bottom to v_lim[1] at the top (v_down: top to
    bottom); axis titles ``xlabel`` under it and ``ylabel`` above it."""
    x0, y0, x1, y1 = box
    cv2.rectangle(img, (x0, y0), (x1, y1), AXIS, 1)
    for t in _nice_ticks(*u_lim):
        f = (t - u_lim[0]) / (u_lim[1] - u_lim[0])
        x = round(x1 - f * (x1 - x0)) if u_reversed else round(x0 + f * (x1 - x0))
        cv2.line(img, (x, y1), (x, y1 + 4), AXIS, 1)
        _text(img, f"{t + 0.0:g}", (x - 8, y1 + 17))
    for t in _nice_ticks(*v_lim):
        f = (t - v_lim[0]) / (v_lim[1] - v_lim[0])
        y = round(y0 + f * (y1 - y0)) if v_down else round(y1 - f * (y1 - y0))
        cv2.line(img, (x0 - 4, y), (x0, y), AXIS, 1)
        _text(img, f"{t + 0.0:g}", (max(2, x0 - 38), y + 5))
    _text(img, xlabel, ((x0 + x1) // 2 - 4 * len(xlabel), y1 + 34))
    if ylabel:
        _text(img, ylabel, (4, y0 - 10))


def _colourbar(img, box, lo: float, hi: float, cmap: int, title: str) -> None:
    """Vertical colour scale in ``box`` (x0, y0, x1, y1) from ``lo`` (bottom) to ``hi`` (top), ticked."""
    x0, y0, x1, y1 = box
    ramp = np.linspace(255, 0, y1 - y0).astype(np.uint8).reshape(-1, 1)
    img[y0:y1, x0:x1] = cv2.applyColorMap(ramp, cmap).reshape(-1, 1, 3)
    cv2.rectangle(img, (x0, y0), (x1 - 1, y1 - 1), AXIS, 1)
    for t in _nice_ticks(lo, hi, 4):
        y = round(y1 - (t - lo) / max(hi - lo, 1e-9) * (y1 - y0))
        cv2.line(img, (x1, y), (x1 + 4, y), AXIS, 1)
        _text(img, f"{t + 0.0:g}", (x1 + 6, y + 5))
    _text(img, title, (x0 - 6, y0 - 8))


def _scatter(u: np.ndarray, v: np.ndarray, c: np.ndarray, xlabel: str, ylabel: str,
             u_reversed: bool = False) -> np.ndarray:
    """Points (u along the horizontal axis, right or with ``u_reversed`` left; v up; c range m) drawn into a
    PLOT_H x PLOT_W BGR image, one scale on both axes, metre ticks, a colour scale of the range."""
    img = _canvas(PLOT_H, PLOT_W)
    x0, y0, x1, y1 = PLOT_BOX
    if u.size == 0:
        _text(img, "no valid points", (PLOT_W // 3, PLOT_H // 2), 0.5)
        return img
    # plot extents from the 0.5 and 99.5 percentiles of at most EXTENT_SAMPLE evenly spaced points (every
    # point is drawn; the extents need no more)
    step = max(1, u.size // EXTENT_SAMPLE)
    lo_u, hi_u = np.percentile(u[::step], (0.5, 99.5))
    lo_v, hi_v = np.percentile(v[::step], (0.5, 99.5))
    w, h = x1 - x0, y1 - y0
    s = min(w / max(hi_u - lo_u, 1e-3), h / max(hi_v - lo_v, 1e-3)) * 0.94  # px per m, both axes
    cu, cv_ = (lo_u + hi_u) / 2, (lo_v + hi_v) / 2
    sign = -1.0 if u_reversed else 1.0
    px = np.round((x0 + x1) / 2 + sign * (u - cu) * s).astype(np.int64)
    py = np.round((y0 + y1) / 2 - (v - cv_) * s).astype(np.int64)
    ok = (px > x0) & (px < x1) & (py > y0) & (py < y1)
    c = c[ok]
    lo_c, hi_c = (float(np.min(c)), float(np.max(c))) if c.size else (0.0, 1.0)
    level = np.clip((c - lo_c) / max(hi_c - lo_c, 1e-6) * 255, 0, 255).astype(np.uint8)
    colours = cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_TURBO).reshape(-1, 3)
    for dy, dx in POINT_PX:  # each point a 2 x 2 px dot: one pixel is too faint to read
        img[py[ok] + dy, px[ok] + dx] = colours
    half_u, half_v = w / 2 / s, h / 2 / s
    _axes(img, PLOT_BOX, (cu - half_u, cu + half_u), (cv_ - half_v, cv_ + half_v), xlabel, ylabel, u_reversed)
    _colourbar(img, (x1 + 22, y0 + 18, x1 + 36, y1), lo_c, hi_c, cv2.COLORMAP_TURBO, "range m")
    _text(img, f"{u.size} points", (x1 - 90, y0 - 8))
    return img


def lidar_frame(points: np.ndarray) -> np.ndarray:
    """(N, 3) points of the LiDAR block (camera axes: X right, Y up, Z forward) in the lidar frame the README
    and the recording use: x forward, y left, z up."""
    p = np.asarray(points, dtype=np.float32)
    return np.stack([p[:, 2], -p[:, 0], p[:, 1]], axis=1)


def _lidar(points: np.ndarray, view: str) -> np.ndarray:
    p = np.asarray(points, dtype=np.float32).reshape(-1, points.shape[-1])
    p = p[np.isfinite(p[:, :3]).all(axis=1)]
    rng = p[:, 3] if p.shape[1] > 3 else np.linalg.norm(p[:, :3], axis=1)
    q = lidar_frame(p[:, :3])
    if view == "top":  # x forward up the picture, y left to the left (looking down from above)
        return _scatter(q[:, 1], q[:, 0], rng, "y left (m)", "x forward (m)", u_reversed=True)
    return _scatter(q[:, 0], q[:, 2], rng, "x forward (m)", "z up (m)")  # seen from the right side


def _map(img, origin: tuple[int, int], h: np.ndarray | None, vmax: float, label: str, size_m, px: tuple[int, int]):
    """Draw one height map (nx, ny) at ``origin`` (x, y px of its top left) as px (w, h) with metre axes."""
    x0, y0 = origin
    w, hpx = px
    box = (x0, y0, x0 + w, y0 + hpx)
    length, width = size_m if size_m else (float(h.shape[0]) if h is not None else 1.0,
                                           float(h.shape[1]) if h is not None else 1.0)
    unit = "m" if size_m else "cells"
    if h is None:
        _text(img, f"{label}: absent", (x0 + 20, y0 + hpx // 2), 0.5)
    else:
        t = np.asarray(h, dtype=np.float64).T  # rows: y (left wall at the top), columns: x (front wall left)
        known = np.isfinite(t)
        level = np.zeros(t.shape, np.uint8)
        level[known] = np.clip(t[known] / vmax * 255, 0, 255).astype(np.uint8)
        tile = cv2.applyColorMap(level, MAP_CMAP)
        tile[~known] = UNKNOWN
        img[y0:y0 + hpx, x0:x0 + w] = cv2.resize(tile, (w, hpx), interpolation=cv2.INTER_NEAREST)
        peak = f"{np.nanmax(t):.2f} m max" if known.any() else "no cell known"
        label = f"{label}: {peak}, {100 * known.mean():.0f} % of cells known"
    _axes(img, box, (0.0, length), (0.0, width), f"x from the front wall ({unit})", "", v_down=True)
    _text(img, label, (x0, y0 - 8), 0.5)
    _text(img, f"y ({unit})", (x0 - 46, y0 - 8))


def _heightmap_pair(snap: Snapshot, size_m: tuple[float, float] | None = None) -> np.ndarray:
    """Truth and perceived height maps side by side on one colour scale (0 .. the higher peak, at least
    MAP_MIN_TOP_M), metre axes (``size_m``: the cart interior's (length, width), m; cells when None), a colour
    bar and a legend for cells without a value (grey)."""
    truth, perc = _heightmaps(snap)
    ht = snap.arrays.get(truth) if truth else None
    hp = snap.arrays.get(perc) if perc else None
    peaks = [float(np.nanmax(a)) for a in (ht, hp) if a is not None and np.isfinite(a).any()]
    vmax = max(peaks + [MAP_MIN_TOP_M])
    ref = ht if ht is not None else hp
    aspect = (size_m[1] / size_m[0]) if size_m else ref.shape[1] / max(ref.shape[0], 1)
    w = MAP_W
    hpx = int(np.clip(round(w * aspect), 60, MAP_MAX_H))
    img = _canvas(hpx + MAP_MARGIN_TOP + MAP_MARGIN_BOTTOM, 2 * (w + MAP_MARGIN_LEFT) + MAP_BAR_W)
    for k, (arr, name) in enumerate(((ht, "ground truth"), (hp, "perceived"))):
        _map(img, (MAP_MARGIN_LEFT + k * (w + MAP_MARGIN_LEFT), MAP_MARGIN_TOP), arr, vmax, name, size_m, (w, hpx))
    bx = 2 * (w + MAP_MARGIN_LEFT) + 14
    _colourbar(img, (bx, MAP_MARGIN_TOP, bx + 16, MAP_MARGIN_TOP + hpx), 0.0, vmax, MAP_CMAP, "height m")
    ly = MAP_MARGIN_TOP + hpx + 22
    img[ly - 12:ly, bx:bx + 16] = UNKNOWN
    _text(img, "no value", (bx + 20, ly - 1))
    return img


def render_panel(snap: Snapshot, panel: str, size_m: tuple[float, float] | None = None) -> bytes | None:
    """PNG bytes of image panel ``panel`` for ``snap``, or None when the panel is absent. ``size_m``: the cart
    interior's (length, width), m, for the height maps' metre axes (cell indices when None)."""
    if panel not in IMAGE_PANELS:
        raise KeyError(f"no image panel {panel!r}; image panels: {IMAGE_PANELS}")
    if panel in ("rgb", "depth"):
        names = [n for n in _cams(snap, f"_{panel}") if n in snap.images]
        return _png(_camera_strip([snap.images[n] for n in names])) if names else None
    if panel == "cameras":
        img = _camera_rows(snap)
        return _png(img) if img is not None else None
    if panel in ("lidar_top", "lidar_side"):
        pts = snap.arrays.get("lidar_points")
        return _png(_lidar(pts, panel[len("lidar_"):])) if pts is not None else None
    if not any(n in snap.arrays for n in _heightmaps(snap)):
        return None
    return _png(_heightmap_pair(snap, size_m))


class PanelRenderer:
    """Renders image panels on demand and keeps the latest rendering of each (drawn once per frame).

    Every drawing is made in one long-lived thread, whichever request thread asks. The HTTP server answers
    each request in a new thread, and OpenCV sets up its text rendering once per thread: ``cv2.putText`` cost
    ~18 ms of CPU on a thread's first call against ~0.02 ms afterwards (OpenCV 5.0), so drawing in the request
    threads made a watched dashboard cost ~200 ms of CPU a second. One thread also draws one panel at a time,
    so a page's burst of requests never takes both cores from the run. Call :meth:`close` when done."""

    def __init__(self, size_m: tuple[float, float] | None = None) -> None:
        self.size_m = size_m
        self._cache: dict[str, tuple[tuple, bytes | None]] = {}
        self._lock = threading.Lock()
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="viewer-panels")
        self.rendered = 0

    def get(self, snap: Snapshot, panel: str) -> bytes | None:
        info = panel_info(snap, stamps=False).get(panel, {})
        key = (info.get("frame"), info.get("note"))
        with self._lock:
            hit = self._cache.get(panel)
            if hit is not None and hit[0] == key:
                return hit[1]
        png = self._pool.submit(render_panel, snap, panel, self.size_m).result()
        with self._lock:
            self._cache[panel] = (key, png)
            self.rendered += 1
        return png

    def close(self) -> None:
        """Stop the drawing thread (after the drawing under way, if any)."""
        self._pool.shutdown(wait=True, cancel_futures=True)
