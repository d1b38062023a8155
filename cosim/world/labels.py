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
           "MATERIALS", "STEEL", "TYRE", "GRAIN_MAT", "STUBBLE", "ENTITY_LABEL", "TERRAIN_MESH_PREFIX", "mesh_label",
           "mesh_material", "label_names"]

#: label code -> name; the code is the index
LABELS = ("none", "ground", "cart_wall", "cart_rim", "grain", "grain_stream", "combine", "tractor", "auger")
NONE, GROUND, CART_WALL, CART_RIM, GRAIN, STREAM, COMBINE, TRACTOR, AUGER = range(len(LABELS))
#: material code -> name; the code is the index
MATERIALS = ("steel", "tyre", "grain", "stubble")
STEEL, TYRE, GRAIN_MAT, STUBBLE = range(len(MATERIALS))
#: the label of an entity's body (its boxes, meshes and wheels): the cart's body is its walls
ENTITY_LABEL = {"combine": COMBINE, "tractor": TRACTOR, "cart": CART_WALL}


#: a scene mesh whose name starts so is the ground (the terrain's patch, cosim.world.terrain)
TERRAIN_MESH_PREFIX = "terrain"


def mesh_label(name: str) -> int:
    """The label of a scene mesh: its entity's body (``combine``, ``tractor``, ``cart``), or the ground for the
    terrain's patch; ``NONE`` for any other."""
    if name.startswith(TERRAIN_MESH_PREFIX):
        return GROUND
    return ENTITY_LABEL.get(name, NONE)


def mesh_material(name: str) -> int:
    """The material of a scene mesh: stubble for the terrain's patch, painted steel otherwise."""
    return STUBBLE if name.startswith(TERRAIN_MESH_PREFIX) else STEEL


def label_names() -> dict[int, str]:
    """Label code -> name, for legends and the recording's metadata."""
    return dict(enumerate(LABELS))
