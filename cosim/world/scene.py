"""The render scene, rebuilt from the dynamics state every frame (the paper's Unreal scene, section 2.4).

One :class:`Scene` feeds both renderers (GL and the numpy mock) and the exact ray caster, so they agree on
geometry by construction. It holds only a few kinds of primitive, each exact in the ray caster:

* :class:`Boxes` - oriented boxes (combine body, cab, header, tractor, cart floor / walls / rim / tongue, the
  ground slab whose top face is the ground plane z = 0 on flat ground);
* :class:`Cylinders` - capped finite cylinders (auger tube, wheels, the grain stream between polyline points);
* :class:`HeightField` - the grain surface over the cart floor (``cosim.world.heightfield``);
* :class:`MeshInstance` - an optional triangle mesh loaded with trimesh from a scenario ``mesh_file``
  (replaces that entity's procedural boxes), and on uneven ground (``terrain:``) the terrain's patch around the
  cart in place of the ground slab (``cosim.world.terrain``; its name changes when the patch moves on).

All coordinates are world frame (x forward, y left, z up, m) unless a name says otherwise.
"""
from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.scenario.config.scenario import Scenario
from cosim.world.geometry import apply, cart_body_from_grid, entity_pose, make_transform, vehicle_pose
from cosim.world.terrain import terrain_of

from .labels import AUGER, GRAIN_MAT, GROUND, STEEL, STREAM, STUBBLE
from .parts import EntityParts, entity_parts

__all__ = [
    "GRAIN_COLOUR",
    "GROUND_THICKNESS_M",
    "MIN_SEGMENT_M",
    "SKY_RGBA",
    "STREAM_COLOUR",
    "STREAM_ROWS",
    "SUN_WORLD",
    "Boxes",
    "Cylinders",
    "HeightField",
    "MeshInstance",
    "Scene",
    "load_mesh",
    "scene_from_state",
]

#: rows of the ``stream`` block (CONTRACTS.md)
STREAM_ROWS = 64
#: thickness of the ground slab below z = 0, m (its top face is the ground plane)
GROUND_THICKNESS_M = 0.5
#: stream segments shorter or thinner than this are dropped (repeated polyline points, the run-out's last
#: frame of zero radius: no surface), m
MIN_SEGMENT_M = 1e-9
#: linear RGB colours of the shaded image
GROUND_COLOUR = (0.35, 0.30, 0.18)
GRAIN_COLOUR = (0.85, 0.70, 0.20)
STREAM_COLOUR = (0.95, 0.80, 0.25)
#: background of the shaded image (linear RGBA)
SKY_RGBA = (0.55, 0.70, 0.90, 1.0)
#: unit vector towards the sun, world frame (shaded image only)
SUN_WORLD = np.array([0.3, 0.4, 0.866]) / np.linalg.norm([0.3, 0.4, 0.866])


@dataclass(frozen=True)
class Boxes:
    """N oriented boxes. ``world_from_box`` (N, 4, 4) float64 rigid; ``half_extents`` (N, 3) float64 m (box
    frame); ``colour`` (N, 3) float32 linear RGB in [0, 1]. ``hidden_top`` (N,) bool or None (none): boxes
    whose top (+z, box frame) face no camera outside the solids can see, because other parts cover it; the
    GL renderer skips those faces (llvmpipe pays for hidden fragments almost as much as for visible ones),
    the ray caster need not. ``label`` and ``material`` (N,) uint8 or None: each box's label and material
    (cosim.world.labels; None: unlabelled, as in hand-built test scenes)."""

    world_from_box: np.ndarray
    half_extents: np.ndarray
    colour: np.ndarray
    hidden_top: np.ndarray | None = None
    label: np.ndarray | None = None
    material: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.half_extents)


@dataclass(frozen=True)
class Cylinders:
    """M capped cylinders from ``p0`` (M, 3) to ``p1`` (M, 3) (world, m) of ``radius`` (M,) m;
    ``colour`` (M, 3) float32 linear RGB; ``label`` and ``material`` (M,) uint8 or None as for :class:`Boxes`."""

    p0: np.ndarray
    p1: np.ndarray
    radius: np.ndarray
    colour: np.ndarray
    label: np.ndarray | None = None
    material: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.radius)


@dataclass(frozen=True)
class HeightField:
    """Grain heights ``heights`` (nx, ny) float32 m above the cart floor, cell (i, j) centred at ((i + 0.5) c,
    (j + 0.5) c) in the cart grid frame; ``world_from_grid`` (4, 4) float64; interior ``length_m`` x
    ``width_m``. The drawn surface is defined in ``cosim.world.heightfield``."""

    world_from_grid: np.ndarray
    heights: np.ndarray
    cell_m: float
    length_m: float
    width_m: float


