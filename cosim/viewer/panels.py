"""The dashboard's panels: which exist for a snapshot, their frame numbers, and their PNG renderings.

Image panels are drawn here (server side, cv2) and cached per frame; the auger chart and the fullness bars are
sent as numbers and drawn by the page. A panel whose blocks the run does not have is *absent* (with the reason),
never an error.

Frames of the drawings: the LiDAR block is in the sensor frame with camera axes (X right, Y up, Z forward);
"from above" plots Z (forward, up the picture) against X (right), "from the side" plots Y (up) against Z
(forward, to the right); colour is range. Height maps are drawn with cart grid x (front wall to rear wall) to
the right and y (left wall to right wall) downwards, truth and perceived on one colour scale, grey = unknown.
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from .snapshot import Snapshot, auger_now, fullness

__all__ = ["PANELS", "IMAGE_PANELS", "panel_info", "PanelRenderer", "render_panel"]

#: panel id -> title shown on the page
PANELS = {
    "rgb": "Shaded camera image",
    "depth": "Depth-encoded image",
    "lidar_top": "LiDAR point cloud, from above",
    "lidar_side": "LiDAR point cloud, from the side",
    "heightmaps": "Height map: ground truth | perceived",
    "auger": "Auger location vs desired (cart grid x)",
    "fullness": "Fullness per section",
}
IMAGE_PANELS = ("rgb", "depth", "lidar_top", "lidar_side", "heightmaps")
#: size of the LiDAR drawings, px
PLOT_W, PLOT_H = 420, 300
PLOT_MARGIN = 28
#: points the LiDAR drawings' extents (robust percentiles) are taken from, at most
EXTENT_SAMPLE = 4096
#: height of each height map drawing, px
MAP_H = 220
#: largest camera panel drawing, px: camera images are shrunk to it (INTER_AREA) before PNG encoding, which
#: keeps the viewer's CPU time per refresh small; the browser shows them at panel width anyway
CAMERA_MAX_W, CAMERA_MAX_H = 880, 330
BACKGROUND = (24, 24, 28)
UNKNOWN = (90, 90, 90)
TEXT = (230, 230, 230)


def _cams(snap: Snapshot, suffix: str) -> list[str]:
    return sorted(n for n in snap.names if n.endswith(suffix) and n not in snap.structs)


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
    put("depth", _cams(snap, "_depth"), "absent: this run has no renderer")
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


def _scatter(u: np.ndarray, v: np.ndarray, c: np.ndarray, xlabel: str, ylabel: str) -> np.ndarray:
    """Points (u right, v up, c colour value) drawn into a PLOT_H x PLOT_W BGR image with extents labelled."""
    img = np.full((PLOT_H, PLOT_W, 3), BACKGROUND, np.uint8)
    if u.size == 0:
        cv2.putText(img, "no valid points", (PLOT_W // 3, PLOT_H // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.5, TEXT, 1)
        return img
    # plot extents from the 0.5 and 99.5 percentiles of at most EXTENT_SAMPLE evenly spaced points (every
    # point is drawn; the extents need no more)
    step = max(1, u.size // EXTENT_SAMPLE)
    lo_u, hi_u = np.percentile(u[::step], (0.5, 99.5))
    lo_v, hi_v = np.percentile(v[::step], (0.5, 99.5))
    span = max(hi_u - lo_u, hi_v - lo_v, 1e-3)  # one scale on both axes: no distortion
    cu, cv_ = (lo_u + hi_u) / 2, (lo_v + hi_v) / 2
    inner_w, inner_h = PLOT_W - 2 * PLOT_MARGIN, PLOT_H - 2 * PLOT_MARGIN
    s = min(inner_w, inner_h) / span
    px = np.round(PLOT_W / 2 + (u - cu) * s).astype(np.int64)
    py = np.round(PLOT_H / 2 - (v - cv_) * s).astype(np.int64)
    ok = (px >= 0) & (px < PLOT_W) & (py >= 0) & (py < PLOT_H)
    c = c[ok]
    lo_c, hi_c = (float(np.min(c)), float(np.max(c))) if c.size else (0.0, 1.0)
    level = np.clip((c - lo_c) / max(hi_c - lo_c, 1e-6) * 255, 0, 255).astype(np.uint8)
    colours = cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_TURBO).reshape(-1, 3)
    img[py[ok], px[ok]] = colours
    half_w, half_h = PLOT_W / 2 / s, PLOT_H / 2 / s
    font = cv2.FONT_HERSHEY_SIMPLEX
    cv2.putText(img, f"{xlabel} {cu - half_w:.1f}..{cu + half_w:.1f} m", (6, PLOT_H - 8), font, 0.42, TEXT, 1)
    cv2.putText(img, f"{ylabel} {cv_ - half_h:.1f}..{cv_ + half_h:.1f} m", (6, 16), font, 0.42, TEXT, 1)
    cv2.putText(img, f"range {lo_c:.1f}..{hi_c:.1f} m, {u.size} pts", (PLOT_W - 220, 16), font, 0.42, TEXT, 1)
    return img


def _lidar(points: np.ndarray, view: str) -> np.ndarray:
    p = np.asarray(points, dtype=np.float32).reshape(-1, points.shape[-1])
    p = p[np.isfinite(p[:, :3]).all(axis=1)]
    rng = p[:, 3] if p.shape[1] > 3 else np.linalg.norm(p[:, :3], axis=1)
    if view == "top":
        return _scatter(p[:, 0], p[:, 2], rng, "X right", "Z forward")
    return _scatter(p[:, 2], p[:, 1], rng, "Z forward", "Y up")


def _map(h: np.ndarray | None, vmax: float, label: str) -> np.ndarray:
    if h is None:
        img = np.full((MAP_H, MAP_H, 3), BACKGROUND, np.uint8)
        cv2.putText(img, f"{label}: absent", (8, MAP_H // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.5, TEXT, 1)
        return img
    t = np.asarray(h, dtype=np.float64).T  # rows: y, columns: x
    known = np.isfinite(t)
    level = np.zeros(t.shape, np.uint8)
    level[known] = np.clip(t[known] / vmax * 255, 0, 255).astype(np.uint8)
    img = cv2.applyColorMap(level, cv2.COLORMAP_VIRIDIS)
    img[~known] = UNKNOWN
    w = max(1, round(t.shape[1] * MAP_H / max(t.shape[0], 1)))
    img = cv2.resize(img, (w, MAP_H), interpolation=cv2.INTER_NEAREST)
    cv2.putText(img, f"{label} {np.nanmax(t) if known.any() else float('nan'):.2f} m max", (6, 16),
                cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1)
    return img


def _heightmap_pair(snap: Snapshot) -> np.ndarray:
    truth, perc = _heightmaps(snap)
    ht = snap.arrays.get(truth) if truth else None
    hp = snap.arrays.get(perc) if perc else None
    peaks = [float(np.nanmax(a)) for a in (ht, hp) if a is not None and np.isfinite(a).any()]
    vmax = max(peaks + [0.1])
    left, right = _map(ht, vmax, "truth"), _map(hp, vmax, "perceived")
    gap = np.full((MAP_H, 8, 3), BACKGROUND, np.uint8)
    bar = cv2.applyColorMap(np.linspace(255, 0, MAP_H).astype(np.uint8).reshape(-1, 1), cv2.COLORMAP_VIRIDIS)
    bar = cv2.resize(bar, (14, MAP_H), interpolation=cv2.INTER_NEAREST)
    scale = np.full((MAP_H, 60, 3), BACKGROUND, np.uint8)
    cv2.putText(scale, f"{vmax:.2f} m", (2, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, TEXT, 1)
    cv2.putText(scale, "0 m", (2, MAP_H - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, TEXT, 1)
    return cv2.hconcat([left, gap, right, gap, bar, scale])


def render_panel(snap: Snapshot, panel: str) -> bytes | None:
    """PNG bytes of image panel ``panel`` for ``snap``, or None when the panel is absent."""
    if panel not in IMAGE_PANELS:
        raise KeyError(f"no image panel {panel!r}; image panels: {IMAGE_PANELS}")
    if panel in ("rgb", "depth"):
        names = [n for n in _cams(snap, f"_{panel}") if n in snap.images]
        return _png(_camera_strip([snap.images[n] for n in names])) if names else None
    if panel in ("lidar_top", "lidar_side"):
        pts = snap.arrays.get("lidar_points")
        return _png(_lidar(pts, panel[len("lidar_"):])) if pts is not None else None
    if not any(n in snap.arrays for n in _heightmaps(snap)):
        return None
    return _png(_heightmap_pair(snap))


class PanelRenderer:
    """Renders image panels on demand and keeps the latest rendering of each (drawn once per frame).

    Every drawing is made in one long-lived thread, whichever request thread asks. The HTTP server answers
    each request in a new thread, and OpenCV sets up its text rendering once per thread: ``cv2.putText`` cost
    ~18 ms of CPU on a thread's first call against ~0.02 ms afterwards (OpenCV 5.0), so drawing in the request
    threads made a watched dashboard cost ~200 ms of CPU a second. One thread also draws one panel at a time,
    so a page's burst of requests never takes both cores from the run. Call :meth:`close` when done."""

    def __init__(self) -> None:
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
        png = self._pool.submit(render_panel, snap, panel).result()
        with self._lock:
            self._cache[panel] = (key, png)
            self.rendered += 1
        return png

    def close(self) -> None:
        """Stop the drawing thread (after the drawing under way, if any)."""
        self._pool.shutdown(wait=True, cancel_futures=True)
