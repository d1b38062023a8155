"""Per-pixel labels and surface materials of the scene's parts (docs/cameras.md).

A camera's label image (``cam_<name>_labels``, (H, W) uint8) holds, per pixel, what its ray meets first: the
codes below (0 where it meets nothing in range). The GL renderer writes each primitive's label from the scene
(``Boxes.label``, ``Cylinders.label``, the grain surface); the mock renderer and the tests find the same
answer by exact ray cast (``cosim.world.labelcast``).

Materials pick a camera's procedural texture (``renderer_proc/shaders/camera.frag``): painted steel (machine
bodies, cart, auger tube), tyres (wheels), grain (the surface and the stream) and stubble (the ground).
"""
from __future__ import annotations

__all__ = ["LABELS", "NONE", "GROUND", "CART_WALL", "CART_RIM", "GRAIN", "STREAM", "COMBINE", "TRACTOR", "AUGER",
           "MATERIALS", "STEEL", "TYRE", "GRAIN_MAT", "STUBBLE", "ENTITY_LABEL", "label_names"]

#: label code -> name; the code is the index
LABELS = ("none", "ground", "cart_wall", "cart_rim", "grain", "grain_stream", "combine", "tractor", "auger")
NONE, GROUND, CART_WALL, CART_RIM, GRAIN, STREAM, COMBINE, TRACTOR, AUGER = range(len(LABELS))
#: material code -> name; the code is the index
MATERIALS = ("steel", "tyre", "grain", "stubble")
STEEL, TYRE, GRAIN_MAT, STUBBLE = range(len(MATERIALS))
#: the label of an entity's body (its boxes, meshes and wheels): the cart's body is its walls
ENTITY_LABEL = {"combine": COMBINE, "tractor": TRACTOR, "cart": CART_WALL}


def label_names() -> dict[int, str]:
    """Label code -> name, for legends and the recording's metadata."""
    return dict(enumerate(LABELS))
