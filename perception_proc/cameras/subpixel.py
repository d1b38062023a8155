"""The stereo matcher's disparity made honest (docs/cameras.md): gross errors come back invalid, sub-pixel values
do not lock to whole pixels.

Two pure functions on the rectified grey pair and the matcher's disparity:

* :func:`texture_mask`: where the left image has no texture to match. The mean absolute horizontal intensity
  gradient over the matcher's block (grey levels per px, the 3 x 3 Sobel derivative divided by its weight 8) is
  below ``threshold``: StereoBM's ``textureThreshold`` check, which StereoSGBM lacks. Without it SGBM's smoothness
  term fills a textureless region (a surface so far or so oblique that its texture fades below the pixel) with the
  disparity of its surroundings, and those pixels pass its uniqueness and left-right checks: on a wall seen
  obliquely beyond 10 m they are the large majority of the "valid" pixels.
* :func:`refine_disparity`: sub-pixel refinement by Gauss-Newton on the intensity difference (the Lucas-Kanade
  step restricted to the epipolar line): with the right image warped by the current disparity, each iteration
  adds -sum(e g) / sum(g^2) over a square window, e = L(x) - R(x - d) and g = dR/dx at x - d (linear
  interpolation). OpenCV's matchers fit a parabola to three integer costs, which pulls a disparity towards the
  nearest whole pixel (pixel locking: on a facing plane the error swings with the fractional disparity between
  about -0.4 and +0.45 px); the continuous step has no preferred fraction. A pixel whose step leaves
  ``max_step_px`` of the matcher's disparity, or whose window has no gradient, is invalid.
  :func:`refine_disparity_reference` is its readable form; :func:`refine_disparity` gives the same bits with its
  pixel grid made once per image size, its products in reused buffers and each pass made once
  (:func:`refine_steps`, which the camera's fused depth path calls on its own; tests/test_stereo_kernels.py).
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

__all__ = ["ITERATIONS", "MAX_STEP_PX", "SOBEL_WEIGHT", "texture_mask", "refine_disparity",
           "refine_disparity_reference", "refine_steps", "step_too_large", "fill_where"]

#: the 3 x 3 Sobel x derivative of a unit ramp (1 grey level per px): its response is 8
SOBEL_WEIGHT = 8.0
#: a window's summed squared gradient below this, (grey levels / px)^2, gives no step (no texture to align)
MIN_GRADIENT_ENERGY = 1e-3
#: Gauss-Newton iterations of the refinement
ITERATIONS = 2
#: a refined disparity further than this from the matcher's is invalid, px
MAX_STEP_PX = 1.0


def texture_mask(left: np.ndarray, block_px: int, threshold: float) -> np.ndarray:
    """(H, W) bool: True where the left grey image ``left`` (H, W) uint8 has less than ``threshold`` grey levels
    per px of mean absolute horizontal gradient over a ``block_px`` square window (no texture to match)."""
    gx = cv2.Sobel(left, cv2.CV_32F, 1, 0, ksize=3, scale=1.0 / SOBEL_WEIGHT)
    energy = cv2.boxFilter(np.abs(gx, out=gx), -1, (block_px, block_px), borderType=cv2.BORDER_REPLICATE)
    return energy < np.float32(threshold)


def refine_disparity_reference(left: np.ndarray, right: np.ndarray, disparity: np.ndarray, window_px: int = 5,
                               iterations: int = ITERATIONS, max_step_px: float = MAX_STEP_PX) -> np.ndarray:
    """Sub-pixel refined disparity (H, W) float32 px of ``disparity`` (H, W) float32 px, NaN invalid, for the
    rectified grey pair ``left``, ``right`` (H, W) uint8 (a point at disparity d in the left image is d px
    further left in the right image): ``iterations`` Gauss-Newton steps over a ``window_px`` square window; NaN
    where the input is NaN, the window has no gradient or the result is more than ``max_step_px`` from the
    input. The readable form of :func:`refine_disparity`, which gives the same bits."""
    lft = left.astype(np.float32)
    rgt = right.astype(np.float32)
    h, w = lft.shape
    grad = cv2.Sobel(rgt, cv2.CV_32F, 1, 0, ksize=3, scale=1.0 / SOBEL_WEIGHT)
    cols = np.broadcast_to(np.arange(w, dtype=np.float32), (h, w))
    rows = np.ascontiguousarray(np.broadcast_to(np.arange(h, dtype=np.float32)[:, None], (h, w)))
    start = np.where(np.isfinite(disparity), disparity, 0.0).astype(np.float32)
    d = start.copy()
    flat = np.zeros((h, w), bool)
    win = (window_px, window_px)
    for _ in range(iterations):
        map_x = cols - d
        warped = cv2.remap(rgt, map_x, rows, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        g = cv2.remap(grad, map_x, rows, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        num = cv2.boxFilter((lft - warped) * g, -1, win, normalize=False, borderType=cv2.BORDER_REPLICATE)
        den = cv2.boxFilter(g * g, -1, win, normalize=False, borderType=cv2.BORDER_REPLICATE)
        flat = den < MIN_GRADIENT_ENERGY
        d -= np.where(flat, np.float32(0.0), num / np.maximum(den, np.float32(MIN_GRADIENT_ENERGY)))
    d[~np.isfinite(disparity) | flat | (np.abs(d - start) > max_step_px)] = np.nan
    return d


@lru_cache(maxsize=4)
def _pixel_grid(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """(column index, row index), each (H, W) float32 C-contiguous and read-only, of an H x W image: the x offset
    and the y map of the warp."""
    cols = np.ascontiguousarray(np.broadcast_to(np.arange(w, dtype=np.float32), (h, w)))
    rows = np.ascontiguousarray(np.broadcast_to(np.arange(h, dtype=np.float32)[:, None], (h, w)))
    cols.setflags(write=False)
    rows.setflags(write=False)
    return cols, rows


@lru_cache(maxsize=8)
def _plane(h: int, w: int, value: float) -> np.ndarray:
    """(H, W) float32 filled with ``value``, read-only: the source of :func:`fill_where`."""
    out = np.full((h, w), value, np.float32)
    out.setflags(write=False)
    return out


def fill_where(a: np.ndarray, mask: np.ndarray, value: float) -> None:
    """``a[mask] = value`` for ``a`` (H, W) float32 and ``mask`` (H, W) bool, in place, by OpenCV's masked copy
    (numpy's masked assignment costs several times more)."""
    cv2.copyTo(_plane(*a.shape, value), mask.view(np.uint8), a)


def refine_steps(left: np.ndarray, right: np.ndarray, start: np.ndarray, window_px: int = 5,
                 iterations: int = ITERATIONS) -> tuple[np.ndarray, np.ndarray]:
    """The Gauss-Newton iterations of :func:`refine_disparity_reference` from ``start`` (H, W) float32 px, finite
    (0 where the matcher gave nothing), for the grey pair ``left``, ``right`` (H, W) uint8: (the iterate (H, W)
    float32 px, nothing made invalid yet; flat (H, W) bool, the last iteration's windows without gradient).

    The same bits as the reference: the pixel grid is made once per image size, each iteration's products go to
    reused buffers, and the element-wise arithmetic is OpenCV's (IEEE float32 subtract, multiply, divide and
    max, as numpy's, at a fraction of numpy's cost here). A flat window's pixel keeps its disparity (the
    reference subtracts a step of +0, which leaves every finite value as it is); the gradient energy is never
    NaN (finite images, maps and steps), so OpenCV's max, which differs from numpy's only on NaN, gives the
    reference's floor."""
    lft = left.astype(np.float32)
    rgt = right.astype(np.float32)
    h, w = lft.shape
    grad = cv2.Sobel(rgt, cv2.CV_32F, 1, 0, ksize=3, scale=1.0 / SOBEL_WEIGHT)
    cols, rows = _pixel_grid(h, w)
    d, moved = start.copy(), np.empty((h, w), np.float32)
    flat = np.zeros((h, w), bool)
    win = (window_px, window_px)
    map_x, warped, g, prod, num, den = (np.empty((h, w), np.float32) for _ in range(6))
    floor = np.float32(MIN_GRADIENT_ENERGY)
    for _ in range(iterations):
        cv2.subtract(cols, d, dst=map_x)
        cv2.remap(rgt, map_x, rows, cv2.INTER_LINEAR, dst=warped, borderMode=cv2.BORDER_REPLICATE)
        cv2.remap(grad, map_x, rows, cv2.INTER_LINEAR, dst=g, borderMode=cv2.BORDER_REPLICATE)
        cv2.subtract(lft, warped, dst=prod)
        cv2.multiply(prod, g, dst=prod)
        cv2.boxFilter(prod, -1, win, dst=num, normalize=False, borderType=cv2.BORDER_REPLICATE)
        cv2.multiply(g, g, dst=prod)
        cv2.boxFilter(prod, -1, win, dst=den, normalize=False, borderType=cv2.BORDER_REPLICATE)
        np.less(den, floor, out=flat)
        cv2.max(den, float(floor), dst=den)
        cv2.divide(num, den, dst=num)
        cv2.subtract(d, num, dst=moved)
        cv2.copyTo(d, flat.view(np.uint8), moved)            # a flat window's pixel stays
        d, moved = moved, d
    return d, flat


def refine_disparity(left: np.ndarray, right: np.ndarray, disparity: np.ndarray, window_px: int = 5,
                     iterations: int = ITERATIONS, max_step_px: float = MAX_STEP_PX) -> np.ndarray:
    """:func:`refine_disparity_reference` (same arguments, the same bits) by :func:`refine_steps`, with the
    invalid pixels written once."""
    finite = np.isfinite(disparity)
    start = np.where(finite, disparity, np.float32(0.0)).astype(np.float32, copy=False)
    d, flat = refine_steps(left, right, start, window_px, iterations)
    fill_where(d, step_too_large(d, start, max_step_px) | flat | ~finite, np.nan)
    return d


def step_too_large(d: np.ndarray, start: np.ndarray, max_step_px: float) -> np.ndarray:
    """(H, W) bool: ``|d - start| > max_step_px`` (``d``, ``start`` (H, W) float32 px)."""
    return cv2.absdiff(d, start) > max_step_px
