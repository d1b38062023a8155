"""Cart pose from whatever part of its rim a camera sees: the known rim rectangle fitted to the visible rim, from
where Machine Sync puts the cart (docs/cameras.md).

:func:`perception_proc.estimates.rim.find_cart` needs the rim's extent across the cart and one end along it. A
camera on the spout or the mast often sees less: one end, one side rim, pieces of both, or only the grain inside.
Machine Sync knows where the cart is (``posegate.expected_cart``: the tractor's RTK position relative to the
combine, the cart on its hitch), and the cart's dimensions are known, so the rim's centre line is a known
rectangle whose pose is nearly known. :func:`fit_cart` refines that pose on the points the sensors see:

1. Points within the rim band (``rim.RIM_BAND_M`` plus one of the point's own expected 1-sigma, the sensor's error
   model: Z^2 dd / (f B) for stereo, the depth model's sigma, the LiDAR's range sigma) are rim candidates.
2. Iteratively reweighted Gauss-Newton on (x, y, yaw): each candidate's residual is its distance from the nearest
   side of the rim's centre line rectangle (the interior plus half the rim's width); its weight is Tukey's biweight
   of the residual over a window shrinking from the pose gate's reach to :data:`FINAL_WINDOW_M`, divided by its
   variance (the rim's own half-width spread :data:`RIM_SPREAD_M` squared plus the point's sigma squared). The
   prior adds (pose - Machine Sync pose) / (:data:`PRIOR_SIGMA_M`, :data:`PRIOR_SIGMA_DEG`): where the rim seen
   constrains a direction (an end seen fixes the position along the cart, a side rim the position across and the
   yaw) the points rule; where it does not, the prior does.
3. The answer is the cart when at least :data:`MIN_RIM_POINTS` points lie on the rim's centre line within the
   final window and cover at least :data:`MIN_RIM_LENGTH_M` of the ring (:data:`RING_BIN_M` bins along its
   perimeter), or, seeing no rim, when at least :data:`MIN_INSIDE_SHARE` of the points over the cart's interior
   (shrunk by the pose gate) lie between its floor and rim top (grain or floor where the cart should be, not
   ground): the pose is then Machine Sync's alone. It is ``partial`` when any direction of the pose rests on the
   prior more than on the points (the information matrix of the points against the prior's, per axis).

The fitted pose never leaves the pose gate (``perception.pose_gate_m``, ``pose_gate_deg``) of the prior; a fit
that would is no answer.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cosim.scenario.config import Cart
from cosim.world.geometry import cart_body_from_grid, make_transform, rot_z
from perception_proc.estimates.rim import RIM_BAND_M, CartEstimate

__all__ = ["CartPrior", "fit_cart", "within_gate", "PRIOR_SIGMA_M", "PRIOR_SIGMA_DEG", "MIN_RIM_LENGTH_M", "FINAL_WINDOW_M",
           "MIN_INSIDE_SHARE"]

#: 1-sigma of the prior's position in the fit, m (half the default pose gate: the points rule wherever they see)
PRIOR_SIGMA_M = 0.25
#: 1-sigma of the prior's yaw in the fit, deg
PRIOR_SIGMA_DEG = 2.5
#: the spread of true rim points across the rim's centre line (a uniform 0.12 m rim: 0.12 / sqrt(12)), m
RIM_SPREAD_M = 0.035
#: the last Tukey window of the residuals, m: the rim's half-width and a few centimetres of depth error
FINAL_WINDOW_M = 0.15
#: Gauss-Newton iterations (the windows shrink geometrically from the gate's reach to FINAL_WINDOW_M)
ITERATIONS = 8
#: fewest rim points on the centre line for an answer from the rim
MIN_RIM_POINTS = 30
#: fewest points on one side of the rim for that side to count
MIN_SIDE_POINTS = 20
#: points this close to a corner (along their side) do not count towards a side's points, m
CORNER_M = 0.3
#: bins along the rim's perimeter used to measure how much of it is seen, m
RING_BIN_M = 0.2
#: least length of the ring seen for an answer from the rim, m (a third of the cart's width)
MIN_RIM_LENGTH_M = 1.0
#: seeing no rim, the least share of the points over the interior that lie between floor and rim top
MIN_INSIDE_SHARE = 0.8
#: seeing no rim, the fewest points over the interior
MIN_INSIDE_POINTS = 200
#: slack under the floor and over the rim top for the points inside, m
INSIDE_SLACK_M = 0.15


@dataclass(frozen=True)
class CartPrior:
    """Where Machine Sync puts the cart, in the level frame: body origin (x, y) m (the rim rectangle's centre) and
    yaw rad; ``gate_m``, ``gate_deg``: how far the fit may move it (``perception.pose_gate_m``, ``pose_gate_deg``)."""

    x: float
    y: float
    yaw: float
    gate_m: float
    gate_deg: float


def _tukey(r: np.ndarray, c: float) -> np.ndarray:
    """Tukey's biweight (1 - (r/c)^2)^2 inside |r| < c, else 0."""
    u = np.clip(1.0 - (r / c) ** 2, 0.0, None)
    return u * u


def _residuals(p: np.ndarray, pose: np.ndarray, a: float, b: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(residual (K,) m, Jacobian (K, 3), coordinate along the ring (K,) m, side (K,) 0 front end, 1 left,
    2 rear end, 3 right, near a corner (K,) bool) of level points ``p`` (K, 2) against the rectangle of half sides ``a`` (along the cart),
    ``b`` (across) at ``pose`` (x, y, yaw)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx, dy = p[:, 0] - pose[0], p[:, 1] - pose[1]
    qx, qy = c * dx + s * dy, -s * dx + c * dy
    sx, sy = np.where(qx >= 0, 1.0, -1.0), np.where(qy >= 0, 1.0, -1.0)
    rx, ry = np.abs(qx) - a, np.abs(qy) - b
    end = rx >= ry                  # the nearest side: an end (|x| = a) where the point lies nearer the ends
    r = np.where(end, rx, ry)
    jac = np.empty((len(p), 3))
    jac[:, 0] = np.where(end, -sx * c, sy * s)
    jac[:, 1] = np.where(end, -sx * s, -sy * c)
    jac[:, 2] = np.where(end, sx * qy, -sy * qx)
    # position along the perimeter, counter-clockwise from the front end's right corner
    along = np.where(end, np.where(sx > 0, qy + b, 2 * a + 3 * b - qy),
                     np.where(sy > 0, 2 * b + a - qx, 4 * b + 3 * a + qx))
    side = np.where(end, np.where(sx > 0, 0, 2), np.where(sy > 0, 1, 3))
    corner = np.where(end, np.abs(qy) > b - CORNER_M, np.abs(qx) > a - CORNER_M)
    return r, jac, np.clip(along, 0.0, 4 * (a + b)), side, corner


def _side_weights(r: np.ndarray, side: np.ndarray, corner: np.ndarray, window: float,
                  w_var: np.ndarray) -> np.ndarray:
    """Each point's weight: Tukey's biweight in ``window`` over its variance, zero on a side with fewer than
    :data:`MIN_SIDE_POINTS` points within ``window`` of it and :data:`CORNER_M` or more from its
    corners (``corner`` (K,) bool: near one); a few points at the field's edge or a wall's inner face, off by the
    matcher's edge fattening, and an end's points round the corner would otherwise set a direction the rest of
    the rim does not see."""
    w = _tukey(r, window) * w_var
    counts = np.bincount(side[(np.abs(r) < window) & ~corner], minlength=4)
    w[counts[side] < MIN_SIDE_POINTS] = 0.0
    return w


def _solve(p, w_var, prior, a, b, reach):
    """Reweighted Gauss-Newton from the prior; (pose (3,), information of the points (3, 3), residuals, weights,
    along)."""
    pose = np.array([prior.x, prior.y, prior.yaw])
    p0 = pose.copy()
    info_prior = np.diag([PRIOR_SIGMA_M ** -2, PRIOR_SIGMA_M ** -2, math.radians(PRIOR_SIGMA_DEG) ** -2])
    ratio = (FINAL_WINDOW_M / reach) ** (1.0 / max(ITERATIONS - 1, 1)) if reach > FINAL_WINDOW_M else 1.0
    for it in range(ITERATIONS):
        window = max(FINAL_WINDOW_M, reach * ratio ** it)
        r, jac, _, side, corner = _residuals(p, pose, a, b)
        w = _side_weights(r, side, corner, window, w_var)
        info = (jac * w[:, None]).T @ jac
        grad = (jac * w[:, None]).T @ r + info_prior @ (pose - p0)
        pose = pose - np.linalg.solve(info + info_prior, grad)
    r, jac, along, side, corner = _residuals(p, pose, a, b)
    w = _side_weights(r, side, corner, FINAL_WINDOW_M, w_var)
    return pose, (jac * w[:, None]).T @ jac, r, w, along


def _inside_confirms(p: np.ndarray, z: np.ndarray, cart: Cart, prior: CartPrior) -> bool:
    """Whether the points over the prior's interior (shrunk by the gate) are mostly between floor and rim top."""
    c, s = math.cos(prior.yaw), math.sin(prior.yaw)
    dx, dy = p[:, 0] - prior.x, p[:, 1] - prior.y
    qx, qy = c * dx + s * dy, -s * dx + c * dy
    over = (np.abs(qx) <= cart.interior_length_m / 2 - prior.gate_m) & \
        (np.abs(qy) <= cart.interior_width_m / 2 - prior.gate_m)
    n = int(np.count_nonzero(over))
    if n < MIN_INSIDE_POINTS:
        return False
    zi = z[over]
    inside = (zi >= cart.floor_height_m - INSIDE_SLACK_M) & (zi <= cart.rim_top_m + INSIDE_SLACK_M)
    return float(np.count_nonzero(inside)) >= MIN_INSIDE_SHARE * n


def _estimate(cart: Cart, pose: np.ndarray, n: int, partial: bool) -> CartEstimate:
    level_from_grid = make_transform(rot_z(pose[2]), (pose[0], pose[1], 0.0)) @ cart_body_from_grid(cart)
    L, W = cart.interior_length_m, cart.interior_width_m
    zr = cart.interior_depth_m + cart.rim_height_m
    grid = np.array([[0, 0, zr], [L, 0, zr], [L, W, zr], [0, W, zr]], dtype=np.float64)
    corners = grid @ level_from_grid[:3, :3].T + level_from_grid[:3, 3]
    return CartEstimate(True, corners, level_from_grid, float(pose[2]), (float(pose[0]), float(pose[1])), n,
                        partial, "")


def fit_cart(points: np.ndarray, sigma_m: np.ndarray, cart: Cart, prior: CartPrior) -> CartEstimate:
    """The cart's pose fitted to the visible rim from ``prior`` (module docstring). ``points`` (N, 3) float m,
    level frame, NaN rows invalid; ``sigma_m`` (N,) each point's expected 1-sigma from its sensor's model, m."""
    p = np.asarray(points, np.float64)
    sig = np.asarray(sigma_m, np.float64)
    ok = np.isfinite(p[:, 0]) & np.isfinite(sig)
    p, sig = p[ok], sig[ok]
    none = CartEstimate(False, np.full((4, 3), np.nan), np.full((4, 4), np.nan), math.nan, (math.nan, math.nan),
                        0, False, "")
    rw = cart.rim_width_m
    a, b = (cart.interior_length_m + rw) / 2, (cart.interior_width_m + rw) / 2
    band = np.abs(p[:, 2] - cart.rim_top_m) <= RIM_BAND_M + sig
    cand, csig = p[band, :2], sig[band]
    reach = prior.gate_m + rw
    if cand.shape[0] >= MIN_RIM_POINTS:
        pose, info, r, w, along = _solve(cand, 1.0 / (RIM_SPREAD_M ** 2 + csig ** 2), prior, a, b, reach)
        on = w > 0
        seen = np.unique(np.floor(along[on] / RING_BIN_M)).size * RING_BIN_M
        moved = math.hypot(pose[0] - prior.x, pose[1] - prior.y)
        turned = abs(math.degrees(math.remainder(pose[2] - prior.yaw, 2 * math.pi)))
        if np.count_nonzero(on) >= MIN_RIM_POINTS and seen >= MIN_RIM_LENGTH_M:
            if moved > prior.gate_m or turned > prior.gate_deg:
                return _reason(none, f"rim fit moved {moved:.2f} m, {turned:.1f} deg from Machine Sync's pose")
            return _estimate(cart, pose, int(np.count_nonzero(on)), _leans_on_prior(info, pose[2]))
    if _inside_confirms(p[:, :2], p[:, 2], cart, prior):
        return _estimate(cart, np.array([prior.x, prior.y, prior.yaw]), 0, True)
    return _reason(none, f"{cand.shape[0]} points at rim height: under {MIN_RIM_LENGTH_M:.1f} m of rim seen "
                         "where Machine Sync puts the cart")


def within_gate(cart: CartEstimate, prior: CartPrior) -> bool:
    """Whether a found ``cart`` lies within the pose gate of ``prior`` (both in the level frame)."""
    moved = math.hypot(cart.centre_xy[0] - prior.x, cart.centre_xy[1] - prior.y)
    turned = abs(math.degrees(math.remainder(cart.yaw_rad - prior.yaw, 2 * math.pi)))
    return moved <= prior.gate_m and turned <= prior.gate_deg


def _leans_on_prior(info: np.ndarray, yaw: float) -> bool:
    """Whether the points' information along the cart, across it or in yaw is below the prior's."""
    c, s = math.cos(yaw), math.sin(yaw)
    along, across = np.array([c, s, 0.0]), np.array([-s, c, 0.0])
    floor = PRIOR_SIGMA_M ** -2
    return bool(along @ info @ along < floor or across @ info @ across < floor
                or info[2, 2] < math.radians(PRIOR_SIGMA_DEG) ** -2)


def _reason(none: CartEstimate, why: str) -> CartEstimate:
    return CartEstimate(False, none.corners, none.level_from_grid, math.nan, (math.nan, math.nan), 0, False, why)
