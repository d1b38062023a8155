"""The stereo camera's depth: disparity from OpenCV's block matchers on the rendered left and right images,
depth Z = f B / d (docs/cameras.md). Pure functions around ``cv2``.

The pair is rectified by construction (same pinhole, parallel axes, the right camera ``baseline_m`` along the
left's +X), so a point at planar depth Z appears d = f B / Z pixels further left in the right image. The
matchers run on the grey images (ITU-R BT.601 luma of the stored bytes): ``sgbm`` is ``cv2.StereoSGBM``
(P1 = 8 cn b^2, P2 = 32 cn b^2 with cn = 1 and b the block size, OpenCV's recommended smoothness penalties),
``bm`` is ``cv2.StereoBM``. OpenCV returns fixed-point disparities (1/16 px); a pixel whose disparity is not
above ``min_disparity_px - 1`` (no match, or filtered as a speckle or by the uniqueness or left-right check)
is invalid, and so is a disparity of 0 (a point at infinity). Then (``perception_proc.cameras.subpixel``) blocks
without texture are invalid (``texture_threshold``) and, with ``subpixel: refine``, each disparity is refined by
Gauss-Newton on the intensity difference instead of OpenCV's parabola, which locks to whole pixels. Nothing is
added to the images: the depth error is the matcher's, on the renderer's textured images.

:func:`stereo_depth_reference` is the readable composition of these steps; :func:`stereo_depth` gives the same
bits with the invalid pixels gathered in one mask (the matcher's fixed-point output checked against one integer
range, :func:`kept_raw_range`) and written once, at the end (tests/test_stereo_kernels.py).
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from cosim.scenario.config.cameras import SEARCH_EDGE_PX, StereoCamera
from perception_proc.cameras.subpixel import (
    MAX_STEP_PX,
    fill_where,
    refine_disparity,
    refine_steps,
    step_too_large,
    texture_mask,
)

__all__ = ["FIXED_POINT", "SGBM_MODES", "make_matcher", "grey", "disparity", "camera_disparity", "depth_from_disparity",
           "kept_raw_range", "stereo_depth", "stereo_depth_reference"]

#: OpenCV's disparity fixed point: 16 steps per pixel
FIXED_POINT = 16.0
#: SGBM's smoothness penalties per unit of cn b^2 (OpenCV's documentation: 8 and 32)
P1_PER_AREA, P2_PER_AREA = 8, 32
#: ``sgbm_mode`` -> OpenCV's StereoSGBM mode
SGBM_MODES = {"sgbm": cv2.STEREO_SGBM_MODE_SGBM, "3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY,
              "hh": cv2.STEREO_SGBM_MODE_HH}


def make_matcher(cam: StereoCamera):
    """The OpenCV matcher of ``cam`` (``sgbm`` or ``bm``) with its parameters."""
    if cam.matcher == "bm":
        m = cv2.StereoBM_create(numDisparities=cam.num_disparities, blockSize=cam.block_size)
        m.setMinDisparity(cam.min_disparity_px)
        m.setUniquenessRatio(cam.uniqueness_ratio)
        m.setSpeckleWindowSize(cam.speckle_window_px)
        m.setSpeckleRange(cam.speckle_range_px)
        m.setDisp12MaxDiff(cam.disp12_max_diff_px)
        return m
    area = cam.block_size * cam.block_size
    return cv2.StereoSGBM_create(minDisparity=cam.min_disparity_px, numDisparities=cam.num_disparities,
                                 blockSize=cam.block_size, P1=P1_PER_AREA * area, P2=P2_PER_AREA * area,
                                 disp12MaxDiff=cam.disp12_max_diff_px, uniquenessRatio=cam.uniqueness_ratio,
                                 speckleWindowSize=cam.speckle_window_px, speckleRange=cam.speckle_range_px,
                                 mode=SGBM_MODES[cam.sgbm_mode])


def grey(rgba: np.ndarray) -> np.ndarray:
    """(H, W) uint8 luma of an (H, W, 4) or (H, W, 3) uint8 RGB(A) image (alpha ignored: OpenCV's RGBA and RGB
    conversions weigh R, G and B alike)."""
    code = cv2.COLOR_RGBA2GRAY if rgba.shape[-1] == 4 else cv2.COLOR_RGB2GRAY
    return cv2.cvtColor(rgba if rgba.flags.c_contiguous else np.ascontiguousarray(rgba), code)


def disparity(matcher, left: np.ndarray, right: np.ndarray, min_disparity_px: int = 0) -> np.ndarray:
    """Disparity (H, W) float32 px of the left image, NaN where the matcher has no answer (or gives 0). ``left``,
    ``right``: (H, W) uint8 grey images."""
    raw = matcher.compute(left, right)
    d = np.divide(raw, np.float32(FIXED_POINT), dtype=np.float32)
    d[raw <= max((min_disparity_px - 1) * FIXED_POINT, 0)] = np.nan      # below the search, or 0 (infinity)
    return d


def camera_disparity(matcher, cam: StereoCamera, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The stereo camera's disparity (H, W) float32 px, NaN invalid, of its grey pair ``left``, ``right`` (H, W)
    uint8: the matcher's, blocks without texture invalid, refined to sub-pixel with ``subpixel: refine``."""
    d = disparity(matcher, left, right, cam.min_disparity_px)
    lo, hi = cam.disparity_range_px
    with np.errstate(invalid="ignore"):
        d[(d < lo + SEARCH_EDGE_PX) | (d > hi - SEARCH_EDGE_PX)] = np.nan
    if cam.texture_threshold > 0:
        d[texture_mask(left, cam.block_size, cam.texture_threshold)] = np.nan
    if cam.subpixel == "refine":
        d = refine_disparity(left, right, d, window_px=cam.block_size)
        with np.errstate(invalid="ignore"):
            d[d <= 0] = np.nan
    return d


