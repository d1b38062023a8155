"""Procedural part lists of the machines, in each entity's body frame (x forward, y left, z up, origin on the
ground), built from the scenario's dimensions with trimesh-free closed forms (boxes and cylinders only).

The proportions below are named constants (m) chosen to look like an S660-class combine, an 8345R-class
tractor and a Brandt 1020XR-class cart at the scenario's overall dimensions; only the cart's interior, walls
and rim are measured geometry that perception relies on.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.scenario.config.scenario import Scenario
from cosim.world.geometry import make_transform
from cosim.world.labels import CART_RIM, CART_WALL, COMBINE, TRACTOR, TYRE

__all__ = ["CART_FLOOR_BOX", "CART_WALL_BOXES", "CART_RIM_BOXES", "HITCH_HEIGHT_M", "EntityParts", "box_from_bounds",
           "cart_boxes", "entity_parts", "wheel_contacts"]

#: combine: ground clearance of the body, header depth / bottom / top, cab height and width (m)
COMBINE_CLEARANCE_M = 0.5
HEADER_DEPTH_M = 1.5
HEADER_BOTTOM_M = 0.1
HEADER_TOP_M = 1.3
COMBINE_CAB_HEIGHT_M = 0.9
COMBINE_CAB_HALF_WIDTH_M = 0.9
COMBINE_CAB_LENGTH_M = 1.5
#: tractor: body (hood) half width, bottom and top; cab length and half width; wheel radii / widths (m)
TRACTOR_HOOD_HALF_WIDTH_M = 0.6
TRACTOR_HOOD_BOTTOM_M = 0.6
TRACTOR_HOOD_TOP_M = 1.8
TRACTOR_CAB_LENGTH_M = 2.0
TRACTOR_CAB_HALF_WIDTH_M = 1.0
TRACTOR_REAR_WHEEL_RADIUS_M = 1.0
TRACTOR_FRONT_WHEEL_RADIUS_M = 0.7
TRACTOR_WHEEL_WIDTH_M = 0.6
#: cart: wheel radius / width / gap to the wall; tongue half width and height (m)
CART_WHEEL_RADIUS_M = 0.8
CART_WHEEL_WIDTH_M = 0.5
CART_WHEEL_GAP_M = 0.05
CART_TONGUE_HALF_WIDTH_M = 0.1
CART_TONGUE_HEIGHT_M = 0.2
#: indices of the floor, of the four walls and of the four rim bars in :func:`cart_boxes`
CART_FLOOR_BOX = 0
CART_WALL_BOXES = (1, 2, 3, 4)
CART_RIM_BOXES = (5, 6, 7, 8)

COMBINE_COLOUR = (0.20, 0.55, 0.15)
TRACTOR_COLOUR = (0.25, 0.60, 0.20)
CART_COLOUR = (0.75, 0.15, 0.10)
WHEEL_COLOUR = (0.08, 0.08, 0.08)


@dataclass(frozen=True)
class EntityParts:
    """One entity's parts in its body frame. Boxes: ``body_from_box`` (N, 4, 4), ``half_extents`` (N, 3) m,
    ``box_colour`` (N, 3), ``box_hidden_top`` (N,) bool: the box's top (+z) face lies under other parts (the
    cart floor's under the grain surface and the walls, the walls' under the rim bars). Cylinders:
    ``cyl_p0``/``cyl_p1`` (M, 3) m, ``cyl_radius`` (M,) m, ``cyl_colour`` (M, 3). ``mesh_file`` replaces the
    boxes when set (drawn with ``mesh_colour``). ``box_label`` (N,), ``cyl_label`` (M,) and ``cyl_material``
    (M,) uint8: each part's label and material (cosim.world.labels; the cylinders of an entity are its wheels,
    material tyre)."""

    body_from_box: np.ndarray
    half_extents: np.ndarray
    box_colour: np.ndarray
    cyl_p0: np.ndarray
    cyl_p1: np.ndarray
    cyl_radius: np.ndarray
    cyl_colour: np.ndarray
    mesh_file: Path | None
    mesh_colour: tuple[float, float, float]
    box_hidden_top: np.ndarray
    box_label: np.ndarray | None = None
    cyl_label: np.ndarray | None = None
    cyl_material: np.ndarray | None = None


def box_from_bounds(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box between corners ``lo`` and ``hi`` (3,) m -> (body_from_box (4, 4), half_extents (3,))."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if np.any(hi <= lo):
        raise ValueError(f"box bounds must satisfy lo < hi, got {lo} and {hi}")
    return make_transform(np.eye(3), (lo + hi) / 2.0), (hi - lo) / 2.0


def _pack(boxes, colour, cyls, cyl_colour, mesh_file, hidden_top=(), label=COMBINE, box_labels=None
          ) -> EntityParts:
    """Stack ``boxes`` [(body_from_box, half_extents)] and ``cyls`` [(p0, p1, radius)]; ``hidden_top``: indices
    of boxes whose top face is covered (see :class:`EntityParts`); ``label``: every part's label, or
    ``box_labels`` per box."""
    t = np.stack([b[0] for b in boxes])
    h = np.stack([b[1] for b in boxes])
    p0 = np.array([c[0] for c in cyls], dtype=np.float64).reshape(-1, 3)
    p1 = np.array([c[1] for c in cyls], dtype=np.float64).reshape(-1, 3)
    r = np.array([c[2] for c in cyls], dtype=np.float64)
    hidden = np.zeros(len(h), dtype=bool)
    hidden[list(hidden_top)] = True
    blabel = np.full(len(h), label, np.uint8) if box_labels is None else np.asarray(box_labels, np.uint8)
    return EntityParts(t, h, np.tile(np.array(colour, np.float32), (len(h), 1)), p0, p1, r,
                       np.tile(np.array(cyl_colour, np.float32), (len(r), 1)), mesh_file, colour, hidden,
                       blabel, np.full(len(r), label, np.uint8), np.full(len(r), TYRE, np.uint8))


def _wheel_pair(x: float, half_track: float, radius: float, width: float):
    """Two wheels (axis along y) centred at x, ±half_track, on the ground."""
    return [((x, s * (half_track - width / 2.0), radius), (x, s * (half_track + width / 2.0), radius), radius)
            for s in (1.0, -1.0)]


def _combine(s: Scenario) -> EntityParts:
    c = s.combine
    hl, hw = c.length_m / 2.0, c.width_m / 2.0
    top = c.height_m - COMBINE_CAB_HEIGHT_M
    front = hl - HEADER_DEPTH_M
    boxes = [
        box_from_bounds((-hl, -hw, COMBINE_CLEARANCE_M), (front, hw, top)),
        box_from_bounds((front - COMBINE_CAB_LENGTH_M, -COMBINE_CAB_HALF_WIDTH_M, top),
                        (front, COMBINE_CAB_HALF_WIDTH_M, c.height_m)),
        box_from_bounds((front, -c.header_width_m / 2.0, HEADER_BOTTOM_M), (hl, c.header_width_m / 2.0, HEADER_TOP_M)),
    ]
    return _pack(boxes, COMBINE_COLOUR, [], WHEEL_COLOUR, c.mesh_file, label=COMBINE)


def _tractor(s: Scenario) -> EntityParts:
    t = s.tractor
    hl, hw = t.length_m / 2.0, t.width_m / 2.0
    boxes = [
        box_from_bounds((-hl, -TRACTOR_HOOD_HALF_WIDTH_M, TRACTOR_HOOD_BOTTOM_M),
                        (hl, TRACTOR_HOOD_HALF_WIDTH_M, TRACTOR_HOOD_TOP_M)),
        box_from_bounds((-hl, -TRACTOR_CAB_HALF_WIDTH_M, TRACTOR_HOOD_TOP_M),
                        (-hl + TRACTOR_CAB_LENGTH_M, TRACTOR_CAB_HALF_WIDTH_M, t.height_m)),
    ]
    wheels = (_wheel_pair(-hl + TRACTOR_REAR_WHEEL_RADIUS_M, hw, TRACTOR_REAR_WHEEL_RADIUS_M, TRACTOR_WHEEL_WIDTH_M)
              + _wheel_pair(hl - TRACTOR_FRONT_WHEEL_RADIUS_M, hw, TRACTOR_FRONT_WHEEL_RADIUS_M,
                            TRACTOR_WHEEL_WIDTH_M))
    return _pack(boxes, TRACTOR_COLOUR, wheels, WHEEL_COLOUR, t.mesh_file, label=TRACTOR)


def cart_boxes(s: Scenario) -> list[tuple[np.ndarray, np.ndarray]]:
    """The cart's floor, four walls, four rim bars and tongue (cart body frame). Interior |x| <= L/2,
    |y| <= W/2, floor_height <= z <= floor_height + D; walls of ``wall_thickness_m`` outside it; the rim bars
    sit on the wall tops, ``rim_width_m`` wide from the inner face outwards, ``rim_height_m`` high."""
    c = s.cart
    hl, hw, t = c.interior_length_m / 2.0, c.interior_width_m / 2.0, c.wall_thickness_m
    z0, z1 = c.floor_height_m, c.floor_height_m + c.interior_depth_m
    rw, rt = c.rim_width_m, c.rim_top_m
    return [
        box_from_bounds((-hl - t, -hw - t, z0 - t), (hl + t, hw + t, z0)),      # floor
        box_from_bounds((hl, -hw - t, z0 - t), (hl + t, hw + t, z1)),           # front wall
        box_from_bounds((-hl - t, -hw - t, z0 - t), (-hl, hw + t, z1)),         # rear wall
        box_from_bounds((-hl, hw, z0 - t), (hl, hw + t, z1)),                   # left wall
        box_from_bounds((-hl, -hw - t, z0 - t), (hl, -hw, z1)),                 # right wall
        box_from_bounds((hl, -hw - rw, z1), (hl + rw, hw + rw, rt)),            # front rim
        box_from_bounds((-hl - rw, -hw - rw, z1), (-hl, hw + rw, rt)),          # rear rim
        box_from_bounds((-hl, hw, z1), (hl, hw + rw, rt)),                      # left rim
        box_from_bounds((-hl, -hw - rw, z1), (hl, -hw, rt)),                    # right rim
        box_from_bounds((hl + t, -CART_TONGUE_HALF_WIDTH_M, z0 - t - CART_TONGUE_HEIGHT_M),
                        (hl + t + c.tongue_length_m, CART_TONGUE_HALF_WIDTH_M, z0 - t)),  # tongue
    ]


def _cart(s: Scenario) -> EntityParts:
    c = s.cart
    half_track = c.interior_width_m / 2.0 + c.wall_thickness_m + CART_WHEEL_GAP_M + CART_WHEEL_WIDTH_M / 2.0
    wheels = _wheel_pair(0.0, half_track, CART_WHEEL_RADIUS_M, CART_WHEEL_WIDTH_M)
    # the floor's top face is covered by the grain surface (heights >= 0 over the whole interior) and, around
    # it, lies inside the walls (which reach down to the floor's underside); a wall's top face lies under its
    # rim bar when the rim is at least as wide as the wall: no outside camera sees either
    hidden = [CART_FLOOR_BOX]
    if c.rim_width_m >= c.wall_thickness_m:
        hidden += list(CART_WALL_BOXES)
    labels = [CART_RIM if k in CART_RIM_BOXES else CART_WALL for k in range(len(cart_boxes(s)))]
    return _pack(cart_boxes(s), CART_COLOUR, wheels, WHEEL_COLOUR, c.mesh_file, hidden_top=hidden, label=CART_WALL,
                 box_labels=labels)


@functools.lru_cache(maxsize=8)
def _entity_parts(scenario: Scenario) -> dict[str, EntityParts]:
    return {"combine": _combine(scenario), "tractor": _tractor(scenario), "cart": _cart(scenario)}


#: the scenario of the last call and its parts: the renderer asks every frame with the same object, and hashing
#: a scenario (for the lru_cache) costs more than building the rest of the frame's scene record
_last: list = [None, None]


def entity_parts(scenario: Scenario) -> dict[str, EntityParts]:
    """Parts of ``combine``, ``tractor`` and ``cart`` in their body frames (cached per scenario)."""
    if _last[0] is not scenario:
        _last[:] = [scenario, _entity_parts(scenario)]
    return _last[1]


#: combine wheels: front axle behind the header, rear axle, and the track inset from the body's side (m)
COMBINE_FRONT_AXLE_BEHIND_HEADER_M = 1.0
COMBINE_REAR_AXLE_FROM_BACK_M = 1.0
COMBINE_TRACK_INSET_M = 0.3
#: height of the tractor's hitch above the ground (its drawbar), and so of the cart's tongue tip, level (m)
HITCH_HEIGHT_M = 0.6


def wheel_contacts(s: Scenario) -> dict[str, np.ndarray]:
    """Where each machine stands on the ground: (K, 2) body-frame (x, y) m of its wheels' contact points
    (combine and tractor: four; cart: its two wheels and, third, the tongue tip, which rests on the tractor's
    hitch at ``HITCH_HEIGHT_M``)."""
    c, t, k = s.combine, s.tractor, s.cart
    fx = c.length_m / 2.0 - HEADER_DEPTH_M - COMBINE_FRONT_AXLE_BEHIND_HEADER_M
    rx = -c.length_m / 2.0 + COMBINE_REAR_AXLE_FROM_BACK_M
    cy = c.width_m / 2.0 - COMBINE_TRACK_INSET_M
    hl, hw = t.length_m / 2.0, t.width_m / 2.0
    tr, tf = -hl + TRACTOR_REAR_WHEEL_RADIUS_M, hl - TRACTOR_FRONT_WHEEL_RADIUS_M
    track = k.interior_width_m / 2.0 + k.wall_thickness_m + CART_WHEEL_GAP_M + CART_WHEEL_WIDTH_M / 2.0
    tongue = k.interior_length_m / 2.0 + k.wall_thickness_m + k.tongue_length_m
    return {"combine": np.array([[fx, cy], [fx, -cy], [rx, cy], [rx, -cy]]),
            "tractor": np.array([[tf, hw], [tf, -hw], [tr, hw], [tr, -hw]]),
            "cart": np.array([[0.0, track], [0.0, -track], [tongue, 0.0]])}
