"""A perception algorithm of our own that works from camera images: grain found by its colour, measured by depth.

Each camera that gives colour and depth (``inp.sensors[name].rgb`` and ``.depth_m``: an RGB-D depth camera, or
a stereo pair's left image and its disparity depth) votes: its pixels whose colour is grain's (corn is yellow:
much more red and green than blue, red at least as strong as green; the cart's red paint, the machines' green
and the stubble's grey-brown are not), away from the edge of the grain seen (``EDGE_PX``: there a depth
camera's pixels mix the grain with the wall in front of it), are back-projected with the camera's ``K`` and
depth into the level frame (``level_from_camera``). The cart comes from the built-in rim stage on every sensor's points (``inp.points``);
each controller cell's height is the median height of the grain pixels over it; the impact comes from the
built-in impact stage.

Protocol (graincosim ``perception.algorithm``, perception_proc.protocol):
``(ctx: PerceptionContext, inp: PerceptionInput) -> PerceptionOutput``. Image arrays: ``rgb`` (H, W, 3) uint8,
``depth_m`` (H, W) float32 planar depth m (NaN invalid); camera frame X right, Y up, Z forward; pixel (i, j) has
its centre at (u, v) = (i + 0.5, j + 0.5), back-projected as Z K^-1 (u, v, 1) with the image's v axis down
(docs/cameras.md).
"""
from __future__ import annotations

import cv2
import numpy as np

from perception_proc.estimates.heightmap import HeightMap
from perception_proc.protocol import PerceptionContext, PerceptionInput, PerceptionOutput

__all__ = ["grain_pixels", "grain_mask", "BLUE_OVER_GREEN_MAX", "RED_OVER_GREEN_MIN", "MIN_GREEN"]

#: grain's blue is well under its green (corn about 0.25-0.35; stubble and soil about 0.6)
BLUE_OVER_GREEN_MAX = 0.45
#: and its red at least as strong as its green (the machines' green paint has far less red)
RED_OVER_GREEN_MIN = 0.95
#: too dark to judge below this green byte (shadow, night)
MIN_GREEN = 20
#: pixels this close to the edge of the grain seen are left out (mixed depths at the wall in front), px
EDGE_PX = 2


def grain_mask(rgb: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels of an (H, W, 3) uint8 image whose colour is grain's."""
    c = rgb.astype(np.int32)
    r, g, b = c[..., 0], c[..., 1], c[..., 2]
    return (g >= MIN_GREEN) & (b * 100 <= BLUE_OVER_GREEN_MAX * 100 * g) & (r * 100 >= RED_OVER_GREEN_MIN * 100 * g)


def _grain_points(inp: PerceptionInput) -> np.ndarray:
    """(N, 3) level-frame points of every camera's grain-coloured pixels with a valid depth."""
    out = [np.zeros((0, 3))]
    for frame in inp.sensors.values():
        if frame.rgb is None or frame.depth_m is None:
            continue
        h, w = frame.depth_m.shape
        core = cv2.erode(grain_mask(frame.rgb).view(np.uint8), np.ones((2 * EDGE_PX + 1,) * 2, np.uint8)) > 0
        keep = core & np.isfinite(frame.depth_m)
        v, u = np.nonzero(keep)
        z = frame.depth_m[v, u].astype(np.float64)
        k = frame.K
        cam = np.stack([(u + 0.5 - k[0, 2]) / k[0, 0] * z, (k[1, 2] - v - 0.5) / k[1, 1] * z, z], axis=1)
        lfc = frame.level_from_camera
        out.append(cam @ lfc[:3, :3].T + lfc[:3, 3])
    return np.concatenate(out)


def grain_pixels(ctx: PerceptionContext, inp: PerceptionInput) -> PerceptionOutput:
    """Cart from the built-in rim stage; heights from grain-coloured pixels; impact from the built-in stage."""
    cart = ctx.stages.rim(ctx, inp)
    from perception_proc.estimates.impact import Impact

    if not cart.valid:
        return PerceptionOutput(cart, None, Impact(False, np.full(3, np.nan), 0, "no cart"))
    c = ctx.scenario.cart
    nx, ny = ctx.grid
    lfg = cart.level_from_grid
    g = (_grain_points(inp) - lfg[:3, 3]) @ lfg[:3, :3]                       # level -> cart grid frame
    inside = (g[:, 0] > 0) & (g[:, 0] < c.interior_length_m) & (g[:, 1] > 0) & (g[:, 1] < c.interior_width_m)
    g = g[inside]
    i = np.minimum((g[:, 0] / ctx.cell_xy[0]).astype(np.int64), nx - 1)
    j = np.minimum((g[:, 1] / ctx.cell_xy[1]).astype(np.int64), ny - 1)
    heights = np.full((nx, ny), np.nan, np.float32)
    counts = np.zeros((nx, ny), np.int32)
    cell = i * ny + j
    order = np.lexsort((g[:, 2], cell))
    cs, zs = cell[order], g[order, 2]
    if cs.size:
        start = np.flatnonzero(np.concatenate(([True], cs[1:] != cs[:-1])))
        cnt = np.diff(np.append(start, cs.size))
        heights.reshape(-1)[cs[start]] = 0.5 * (zs[start + (cnt - 1) // 2] + zs[start + cnt // 2])
        counts.reshape(-1)[cs[start]] = cnt
    hm = HeightMap(heights, counts, np.asfortranarray(g), np.zeros(len(g), bool),
                   float(np.count_nonzero(np.isfinite(heights)) / heights.size))
    impact = ctx.stages.impact(ctx, inp, cart, hm)
    return PerceptionOutput(cart, hm, impact)
