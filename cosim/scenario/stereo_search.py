"""The stereo head's disparity search against what it sees over the cart at the start (a plausibility check,
cosim.scenario.plausibility; docs/cameras.md, "The stereo camera").

OpenCV's matcher finds a disparity only inside its search, ``min_disparity_px`` to ``min_disparity_px +
num_disparities - 1``; a surface nearer than the search's near end (a larger disparity) or farther than its far
end has its cost minimum at an end of the search, or is matched to a wrong disparity inside it. Over the cart that
is a wrong point in the height map: the auger tube between a spout camera and the cart, read as grain, or grain
read at the wrong height. A search cut to the packaged head's geometry (``stereo_spout``) no longer holds the tube
when the head moves nearer to it, and nothing in the run says so: the height map loses the strip under the tube
or reads it wrong, and the cart overfills. So the check casts the camera's start view (the same rays as the field
of view check) and refuses a search that does not hold every surface it sees over the cart's outer footprint (the
walls, the rim, the grain, the floor and whatever lies between them and the camera), naming the nearest or farthest
such surface and the search that holds it (:func:`cosim.world.disparity_search.disparity_search`) together with
what it sees within :data:`AROUND_M` of the footprint (the ground beside the cart: a surface beyond the far end is
matched to a wrong disparity inside the search, docs/cameras.md).

Where it stops being valid: it sees the start pose only. The grain rises during the run, which the rim in view
bounds from above (its top is the highest the grain is meant to reach), and a head that swings with the auger over
other objects (another vehicle's body) is checked where it starts.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from cosim.scenario.config import Scenario
from cosim.scenario.config.cameras import StereoCamera
from cosim.world.disparity_search import disparity_search, searched_depths_m
from cosim.world.labels import LABELS

__all__ = ["AROUND_M", "footprint_masks", "search_problem"]

#: what a suggested search also holds: the surfaces seen within this of the cart's outer footprint, m
AROUND_M = 1.0


def footprint_masks(s: Scenario, cart_from_world: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(over, around), each (K,) bool: whether each world point (K, 3) m lies over the cart's outer footprint
    (inside its walls' outer faces in the cart's x and y, at any height), and over it grown by :data:`AROUND_M`."""
    c = s.cart
    hl, hw = c.interior_length_m / 2.0 + c.wall_thickness_m, c.interior_width_m / 2.0 + c.wall_thickness_m
    local = np.abs(points @ cart_from_world[:3, :3].T + cart_from_world[:3, 3])
    return ((local[:, 0] <= hl) & (local[:, 1] <= hw),
            (local[:, 0] <= hl + AROUND_M) & (local[:, 1] <= hw + AROUND_M))


def search_problem(cam: StereoCamera, depth: np.ndarray, over: np.ndarray, around: np.ndarray,
                   label_of: Callable[[int], int]) -> str:
    """The problem of stereo head ``cam``'s disparity search, "" when it holds every planar depth ``depth`` (N,) m
    of its start view's rays that hit a surface over the cart (``over`` (N,) bool); ``around`` (N,) bool: the rays
    that hit within :data:`AROUND_M` of the cart, which the suggested search holds too; ``label_of(i)``: what ray
    ``i`` hit (cosim.world.labels), asked for the one ray the problem names."""
    seen = over & np.isfinite(depth)
    if not seen.any():
        return ""                                   # the field of view check names a cart not in view
    f, b = cam.focal_px, cam.baseline_m
    z_near, z_far = searched_depths_m(f, b, cam.min_disparity_px, cam.num_disparities)
    rays = np.flatnonzero(seen)
    z = depth[rays]
    i_near, i_far = int(np.argmin(z)), int(np.argmax(z))
    if z[i_near] >= z_near and z[i_far] <= z_far:
        return ""
    if z[i_near] < z_near:
        what = f"the {LABELS[label_of(int(rays[i_near]))].replace('_', ' ')} over the cart at {z[i_near]:.2f} m is nearer"
    else:
        what = f"the {LABELS[label_of(int(rays[i_far]))].replace('_', ' ')} in the cart at {z[i_far]:.2f} m is farther"
    lo, hi = cam.disparity_range_px
    text = (f"its disparity search ({lo}-{hi} px: min_disparity_px {cam.min_disparity_px}, num_disparities "
            f"{cam.num_disparities}) holds planar depths {z_near:.2f}-{z_far:.2f} m, but at the start {what}: the "
            f"matcher would give those pixels wrong depths, and the height map wrong or missing cells")
    beside = depth[around & np.isfinite(depth)]
    near, far = float(z.min()), max(float(z.max()), float(beside.max()))
    try:
        m, n = disparity_search(f, b, near, far)
    except ValueError:
        return text + f"; no search holds {near:.2f}-{far:.2f} m"
    if m + n >= cam.width_px:
        return text + f"; holding {near:.2f}-{far:.2f} m needs more disparities than the image is wide"
    return text + f"; the search that holds {near:.2f}-{far:.2f} m: min_disparity_px {m}, num_disparities {n}"
