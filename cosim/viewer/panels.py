"""The dashboard's panels: which exist for a snapshot, their frame numbers, and their PNG renderings.

Image panels are drawn here (server side, cv2) and cached per frame; the auger chart and the fullness bars are
sent as numbers and drawn by the page. A panel whose blocks the run does not have is *absent* (with the reason),
never an error.

Frames of the drawings (docs/viewer.md): the point clouds (every depth-giving sensor's, cosim.viewer.clouds) and
the height maps are in the cart grid frame, x from the front wall to the right, seen from above: the height maps
with y (from the left wall) up, metres when the cart's size is known, truth and perceived on one colour scale
with its bar, grey = no value (legend). Without the run's scenario the point clouds fall back to one sensor's
own frame.
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from .clouds import cart_view, clouds_in_cart, sensor_frame_view
from .draw import BACKGROUND, UNKNOWN, axes, canvas, colour_lut, colourbar, png, text
from .snapshot import Snapshot, auger_now, fullness
from .viewinfo import LIDAR_POINTS, ViewInfo

__all__ = ["PANELS", "IMAGE_PANELS", "panel_info", "PanelRenderer", "render_panel", "depth_colour", "point_blocks"]

#: panel id -> title shown on the page
PANELS = {
    "rgb": "Shaded camera image",
    "depth": "Depth-encoded image",
    "cameras": "Camera sensors: colour | measured depth",
    "lidar_top": "Point clouds from above (cart frame)",
    "lidar_side": "Point clouds from the cart's left (cart frame)",
    "heightmaps": "Height map from above: ground truth | perceived",
    "auger": "Auger location vs desired (cart grid x)",
    "fullness": "Fullness per section",
}
IMAGE_PANELS = ("rgb", "depth", "cameras", "lidar_top", "lidar_side", "heightmaps")
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


def _cams(snap: Snapshot, suffix: str) -> list[str]:
    return sorted(n for n in snap.names if n.endswith(suffix) and n not in snap.structs)


def _camera_sensors(snap: Snapshot) -> list[str]:
    """The camera sensors a snapshot knows of (``cam_<name>`` of their colour or measured-depth blocks)."""
    return sorted({n.rpartition("_")[0] for n in snap.names if n.startswith("cam_")
                   and n.endswith(("_rgb", "_measured")) and n not in snap.structs})


def point_blocks(snap: Snapshot) -> list[str]:
    """The point blocks of the depth-giving sensors a snapshot knows of: ``lidar_points`` and each camera's
    ``cam_<name>_points``."""
    return sorted(n for n in snap.names if n == LIDAR_POINTS or (n.startswith("cam_") and n.endswith("_points")
                                                                  and n not in snap.structs))


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
    points = point_blocks(snap)
    why = "absent: this run has no depth-giving sensor's points (lidar_points, cam_<name>_points)"
    put("lidar_top", points, why)
    put("lidar_side", points, why)
    put("heightmaps", list(_heightmaps(snap)), "absent: this run has no height map block")
    hit = auger_now(snap.structs)
    put("auger", [hit[0]] if hit else [], "absent: no desired_auger_x_m / actual_auger_x_m field")
    full = fullness(snap.structs)
    put("fullness", [full[0]] if full else [], "absent: no section<k>_fullness fields")
    return out


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




def _map(img, origin: tuple[int, int], h: np.ndarray | None, vmax: float, label: str, size_m, px: tuple[int, int]):
    """Draw one height map (nx, ny) at ``origin`` (x, y px of its top left) as px (w, h) with metre axes, seen
    from above: x (front wall) to the right, y (left wall) up."""
    x0, y0 = origin
    w, hpx = px
    box = (x0, y0, x0 + w, y0 + hpx)
    length, width = size_m if size_m else (float(h.shape[0]) if h is not None else 1.0,
                                           float(h.shape[1]) if h is not None else 1.0)
    unit = "m" if size_m else "cells"
    if h is None:
        text(img, f"{label}: absent", (x0 + 20, y0 + hpx // 2), 0.5)
    else:
        t = np.asarray(h, dtype=np.float64).T[::-1]  # rows: y (right wall at the top), columns: x (front left)
        known = np.isfinite(t)
        level = np.zeros(t.shape, np.uint8)
        level[known] = np.clip(t[known] / vmax * 255, 0, 255).astype(np.uint8)
        tile = cv2.applyColorMap(level, MAP_CMAP)
        tile[~known] = UNKNOWN
        img[y0:y0 + hpx, x0:x0 + w] = cv2.resize(tile, (w, hpx), interpolation=cv2.INTER_NEAREST)
        peak = f"{np.nanmax(t):.2f} m max" if known.any() else "no cell known"
        label = f"{label}: {peak}, {100 * known.mean():.0f} % of cells known"
    axes(img, box, (0.0, length), (0.0, width), f"x from the front wall ({unit})", "")
    text(img, label, (x0, y0 - 8), 0.5)
    text(img, f"y ({unit})", (x0 - 46, y0 - 8))


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
    img = canvas(hpx + MAP_MARGIN_TOP + MAP_MARGIN_BOTTOM, 2 * (w + MAP_MARGIN_LEFT) + MAP_BAR_W)
    for k, (arr, name) in enumerate(((ht, "ground truth"), (hp, "perceived"))):
        _map(img, (MAP_MARGIN_LEFT + k * (w + MAP_MARGIN_LEFT), MAP_MARGIN_TOP), arr, vmax, name, size_m, (w, hpx))
    bx = 2 * (w + MAP_MARGIN_LEFT) + 14
    colourbar(img, (bx, MAP_MARGIN_TOP, bx + 16, MAP_MARGIN_TOP + hpx), 0.0, vmax, colour_lut(MAP_CMAP), "height m")
    ly = MAP_MARGIN_TOP + hpx + 22
    img[ly - 12:ly, bx:bx + 16] = UNKNOWN
    text(img, "no value", (bx + 20, ly - 1))
    return img


def _cloud_panel(snap: Snapshot, which: str, view: ViewInfo | None) -> np.ndarray | None:
    """The point-cloud drawing ``which`` ("top" or "side"): every sensor's points in the cart frame when the
    view and the machines' poses are known, else one sensor's points (the LiDAR's, else the first camera's) in
    its own frame; None without points."""
    if view is not None:
        clouds = clouds_in_cart(view, snap.structs, snap.arrays)
        if clouds:
            full = fullness(snap.structs)
            return cart_view(view, clouds, which, len(full[1]) if full else 0)
        why = "the machines' poses are unknown"
    else:
        why = "the cart's geometry is unknown"
    block = next((b for b in sorted(point_blocks(snap), key=lambda b: b != LIDAR_POINTS) if b in snap.arrays), None)
    return sensor_frame_view(snap.arrays[block], which, why, block) if block is not None else None


def render_panel(snap: Snapshot, panel: str, size_m: tuple[float, float] | None = None,
                 view: ViewInfo | None = None) -> bytes | None:
    """PNG bytes of image panel ``panel`` for ``snap``, or None when the panel is absent. ``size_m``: the cart
    interior's (length, width), m, for the height maps' metre axes (``view``'s when None; cell indices without
    either); ``view``: the run's cart, sensors and fill target (the point clouds' cart frame)."""
    if panel not in IMAGE_PANELS:
        raise KeyError(f"no image panel {panel!r}; image panels: {IMAGE_PANELS}")
    if panel in ("rgb", "depth"):
        names = [n for n in _cams(snap, f"_{panel}") if n in snap.images]
        return png(_camera_strip([snap.images[n] for n in names])) if names else None
    if panel == "cameras":
        img = _camera_rows(snap)
        return png(img) if img is not None else None
    if panel in ("lidar_top", "lidar_side"):
        img = _cloud_panel(snap, panel[len("lidar_"):], view)
        return png(img) if img is not None else None
    if not any(n in snap.arrays for n in _heightmaps(snap)):
        return None
    return png(_heightmap_pair(snap, size_m or (view.size_m if view is not None else None)))


class PanelRenderer:
    """Renders image panels on demand and keeps the latest rendering of each (drawn once per frame).

    Every drawing is made in one long-lived thread, whichever request thread asks. The HTTP server answers
    each request in a new thread, and OpenCV sets up its text rendering once per thread: ``cv2.putText`` cost
    ~18 ms of CPU on a thread's first call against ~0.02 ms afterwards (OpenCV 5.0), so drawing in the request
    threads made a watched dashboard cost ~200 ms of CPU a second. One thread also draws one panel at a time,
    so a page's burst of requests never takes both cores from the run. Call :meth:`close` when done."""

    def __init__(self, size_m: tuple[float, float] | None = None, view: ViewInfo | None = None) -> None:
        self.size_m, self.view = size_m, view
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
        png_bytes = self._pool.submit(render_panel, snap, panel, self.size_m, self.view).result()
        with self._lock:
            self._cache[panel] = (key, png_bytes)
            self.rendered += 1
        return png_bytes

    def close(self) -> None:
        """Stop the drawing thread (after the drawing under way, if any)."""
        self._pool.shutdown(wait=True, cancel_futures=True)
