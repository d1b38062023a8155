"""Flying pixels taken out of a depth camera's image before its points are used (docs/cameras.md).

A depth camera's pixel whose footprint straddles a depth edge reports a depth between the two surfaces (a
time-of-flight pixel mixes their returns, a structured-light pixel its pattern's two halves): a point in the air
along the ray, behind the occluding edge. Seen past a cart's near rim, such points lie over the hidden grain at
heights between the rim and the grain, and read as grain there.

The built-in perception drops them as depth pipelines do (a jump-edge filter): a pixel counts as flying when its
:data:`WINDOW` x :data:`WINDOW` neighbourhood holds a depth nearer than its own by more than a threshold *and* one
farther by more than it (or an invalid one: the far surface may lie beyond the camera's range), i.e. it lies
between two surfaces rather than on one. The threshold is
max(:data:`JUMP_MIN_M`, :data:`JUMP_SIGMAS` sigma(z)), sigma the camera's own expected depth error at the pixel's
depth, so the noise of one surface never reads as a jump. The pixels on each side of the edge (the rim, the grain
behind it) are the nearest or the farthest of their neighbourhood and stay.

Where it stops being valid: a surface seen so obliquely that its depth changes by more than the threshold over
:data:`WINDOW` // 2 pixels (about 78 deg of incidence for a Kinect-class camera at 5 m) loses its middle pixels
too; a flying pixel drawn within the threshold of either surface stays (its error is then below the threshold).
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["WINDOW", "JUMP_MIN_M", "JUMP_SIGMAS", "flying_pixels"]

#: side of the square neighbourhood searched for the two surfaces, px (5: a flying pixel's 3 x 3 neighbours
#: may all be flying pixels or one surface; two pixels out, both surfaces are seen)
WINDOW = 5
#: the smallest depth jump that counts, m
JUMP_MIN_M = 0.10
#: the jump must also exceed this many of the camera's expected depth sigmas at the pixel's depth
JUMP_SIGMAS = 3.0
_KERNEL = np.ones((WINDOW, WINDOW), np.uint8)


def flying_pixels(z: np.ndarray, sigma_m: np.ndarray, rows: np.ndarray | None = None,
                  cols: np.ndarray | None = None) -> np.ndarray:
    """Which pixels of the depth image ``z`` (H, W) m (NaN invalid) lie between two surfaces (module docstring),
    tested at the pixels ``rows`` x ``cols`` (index arrays; None: every pixel) whose expected depth sigmas
    ``sigma_m`` (len(rows), len(cols)) m are given. Returns bool of that shape; False where z is NaN."""
    z = np.asarray(z, np.float32)
    invalid = np.isnan(z)
    near = cv2.erode(np.where(invalid, np.float32(np.inf), z), _KERNEL, borderType=cv2.BORDER_REPLICATE)
    # an invalid neighbour may be the far surface out of range (or at grazing incidence): +inf, a jump
    far = cv2.dilate(np.where(invalid, np.float32(np.inf), z), _KERNEL, borderType=cv2.BORDER_REPLICATE)
    if rows is not None:
        pick = np.ix_(rows, cols)
        z, near, far = z[pick], near[pick], far[pick]
    jump = np.maximum(JUMP_MIN_M, JUMP_SIGMAS * np.asarray(sigma_m, np.float64))
    with np.errstate(invalid="ignore"):
        return (near < z - jump) & (far > z + jump)