@dataclass(frozen=True)
class MeshInstance:
    """A trimesh mesh: ``vertices`` (V, 3) float64 in its entity's body frame (m), ``faces`` (F, 3) int64,
    placed by ``world_from_mesh`` (4, 4) float64; ``colour`` (3,) linear RGB."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    world_from_mesh: np.ndarray
    colour: tuple[float, float, float]


@dataclass(frozen=True)
class Scene:
    """Everything the renderers draw for one frame (world frame). ``ground_box``: index in ``boxes`` of the
    ground slab (its top face is the ground plane), or None; the GL renderer keeps a per-camera image of it
    while the camera's pose relative to the slab's plane does not change (``renderer_proc.gl.backend``).
    ``poses``: world_from_body (4, 4) float64 of each entity the scene was built from (:func:`scene_from_state`),
    or None; with it the exact ray cast keeps each entity's parts in its body frame across frames
    (``cosim.world.rigidcast``)."""

    boxes: Boxes
    cylinders: Cylinders
    heightfield: HeightField
    meshes: tuple[MeshInstance, ...] = ()
    ground_box: int | None = None
    poses: Mapping[str, np.ndarray] | None = None


@functools.lru_cache(maxsize=8)
def load_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Load a mesh file (OBJ, STL, glTF, ...) with trimesh as one triangle mesh: (vertices (V, 3) float64 m,
    faces (F, 3) int64). Vertices must be in the entity's body frame (x forward, y left, z up, m)."""
    import trimesh  # lazily: only scenarios with mesh files pay for it

    mesh = trimesh.load(str(path), force="mesh")
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{path}: no triangles could be loaded")
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def _poses(state: Mapping[str, float]) -> dict[str, np.ndarray]:
    """world_from_body of each entity from the dyn_state fields (on the terrain: with z, roll and pitch)."""
    return {name: entity_pose(state, name) for name in ("combine", "tractor", "cart")}


