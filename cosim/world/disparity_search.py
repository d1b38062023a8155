"""The stereo matcher's disparity search from the depths the cart can lie at (docs/cameras.md, "The stereo camera").

A rectified pair of focal length f (px) and baseline B (m) sees a point at planar depth Z (m, along the optical
axis) at disparity d = f B / Z (px). A surface between planar depths ``z_near_m`` and ``z_far_m`` therefore lies
between f B / z_far and f B / z_near; OpenCV searches ``num_disparities`` (a multiple of 16) disparities from
``min_disparity_px``, and the stereo model invalidates a disparity within ``SEARCH_EDGE_PX`` of either end of the
search (the stereo model in perception: a surface outside the searched depths has its cost minimum at an end). The
search here is the smallest that keeps every depth of [z_near, z_far] at least that edge inside it: the largest
``min_disparity_px`` and then the fewest ``num_disparities`` that do. The matcher's work per pixel is linear in
``num_disparities``, so a search limited to where the cart can be costs that share of the full one.

:func:`spout_view_depths_m` gives the span for a camera looking straight down from the spout on a level cart over
level ground. The far end is the ground lowered by a margin: the ground beside the cart is in view, and a surface
beyond the search is matched to a wrong disparity inside it (docs/cameras.md gives the measured share). The near
end is the nearer of the rim top raised by a margin (grain heaped to the rim, the cart's bounce) and the auger
tube's top at the spout (:func:`auger_top_m`), which lies over the cart in view: a search that stops short of it
reads the tube's pixels as points inside the cart (docs/cameras.md: the fill-height error more than doubles).
"""
from __future__ import annotations

import math

from cosim.scenario.config.cameras import DISPARITY_STEP_PX, SEARCH_EDGE_PX

__all__ = ["CART_MARGIN_M", "disparity_of_depth", "disparity_search", "searched_depths_m",
           "auger_top_m", "spout_view_depths_m"]

#: margin above the rim top and below the ground in the depth span of a spout camera's view, m
CART_MARGIN_M = 0.5


def disparity_of_depth(z_m: float, focal_px: float, baseline_m: float) -> float:
    """Disparity d = f B / Z, px, of planar depth ``z_m`` (m) for focal length ``focal_px`` and baseline
    ``baseline_m`` (m)."""
    return focal_px * baseline_m / z_m


def disparity_search(focal_px: float, baseline_m: float, z_near_m: float, z_far_m: float,
                     edge_px: float = SEARCH_EDGE_PX) -> tuple[int, int]:
    """(``min_disparity_px``, ``num_disparities``): the smallest search that holds every planar depth in
    [``z_near_m``, ``z_far_m``] (m, 0 < near < far) at least ``edge_px`` inside its ends (module docstring).
    ValueError where the far depth's disparity is within ``edge_px`` of 0 (no search holds it)."""
    if not 0.0 < z_near_m < z_far_m:
        raise ValueError(f"need 0 < z_near_m < z_far_m, got {z_near_m} and {z_far_m}")
    d_lo = disparity_of_depth(z_far_m, focal_px, baseline_m)
    d_hi = disparity_of_depth(z_near_m, focal_px, baseline_m)
    if d_lo < edge_px:
        raise ValueError(f"z_far_m {z_far_m} m is at {d_lo:.3f} px, within {edge_px} px of 0: no search holds it")
    lo = math.floor(d_lo - edge_px)
    hi = math.ceil(d_hi + edge_px)
    return lo, DISPARITY_STEP_PX * math.ceil((hi - lo + 1) / DISPARITY_STEP_PX)


def searched_depths_m(focal_px: float, baseline_m: float, min_disparity_px: int, num_disparities: int,
                      edge_px: float = SEARCH_EDGE_PX) -> tuple[float, float]:
    """(nearest, farthest) planar depth, m, whose disparity lies at least ``edge_px`` inside the search
    [``min_disparity_px``, ``min_disparity_px + num_disparities - 1``] (``edge_px`` > 0)."""
    lo, hi = min_disparity_px + edge_px, min_disparity_px + num_disparities - 1 - edge_px
    return focal_px * baseline_m / hi, focal_px * baseline_m / lo


def auger_top_m(auger) -> float:
    """Height of the auger tube's top at the spout above the combine frame's origin (the ground), m: the pivot's
    height + ``length_m`` sin(``elevation_deg``) + ``tube_radius_m`` (``auger``: the scenario's Auger)."""
    return auger.pivot_xyz_m[2] + auger.length_m * math.sin(math.radians(auger.elevation_deg)) + auger.tube_radius_m


def spout_view_depths_m(camera_height_m: float, rim_top_m: float, auger_top_m: float,
                        margin_m: float = CART_MARGIN_M) -> tuple[float, float]:
    """(near, far) planar depth, m, for a camera looking straight down from ``camera_height_m`` above level ground
    onto a level cart whose rim top lies ``rim_top_m`` above it, past the auger tube whose top at the spout lies
    ``auger_top_m`` above it: near the nearer of the rim top raised by ``margin_m`` and the tube's top (where the
    tube lies below the camera), far the ground lowered by ``margin_m`` (module docstring)."""
    near = camera_height_m - (rim_top_m + margin_m)
    if auger_top_m < camera_height_m:
        near = min(near, camera_height_m - auger_top_m)
    return near, camera_height_m + margin_m
