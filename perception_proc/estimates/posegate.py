"""The cart found where Machine Sync puts it, or no cart (``perception.pose_gate_m``, ``pose_gate_deg``;
docs/field.md).

The rim finder (perception_proc.estimates.rim) takes any rim-sized group of points at rim height for the cart. In dust no
sensor sees through, the dust's own near returns can form one: a phantom cart metres from the real one, whose
"height map" reads grain where none lies, so that the controller would fill blind or declare the cart full.
Machine Sync knows where the cart is: the tractor's position from its RTK receiver, relative to the combine's
(about 2 cm), and the cart on its hitch. :func:`expected_cart` is that pose (the cart's, moved by the tractor's
GNSS error relative to the combine, ``dyn_state.gnss_error_long_m`` / ``_lat_m`` in combine axes);
:func:`pose_gate` rejects a found cart farther than ``pose_gate_m`` from it or turned more than ``pose_gate_deg``:
the frame then has no cart, no height map and no impact, as when nothing was found. Measured: a cart really found
lies within 0.11 m and 0.6 deg of it (``high_flow``, perception feedback, 553 frames); the phantoms in 5-15 m
visibility dust lay 1.0-2.1 m and 14-29 deg off (``blinding_dust``, 221 frames of two seeds).
"""
from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from perception_proc.estimates.impact import Impact
from perception_proc.estimates.rim import NO_CART
from perception_proc.estimates.rimfit import CartPrior
from perception_proc.pipeline import FrameResult

__all__ = ["expected_cart", "pose_offset", "pose_gate", "level_prior"]


def expected_cart(state: Mapping[str, float]) -> tuple[float, float, float] | None:
    """Where Machine Sync puts the cart body origin: world (x, y) m and yaw rad, from the frame's ``dyn_state``
    (None when it has no cart pose)."""
    try:
        x, y, yaw = float(state["cart_x_m"]), float(state["cart_y_m"]), float(state["cart_yaw_rad"])
    except KeyError:
        return None
    cy = float(state.get("combine_yaw_rad", 0.0))
    el, et = float(state.get("gnss_error_long_m", 0.0)), float(state.get("gnss_error_lat_m", 0.0))
    return x + math.cos(cy) * el - math.sin(cy) * et, y + math.sin(cy) * el + math.cos(cy) * et, yaw


def level_prior(state: Mapping[str, float], wfp: np.ndarray, gate_m: float, gate_deg: float) -> CartPrior | None:
    """:func:`expected_cart` in the level frame (``wfp`` (4, 4): world from it) with the gate's reach, for the rim
    fit (perception_proc.estimates.rimfit); None without a cart pose or with the gate off (``gate_m`` 0)."""
    expected = expected_cart(state) if state and gate_m > 0.0 else None
    if expected is None:
        return None
    lw = np.linalg.inv(wfp)
    c = lw @ np.array([expected[0], expected[1], 0.0, 1.0])
    yaw = expected[2] + math.atan2(lw[1, 0], lw[0, 0])
    return CartPrior(float(c[0]), float(c[1]), math.atan2(math.sin(yaw), math.cos(yaw)), gate_m, gate_deg)


def pose_offset(res: FrameResult, wfp: np.ndarray, expected: tuple[float, float, float]) -> tuple[float, float]:
    """(distance m, |yaw difference| deg) of the found cart from ``expected``; ``wfp`` (4, 4) world from the level
    frame the cart was found in."""
    c = wfp @ np.array([res.cart.centre_xy[0], res.cart.centre_xy[1], 0.0, 1.0])
    yaw = math.atan2(wfp[1, 0], wfp[0, 0]) + res.cart.yaw_rad
    d = yaw - expected[2]
    return math.hypot(c[0] - expected[0], c[1] - expected[1]), abs(math.degrees(math.atan2(math.sin(d), math.cos(d))))


def pose_gate(res: FrameResult, state: Mapping[str, float], wfp: np.ndarray, gate_m: float,
              gate_deg: float) -> FrameResult:
    """``res``, or, when its cart lies more than ``gate_m`` or ``gate_deg`` from :func:`expected_cart`, the same
    frame without a cart, height map or impact (the cart's ``reason`` says how far off it was). ``gate_m`` 0: no
    gate."""
    if gate_m <= 0.0 or not res.cart.valid or not state:
        return res
    expected = expected_cart(state)
    if expected is None:
        return res
    dist, turn = pose_offset(res, wfp, expected)
    if dist <= gate_m and turn <= gate_deg:
        return res
    why = f"found {dist:.2f} m and {turn:.1f} deg from where Machine Sync puts the cart: not the cart"
    cart = type(NO_CART)(False, NO_CART.corners, NO_CART.level_from_grid, math.nan, (math.nan, math.nan),
                         res.cart.n_points, False, why)
    return FrameResult(res.points, cart, None, Impact(False, np.full(3, np.nan), 0, "no cart"), res.timing_ms)