def depth_from_disparity(d: np.ndarray, focal_px: float, baseline_m: float) -> np.ndarray:
    """Planar depth Z = f B / d (H, W) float32 m of disparities ``d`` (px, NaN invalid)."""
    return np.divide(np.float32(focal_px * baseline_m), d, dtype=np.float32)


def stereo_depth_reference(matcher, cam: StereoCamera, focal_px: float, left_rgba: np.ndarray,
                           right_rgba: np.ndarray) -> np.ndarray:
    """The stereo camera's planar depth (H, W) float32 m, NaN invalid or outside ``range_min_m`` ..
    ``range_max_m``, from its left and right (H, W, 4) uint8 images: the readable form of :func:`stereo_depth`."""
    z = depth_from_disparity(camera_disparity(matcher, cam, grey(left_rgba), grey(right_rgba)), focal_px,
                             cam.baseline_m)
    with np.errstate(invalid="ignore"):
        z[(z < cam.range_min_m) | (z > cam.range_max_m)] = np.nan
    return z


def kept_raw_range(cam: StereoCamera) -> tuple[int, int]:
    """(lowest, highest) fixed-point disparity (1/16 px) of OpenCV's output that :func:`camera_disparity` keeps:
    above the search's invalid value and 0 (:func:`disparity`) and :data:`SEARCH_EDGE_PX` inside the search. The
    float32 thresholds are compared as :func:`camera_disparity` compares them (d = raw / 16 is exact)."""
    lo, hi = cam.disparity_range_px
    floor = max((cam.min_disparity_px - 1) * FIXED_POINT, 0)
    low = float(np.float32(lo + SEARCH_EDGE_PX)) * FIXED_POINT                # d < low / 16 is invalid
    high = float(np.float32(hi - SEARCH_EDGE_PX)) * FIXED_POINT               # d > high / 16 is invalid
    return max(math.floor(floor) + 1, math.ceil(low)), math.floor(high)


def stereo_depth(matcher, cam: StereoCamera, focal_px: float, left_rgba: np.ndarray, right_rgba: np.ndarray
                 ) -> np.ndarray:
    """The stereo camera's planar depth (H, W) float32 m, NaN invalid or outside ``range_min_m`` ..
    ``range_max_m``, from its left and right (H, W, 4) uint8 images: :func:`stereo_depth_reference`'s bits with
    every invalid pixel gathered in one mask and written once."""
    left, right = grey(left_rgba), grey(right_rgba)
    raw = matcher.compute(left, right)
    invalid = cv2.inRange(raw, *kept_raw_range(cam)) == 0
    if cam.texture_threshold > 0:
        invalid |= texture_mask(left, cam.block_size, cam.texture_threshold)
    d = np.divide(raw, np.float32(FIXED_POINT), dtype=np.float32)
    if cam.subpixel == "refine":
        fill_where(d, invalid, 0.0)                                           # the refinement's start
        start = d
        d, flat = refine_steps(left, right, start, window_px=cam.block_size)
        invalid |= step_too_large(d, start, MAX_STEP_PX)
        invalid |= flat                 # d <= 0 (camera_disparity's test) gives z <= 0 or +inf: out of range
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.divide(np.float32(focal_px * cam.baseline_m), d, dtype=np.float32)
        invalid |= z < cam.range_min_m
        invalid |= z > cam.range_max_m
    fill_where(z, invalid, np.nan)
    return z
