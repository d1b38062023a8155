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
    inv(world_from_body(end))); None or an index beyond the list: the point is still in the world.

    Per body one transform takes a point from the camera at the end to the camera at the start,
    inv(camera_start) @ motion @ camera_end; each pixel takes its body's (12 coefficients gathered per pixel)."""
    inv_start = np.linalg.inv(world_from_camera_start)
    chain = [inv_start @ m @ world_from_camera_end for m in start_from_end] + [inv_start @ world_from_camera_end]
    table = np.array([t[:3, :4].ravel() for t in chain], np.float32)                  # (bodies + 1, 12)
    z = np.asarray(depth, np.float32)
    ok = np.isfinite(z) & (z > 0.0)
    z = np.where(ok, z, np.float32(1.0))
    h, w = z.shape
    f = np.float32(pin.f)
    u = np.arange(w, dtype=np.float32) + np.float32(0.5)
    v = np.arange(h, dtype=np.float32) + np.float32(0.5)
    x = (u[None, :] - np.float32(pin.width / 2.0)) * z / f                              # camera frame at the end
    y = (np.float32(pin.height / 2.0) - v[:, None]) * z / f
    static = len(chain) - 1
    if body is None:
        idx = np.full(z.shape, static, np.intp)
    else:
        b = np.asarray(body, np.intp)
        idx = np.where((b >= 0) & (b < static), b, static)
    c = table[idx]                                                                      # (H, W, 12)
    q = [c[..., 4 * r] * x + c[..., 4 * r + 1] * y + c[..., 4 * r + 2] * z + c[..., 4 * r + 3] for r in range(3)]
    moving = ok & (q[2] > np.float32(1e-6))
    qz = np.where(moving, q[2], np.float32(1.0))
    du = (u[None, :] - np.float32(pin.width / 2.0)) - f * q[0] / qz          # end minus start, px
    dv = (v[:, None] - np.float32(pin.height / 2.0)) + f * q[1] / qz
    d = np.stack([du, dv], axis=-1)
    d[~moving] = 0.0
    return d


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
