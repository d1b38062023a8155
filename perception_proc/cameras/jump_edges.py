"""Flying pixels taken out of a depth camera's image before its points are used (docs/cameras.md).

A depth camera's pixel whose footprint straddles a depth edge reports a depth between the two surfaces (a
time-of-flight pixel mixes their returns, a structured-light pixel its pattern's two halves): a point in the air
along the ray, behind the occluding edge. Seen past a cart's near rim, such points lie over the hidden grain at
heights between the rim and the grain, and read as grain there.

The built-in perception drops them as depth pipelines do (a jump-edge filter): a pixel counts as flying when its
:data:`WINDOW` x :data:`WINDOW` neighbourhood holds a depth nearer than its own by more than a threshold *and* one
farther by more than it (or an invalid one: the far surface may lie beyond the camera's range), i.e. it lies
between two surfaces rather than on one (:func:`jump_threshold`). The threshold is what one surface can span: its
slope, a surface the camera reports at all (incidence below its ``max_incidence_deg``, theta) changing by at most
z tan(theta) / f per pixel over the :data:`WINDOW` // 2 pixels to the window's edge, plus :data:`JUMP_SIGMAS` of
the camera's own expected depth error sigma(z), so that neither a slope nor the noise reads as a jump. The pixels
on each side of the edge (the rim, the grain behind it) are the nearest or the farthest of their neighbourhood and
stay. The threshold scales with the pixel's footprint, so the filter means the same at any resolution.

Where it stops being valid: a flying pixel drawn within the threshold of either surface stays (its error is then
below the threshold: 0.28 m along the ray for the Kinect-class camera, 512 px over 70.6 deg, at 5 m: 0.16 m of
slope and 0.12 m of noise); a step smaller than the threshold (a thin ledge) is not a jump.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["WINDOW", "JUMP_SIGMAS", "jump_threshold", "flying_pixels"]

#: side of the square neighbourhood searched for the two surfaces, px (5: a flying pixel's 3 x 3 neighbours
#: may all be flying pixels or one surface; two pixels out, both surfaces are seen)
WINDOW = 5
#: the jump must exceed this many of the camera's expected depth sigmas at the pixel's depth (besides the slope)
JUMP_SIGMAS = 3.0
_KERNEL = np.ones((WINDOW, WINDOW), np.uint8)


def jump_threshold(z_m: np.ndarray, sigma_m: np.ndarray, focal_px: float, max_incidence_deg: float) -> np.ndarray:
    """The depth step (m, shape of ``z_m``) beyond which a pixel at planar depth ``z_m`` (m) sees two surfaces: the
    most one surface at incidence under ``max_incidence_deg`` spans over :data:`WINDOW` // 2 pixels of a camera of
    focal length ``focal_px`` (px), (WINDOW // 2) z tan(theta) / f, plus :data:`JUMP_SIGMAS` ``sigma_m`` (m)."""
    z = np.asarray(z_m, np.float64)
    slope = (WINDOW // 2) * z * math.tan(math.radians(max_incidence_deg)) / focal_px
    return slope + JUMP_SIGMAS * np.asarray(sigma_m, np.float64)


def flying_pixels(z: np.ndarray, jump_m: np.ndarray, rows: np.ndarray | None = None,
                  cols: np.ndarray | None = None) -> np.ndarray:
    """Which pixels of the depth image ``z`` (H, W) m (NaN invalid) lie between two surfaces (module docstring),
    tested at the pixels ``rows`` x ``cols`` (index arrays; None: every pixel) with their thresholds ``jump_m``
    (len(rows), len(cols)) m (:func:`jump_threshold`). Returns bool of that shape; False where z is NaN."""
    z = np.asarray(z, np.float32)
    invalid = np.isnan(z)
    near = cv2.erode(np.where(invalid, np.float32(np.inf), z), _KERNEL, borderType=cv2.BORDER_REPLICATE)
    # an invalid neighbour may be the far surface out of range (or at grazing incidence): +inf, a jump
    far = cv2.dilate(np.where(invalid, np.float32(np.inf), z), _KERNEL, borderType=cv2.BORDER_REPLICATE)
    if rows is not None:
        pick = np.ix_(rows, cols)
        z, near, far = z[pick], near[pick], far[pick]
    jump = np.asarray(jump_m, np.float64)
    with np.errstate(invalid="ignore"):
        return (near < z - jump) & (far > z + jump)
