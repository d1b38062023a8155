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

import numpy as np

from cosim.scenario.config import Scenario
from cosim.scenario.config.cameras import StereoCamera
from cosim.world.disparity_search import disparity_search, searched_depths_m
from cosim.world.labels import LABELS

__all__ = ["AROUND_M", "over_cart", "search_problem"]

#: what a suggested search also holds: the surfaces seen within this of the cart's outer footprint, m
AROUND_M = 1.0


def over_cart(s: Scenario, cart_from_world: np.ndarray, points: np.ndarray, grow_m: float = 0.0) -> np.ndarray:
    """(K,) bool: whether each world point (K, 3) m lies over the cart's outer footprint grown by ``grow_m`` m
    (inside its walls' outer faces in the cart's x and y, at any height)."""
    c = s.cart
    hl = c.interior_length_m / 2.0 + c.wall_thickness_m + grow_m
    hw = c.interior_width_m / 2.0 + c.wall_thickness_m + grow_m
    local = points @ cart_from_world[:3, :3].T + cart_from_world[:3, 3]
    return (np.abs(local[:, 0]) <= hl) & (np.abs(local[:, 1]) <= hw)


def search_problem(cam: StereoCamera, depth: np.ndarray, label: np.ndarray, over: np.ndarray,
                   around: np.ndarray) -> str:
    """The problem of stereo head ``cam``'s disparity search, "" when it holds every planar depth ``depth`` (N,) m
    of its start view's rays that hit a surface over the cart (``over`` (N,) bool; ``label`` (N,) uint8, what
    each ray hit, cosim.world.labels); ``around`` (N,) bool: the rays that hit within :data:`AROUND_M` of the
    cart, which the suggested search holds too."""
    seen = over & np.isfinite(depth)
    if not seen.any():
        return ""                                   # the field of view check names a cart not in view
    f, b = cam.focal_px, cam.baseline_m
    z_near, z_far = searched_depths_m(f, b, cam.min_disparity_px, cam.num_disparities)
    z, lab = depth[seen], label[seen]
    i_near, i_far = int(np.argmin(z)), int(np.argmax(z))
    if z[i_near] >= z_near and z[i_far] <= z_far:
        return ""
    if z[i_near] < z_near:
        what = f"the {LABELS[lab[i_near]].replace('_', ' ')} over the cart at {z[i_near]:.2f} m is nearer"
    else:
        what = f"the {LABELS[lab[i_far]].replace('_', ' ')} in the cart at {z[i_far]:.2f} m is farther"
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