def _stream_cylinders(stream: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments between consecutive valid stream rows: (p0 (K, 3), p1 (K, 3), radius (K,)), K <= n - 1 (those
    shorter or thinner than ``MIN_SEGMENT_M`` dropped)."""
    s = np.asarray(stream, dtype=np.float64)
    if s.ndim != 2 or s.shape[1] != 4:
        raise ValueError(f"stream must be (rows, 4) [x, y, z, radius], got {s.shape}")
    n = int(min(max(n_points, 0), len(s)))
    if n < 2:
        empty = np.zeros((0, 3))
        return empty, empty, np.zeros(0)
    pts = s[:n]
    radius = 0.5 * (pts[:-1, 3] + pts[1:, 3])
    keep = (np.linalg.norm(np.diff(pts[:, :3], axis=0), axis=1) > MIN_SEGMENT_M) & (radius > MIN_SEGMENT_M)
    return pts[:-1, :3][keep], pts[1:, :3][keep], radius[keep]


def _auger_and_stream(scenario: Scenario, state: Mapping[str, float], poses: Mapping[str, np.ndarray],
                      parts: Mapping[str, EntityParts], stream: np.ndarray,
                      stream_solid: bool | None) -> tuple[list, ...]:
    """The cylinders of the auger tube (pivot on the combine body -> spout, world) and of the stream: six lists of
    row arrays, one per cylinder column (p0, p1, radius, colour, label, material), for :func:`scene_from_state`."""
    c0, c1, rad, ccol, clabel, cmat = [], [], [], [], [], []
    # auger tube: pivot (combine body) -> spout (world)
    pivot = apply(poses["combine"], np.asarray(scenario.auger.pivot_xyz_m, dtype=np.float64))
    spout = np.array([state["spout_x_m"], state["spout_y_m"], state["spout_z_m"]], dtype=np.float64)
    c0.append(pivot[None])
    c1.append(spout[None])
    rad.append(np.array([scenario.auger.tube_radius_m]))
    ccol.append(np.array([parts["combine"].box_colour[0]], dtype=np.float32))
    clabel.append(np.array([AUGER], np.uint8))
    cmat.append(np.array([STEEL], np.uint8))
    # the stream is drawn from its valid rows alone (grain still falls for a while after the auger stops); with
    # atmosphere.stream_particles it is no solid: the LiDAR's atmosphere meets its kernels (docs/field.md)
    solid = not scenario.atmosphere.stream_particles if stream_solid is None else stream_solid
    s0, s1, sr = _stream_cylinders(stream, int(state["stream_points"]) if solid else 0)
    c0.append(s0)
    c1.append(s1)
    rad.append(sr)
    ccol.append(np.tile(np.array(STREAM_COLOUR, dtype=np.float32), (len(sr), 1)))
    clabel.append(np.full(len(sr), STREAM, np.uint8))
    cmat.append(np.full(len(sr), GRAIN_MAT, np.uint8))
    return c0, c1, rad, ccol, clabel, cmat


def scene_from_state(scenario: Scenario, state: Mapping[str, float], heightmap: np.ndarray,
                     stream: np.ndarray, stream_solid: bool | None = None) -> Scene:
    """Build the frame's scene.

    ``state``: dyn_state field name -> value (poses ``<entity>_{x_m,y_m,yaw_rad}``, ``spout_{x,y,z}_m``,
    ``auger_on``, ``stream_points``). ``heightmap``: (nx, ny) float32 grain heights m (cart grid frame).
    ``stream``: (64, 4) float32 rows [x, y, z, radius] (world, m); rows >= ``stream_points`` are ignored.
    """
    cart = scenario.cart
    nx, ny = (int(round(cart.interior_length_m / scenario.grain.cell_m)),
              int(round(cart.interior_width_m / scenario.grain.cell_m)))
    h = np.asarray(heightmap)
    if h.shape != (nx, ny):
        raise ValueError(f"heightmap shape {h.shape} does not match the cart grid ({nx}, {ny}) at cell "
                         f"{scenario.grain.cell_m} m")
    poses = _poses(state)
    parts: dict[str, EntityParts] = entity_parts(scenario)
    w_from_box, half, colour, hidden, blabel = [], [], [], [], []
    c0, c1, rad, ccol, clabel, cmat = [], [], [], [], [], []
    meshes = []
    for name, p in parts.items():
        pose = poses[name]
        if p.mesh_file is not None:
            v, f = load_mesh(p.mesh_file)
            meshes.append(MeshInstance(name, v, f, pose, p.mesh_colour))
        else:
            w_from_box.append(pose[None] @ p.body_from_box)
            half.append(p.half_extents)
            colour.append(p.box_colour)
            hidden.append(p.box_hidden_top)
            blabel.append(p.box_label)
        c0.append(apply(pose, p.cyl_p0))
        c1.append(apply(pose, p.cyl_p1))
        rad.append(p.cyl_radius)
        ccol.append(p.cyl_colour)
        clabel.append(p.cyl_label)
        cmat.append(p.cyl_material)
    terrain = terrain_of(scenario)
    ground_box = None
    if terrain is None:
        # ground slab under the combine: its top face z = 0 is the ground plane
        size = scenario.render.ground_size_m
        g = vehicle_pose(float(state["combine_x_m"]), float(state["combine_y_m"]), 0.0, -GROUND_THICKNESS_M / 2.0)
        ground_box = sum(len(x) for x in half)
        w_from_box.append(g[None])
        half.append(np.array([[size / 2.0, size / 2.0, GROUND_THICKNESS_M / 2.0]]))
        colour.append(np.array([GROUND_COLOUR], dtype=np.float32))
        hidden.append(np.zeros(1, dtype=bool))
        blabel.append(np.array([GROUND], np.uint8))
    else:
        # the terrain's patch around the cart (cosim.world.terrain): the surface the wheels stand on
        name, verts, faces, origin = terrain.mesh((float(state["cart_x_m"]), float(state["cart_y_m"])))
        meshes.append(MeshInstance(name, verts, faces, make_transform(np.eye(3), origin), GROUND_COLOUR))
    tube_and_stream = _auger_and_stream(scenario, state, poses, parts, stream, stream_solid)
    for column, rows in zip((c0, c1, rad, ccol, clabel, cmat), tube_and_stream):
        column.extend(rows)
    hf = HeightField(poses["cart"] @ cart_body_from_grid(cart), h.astype(np.float32, copy=False),
                     scenario.grain.cell_m, cart.interior_length_m, cart.interior_width_m)
    box_labels = np.concatenate(blabel)
    return Scene(
        Boxes(np.concatenate(w_from_box), np.concatenate(half), np.concatenate(colour).astype(np.float32),
              np.concatenate(hidden), box_labels, np.where(box_labels == GROUND, STUBBLE, STEEL).astype(np.uint8)),
        Cylinders(np.concatenate(c0), np.concatenate(c1), np.concatenate(rad),
                  np.concatenate(ccol).astype(np.float32), np.concatenate(clabel), np.concatenate(cmat)),
        hf, tuple(meshes), ground_box, poses,
    )
