"""Motion blur of a camera's image over its exposure (docs/cameras.md, "Motion blur").

During an exposure of T seconds each point the camera sees moves in the image by the camera's motion relative to
the body the point is on (the ground is still in the world; the cart, the tractor and the combine move as rigid
bodies). The pixel's value is the mean of what passes over it. The model is a per-pixel blur along each pixel's
own image-space displacement over the exposure:

* :func:`pixel_displacement`: the pixel's point (its planar depth, back-projected at the exposure's end) carried
  back to the exposure's start by its body's rigid motion and projected by the camera's pose at the start:
  ``d = p_end - p_start`` px (the exact image motion of that point under both rigid motions, rotation included);
* :func:`blur`: the pixel's value is the mean over the exposure of the end image at ``p + (1 - s) d``,
  s in [0, 1] (a locally uniform image motion), taken at the midpoints of ``K`` equal parts of the exposure by
  bilinear resampling; K is one more than the largest displacement in whole pixels (a sample at least every
  pixel of blur), at most :data:`MAX_SAMPLES`.

Why not K renders at sub-exposure poses: the GL draw is the renderer's most costly part (llvmpipe), the scene's
bodies and grain would have to be posed K times per image, and K renders cost K draws; this costs one read of the
view's depth and labels and K bilinear remaps of the image (1024 x 544 RGBA: about 4 ms a remap on one core).
Its limits: the gather uses each pixel's own displacement, so at an edge between two bodies moving differently
the nearer body's blur does not spread over the farther one, and the motion is uniform over the exposure (a few
milliseconds).
"""
from __future__ import annotations

import math
from typing import Sequence

import cv2
import numpy as np

from cosim.world.camera import Pinhole

__all__ = ["MAX_SAMPLES", "MIN_BLUR_PX", "pixel_displacement", "blur"]

#: the most samples along a pixel's displacement (a blur longer than this many px is sampled more sparsely)
MAX_SAMPLES = 16
#: below this largest displacement, px, the image is returned unchanged
MIN_BLUR_PX = 0.05


def pixel_displacement(depth: np.ndarray, pin: Pinhole, world_from_camera_end: np.ndarray,
                       world_from_camera_start: np.ndarray, body: np.ndarray | None = None,
                       start_from_end: Sequence[np.ndarray] = ()) -> np.ndarray:
    """(H, W, 2) float32 px: each pixel's image motion (u, v) over the exposure, end minus start.

    ``depth`` (H, W) planar depth m at the exposure's end (NaN: nothing, no motion); the camera's poses
    (4, 4, camera axes) at the exposure's end and start; ``body`` (H, W) int index into ``start_from_end``
    [(4, 4)], each body's world motion from the end back to the start (world_from_body(start) @
    inv(world_from_body(end))); None or an index beyond the list: the point is still in the world."""
    uu, vv = pin.pixel_centres()
    z = np.asarray(depth, np.float64)
    ok = np.isfinite(z) & (z > 0.0)
    p = pin.backproject(uu, vv, np.where(ok, z, 1.0))                      # (H, W, 3) camera frame at the end
    w = p @ world_from_camera_end[:3, :3].T + world_from_camera_end[:3, 3]
    if body is not None:
        for k, m in enumerate(start_from_end):
            sel = body == k
            if sel.any():
                w[sel] = w[sel] @ m[:3, :3].T + m[:3, 3]
    inv = np.linalg.inv(world_from_camera_start)
    q = w @ inv[:3, :3].T + inv[:3, 3]                                       # camera frame at the start
    q[..., 2] = np.where(q[..., 2] > 1e-6, q[..., 2], np.nan)
    d = np.stack([uu, vv], axis=-1) - pin.project(q)
    d[~ok | ~np.isfinite(d).all(axis=-1)] = 0.0
    return d.astype(np.float32)


def blur(image: np.ndarray, displacement: np.ndarray) -> np.ndarray:
    """The image (H, W, C) uint8 exposed while each pixel's content moved by ``displacement`` (H, W, 2) px
    (:func:`pixel_displacement`): the mean of the image at ``p + (1 - s) d`` over the midpoints s of K equal parts of [0, 1]
    (module docstring), uint8; the image itself (not a copy) when no pixel moves :data:`MIN_BLUR_PX`."""
    d = np.asarray(displacement, np.float32)
    longest = float(np.sqrt(np.max(np.sum(d * d, axis=-1)))) if d.size else 0.0
    if longest < MIN_BLUR_PX:
        return image
    k = min(MAX_SAMPLES, int(math.ceil(longest)) + 1)
    h, w = image.shape[:2]
    u = np.arange(w, dtype=np.float32)[None, :].repeat(h, axis=0)
    v = np.arange(h, dtype=np.float32)[:, None].repeat(w, axis=1)
    acc = np.zeros(image.shape, np.float32)
    for s in (np.arange(k) + 0.5) / k:                    # the midpoints of K equal parts of the exposure
        f = np.float32(1.0 - s)
        acc += cv2.remap(image, u + f * d[..., 0], v + f * d[..., 1], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE).astype(np.float32).reshape(image.shape)
    return np.clip(np.rint(acc / k), 0, 255).astype(np.uint8)
