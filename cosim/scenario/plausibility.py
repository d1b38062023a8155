"""Checks a valid scenario must also pass before anything starts: the world at frame 0 makes sense.

Each check returns ``(loc, message)`` pairs (``loc`` the key path the problem belongs to); the loader turns them
into ``file:line:col: path: message`` problems (exit 2). They use the same geometry as the run (the frame-0
world of ``dynamics_proc.model.initial_world``, the scene of ``cosim.world.scene`` and its exact ray caster), so
what they refuse is what the run would have got wrong:

* each sensor (``sensor:``, or every entry of ``sensors:``; each eye of a stereo pair) below the ground, or inside
  the solids of the scene (a cart wall, a vehicle body, a wheel, the
  auger tube; a point on the face two solids share, e.g. where two cart walls meet, is inside their union), or
  inside the cart's walls below its rim (in the grain);
* the combine standing inside the cart (a cart far larger than the machines);
* the cart never in a sensor's field of view at the start pose: no beam (of at most ``FOV_BEAMS``, spread over
  the pattern) or camera ray (``FOV_PIXELS`` over the image) hits the cart within ``range_max_m``;
* a stereo head's disparity search that does not hold every surface its start view sees over the cart
  (cosim.scenario.stereo_search);
* a ``mesh_file`` that trimesh cannot load (or that holds no triangles);
* a CSV beam table that cannot be read, holds a non-finite or out-of-range angle, or is larger than
  ``MAX_CSV_BYTES``;
* a beam pattern whose memory exceeds what /dev/shm, the machine and the address space allow
  (cosim.scenario.memory);
* cameras beyond the pixel budget or the memory, and a height-map file that cannot be read safely or is out of
  bounds (cosim.scenario.sizes, checked first: nothing else is built when one fails).

A frame-0 world that cannot be built at all is a problem too (named, never a traceback).
"""
from __future__ import annotations

import itertools
import os
from pathlib import Path

import numpy as np

from cosim.runtime.specs import DEFAULT_SPECS, load_callable
from cosim.scenario.config import Scenario
from cosim.world.camera import Pinhole, beam_directions
from cosim.world.geometry import apply, body_from_camera_axes, entity_pose, invert, mount_transform
from cosim.world.parts import cart_boxes
from cosim.world.patterns import PatternError, beam_table

from .memory import memory_problems, size_text
from .sizes import size_problems

__all__ = ["implausible", "FOV_BEAMS", "MAX_CSV_BYTES", "NEIGHBOURHOOD_M"]

Loc = tuple
#: beams cast for the field-of-view check (spread evenly over the pattern's table)
FOV_BEAMS = 4096
#: rays cast over a camera's image for the field-of-view check (columns; rows keep the aspect ratio)
FOV_PIXELS = (64, 48)
#: largest CSV beam table read, bytes (~3 million beams; larger is refused unread)
MAX_CSV_BYTES = 64 << 20
#: a point is inside the union of the solids when every point of its neighbourhood (the 26 points at this
#: distance along the axes and diagonals, and itself) lies in some solid: a point closer than this to the surface
#: of the union counts as on it, m
NEIGHBOURHOOD_M = 2e-6
#: the neighbourhood's offsets (27, 3), m
_OFFSETS = NEIGHBOURHOOD_M * np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=3)))
#: slack of the closed containment tests (rounding of the transforms), m
_TOL_M = 1e-9


def _initial_state(s: Scenario) -> tuple[dict, np.ndarray]:
    """dyn_state fields and the truth height map (float32) of frame 0, as the dynamics role's spec gives them."""
    return load_callable(DEFAULT_SPECS["dynamics"].initial_state)(s)


def _pose(s: Scenario, state: dict, entity: str) -> np.ndarray:
    if entity == "world":
        return np.eye(4)
    return entity_pose(state, entity)


def _in_boxes(points: np.ndarray, world_from_box: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(K,) bool: each of ``points`` (K, 3) in (or on) any of N oriented boxes (N, 4, 4), half extents (N, 3)."""
    if len(half) == 0:
        return np.zeros(len(points), dtype=bool)
    rot, origin = world_from_box[:, :3, :3], world_from_box[:, :3, 3]
    local = np.einsum("nji,knj->kni", rot, points[:, None, :] - origin[None])     # R^T (p - o), (K, N, 3)
    return np.any(np.all(np.abs(local) <= half[None] + _TOL_M, axis=2), axis=1)


def _in_cylinders(points: np.ndarray, p0: np.ndarray, p1: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """(K,) bool: each of ``points`` (K, 3) in (or on) any of M cylinders (axis p0 -> p1 (M, 3), radius (M,))."""
    if len(radius) == 0:
        return np.zeros(len(points), dtype=bool)
    axis = p1 - p0
    length = np.linalg.norm(axis, axis=1)
    u = axis / np.maximum(length, 1e-12)[:, None]
    rel = points[:, None, :] - p0[None]                                            # (K, M, 3)
    t = np.einsum("kmi,mi->km", rel, u)
    radial = np.linalg.norm(rel - t[..., None] * u[None], axis=2)
    inside = (t >= -_TOL_M) & (t <= length + _TOL_M) & (radial <= radius + _TOL_M)
    return inside.any(axis=1)


def _mesh_problems(s: Scenario) -> list[tuple[Loc, str]]:
    from cosim.world.scene import load_mesh

    out = []
    for entity in ("combine", "tractor", "cart"):
        path = getattr(s, entity).mesh_file
        if path is None:
            continue
        try:
            load_mesh(Path(path))
        except Exception as exc:  # noqa: BLE001 - trimesh raises many types; each is the same refusal
            out.append(((entity, "mesh_file"), f"cannot load mesh {str(path)!r}: {type(exc).__name__}: {exc}"))
    return out


def _lidar_key(s: Scenario) -> tuple:
    """The key path of the LiDAR: ``sensor`` for the shorthand, else ``sensors.<name>``."""
    return ("sensor",) if not s.sensors else ("sensors", s.lidar_name)


def _pattern_problems(s: Scenario) -> tuple[list[tuple[Loc, str]], tuple | None]:
    """The beam table's problems (an unreadable or malformed CSV table, too many beams for the memory) and the
    table (elevation, azimuth) when it could be built without them (None without a LiDAR)."""
    lidar = s.lidar
    if lidar is None:
        return [], None
    key = _lidar_key(s) + ("pattern",)
    if lidar.pattern.preset == "csv":
        path = lidar.pattern.csv_file
        csv_key = key + ("csv_file",)
        try:
            size = os.stat(path).st_size
        except OSError as exc:
            return [(csv_key, f"cannot read the beam table {str(path)!r}: {exc.strerror}")], None
        if size > MAX_CSV_BYTES:
            return [(csv_key, f"the beam table is {size_text(size)}; tables are limited to "
                              f"{size_text(MAX_CSV_BYTES)} (~3 million beams)")], None
        try:
            table = beam_table(lidar.pattern)
        except PatternError as exc:
            return [(csv_key, str(exc))], None
        return memory_problems(s, beams=len(table[0])), table
    problems = memory_problems(s)
    if problems:
        return problems, None                  # the table itself would not fit
    try:
        return [], beam_table(lidar.pattern)
    except PatternError as exc:
        return [(key, str(exc))], None


def implausible(s: Scenario) -> list[tuple[Loc, str]]:
    """Every plausibility problem of ``s`` as (loc, message); [] when the world at frame 0 makes sense."""
    problems = size_problems(s)
    if problems:
        return problems  # nothing below may allocate what these refuse
    problems, table = _pattern_problems(s)
    problems += _mesh_problems(s)
    if problems:
        return problems  # the geometry below would load the same meshes, or use the pattern
    try:
        return _world_problems(s, table)
    except (ArithmeticError, ValueError, MemoryError) as exc:  # a world this far off cannot even be built
        return [((), f"the world at frame 0 cannot be built from this scenario ({type(exc).__name__}: {exc})")]


def _world_problems(s: Scenario, table: tuple | None) -> list[tuple[Loc, str]]:
    """The geometry checks of the frame-0 world (the module docstring's list), with the LiDAR's beam ``table``."""
    from cosim.world.scene import scene_from_state
    from cosim.world.terrain import terrain_of

    state, heights = _initial_state(s)
    cart_from_world = invert(_pose(s, state, "cart"))
    c = s.cart
    hl, hw = c.interior_length_m / 2.0, c.interior_width_m / 2.0
    combine = apply(cart_from_world, np.array([[state["combine_x_m"], state["combine_y_m"], 0.0]]))[0]
    if abs(combine[0]) < hl + c.wall_thickness_m and abs(combine[1]) < hw + c.wall_thickness_m:
        name, first = next(iter(s.sensor_set.items()))
        origin = _world_from_sensor(s, state, first)[:3, 3]
        if _under_grain(s, cart_from_world, origin):
            return [(_where(s, name, "mount", "xyz_m"), f"the sensor is inside the cart, under the grain surface "
                                                        f"{_at(origin)}")]
        return [(("cart",), f"the combine stands inside the cart at the start pose (cart interior "
                            f"{c.interior_length_m:g} x {c.interior_width_m:g} m, machine_sync offsets "
                            f"{s.machine_sync.longitudinal_offset_m:g}, {s.machine_sync.lateral_offset_m:g} m)")]
    terrain = terrain_of(s)
    scene = scene_from_state(s, state, heights, np.zeros((64, 4), np.float32))
    problems: list[tuple[Loc, str]] = []
    for name, sensor in s.sensor_set.items():
        problems += _sensor_problems(s, name, sensor, state, scene, cart_from_world, terrain, table)
    return problems


def _where(s: Scenario, name: str, *key: str) -> Loc:
    """The key path of sensor ``name``'s ``key``: under ``sensor`` for the shorthand LiDAR, else under
    ``sensors.<name>``."""
    return ("sensor", *key) if not s.sensors else ("sensors", name, *key)


def _at(origin: np.ndarray) -> str:
    return f"at world ({origin[0]:.2f}, {origin[1]:.2f}, {origin[2]:.2f}) m at the start"


def _world_from_sensor(s: Scenario, state: dict, sensor) -> np.ndarray:
    mount = sensor.mount
    return _pose(s, state, mount.parent) @ mount_transform(mount) @ body_from_camera_axes()


def _under_grain(s: Scenario, cart_from_world: np.ndarray, origin: np.ndarray) -> bool:
    c = s.cart
    local = apply(cart_from_world, origin[None])[0]
    return bool(abs(local[0]) < c.interior_length_m / 2.0 and abs(local[1]) < c.interior_width_m / 2.0
                and local[2] < c.floor_height_m + s.grain.initial_fill_m)


def _sensor_problems(s: Scenario, name: str, sensor, state: dict, scene, cart_from_world: np.ndarray, terrain,
                     table: tuple | None) -> list[tuple[Loc, str]]:
    """The problems of one sensor: an origin (each of a stereo pair's two) below the ground, under the grain or
    inside a solid; the cart never in its field of view within its range."""
    from cosim.world.fastcast import cast_from
    from cosim.world.raycast import raycast
    from cosim.world.sensors import camera_views

    wfs = _world_from_sensor(s, state, sensor)
    where = _where(s, name, "mount", "xyz_m")
    is_lidar = sensor.kind == "lidar"
    views = [("", np.eye(4))] if is_lidar else camera_views(name, sensor)
    for view, sensor_from_view in views:
        origin = (wfs @ sensor_from_view)[:3, 3]
        what = "the sensor" if is_lidar else f"camera {name!r}" + (f" ({view})" if len(views) > 1 else "")
        ground = float(terrain.height(origin[0], origin[1])) if terrain is not None else 0.0
        if origin[2] < ground:
            return [(where, f"{what} is {ground - origin[2]:.2f} m below the ground {_at(origin)}")]
        if _under_grain(s, cart_from_world, origin):
            return [(where, f"{what} is inside the cart, under the grain surface {_at(origin)}")]
        inside = _solids_at(s, state, origin)
        if inside:
            return [(where, f"{what} is inside the {inside} {_at(origin)}")]
    origin = wfs[:3, 3]
    if is_lidar:
        if table is None:
            return []                                  # the pattern's own checks report it
        elev, az = table
        pick = np.linspace(0, len(elev) - 1, min(FOV_BEAMS, len(elev))).astype(np.int64)
        d = beam_directions(elev[pick], az[pick]) @ wfs[:3, :3].T
        along = np.ones(len(d))
        rays = f"{len(pick)} beams spread over the pattern"
    else:
        pin = Pinhole(FOV_PIXELS[0], max(1, round(FOV_PIXELS[0] * sensor.height_px / sensor.width_px)),
                      float(np.radians(sensor.hfov_deg)))
        dc = pin.ray_directions().reshape(-1, 3)
        d, along = dc @ wfs[:3, :3].T, dc[:, 2]
        rays = f"{len(d)} rays spread over the image"
    # on uneven ground the scene holds the terrain's triangles: the Embree cast where it is installed
    t = raycast(scene, np.broadcast_to(origin, d.shape), d) if terrain is None else cast_from(scene, origin, d)
    depth = t * along                                   # range for the LiDAR, planar depth for a camera
    hit = np.isfinite(t) & (depth <= sensor.range_max_m) & (depth >= sensor.range_min_m)
    if not hit.any() or not _hits_cart(s, cart_from_world, origin + t[hit, None] * d[hit]):
        what = "the sensor's" if is_lidar else f"camera {name!r}'s"
        return [(_where(s, name, "mount"), f"the cart is never in {what} field of view at the start pose: none of "
                                           f"{rays} hits it within range_max_m {sensor.range_max_m:g} m "
                                           f"({'sensor' if is_lidar else 'camera'} {_at(origin)})")]
    if sensor.kind == "stereo_camera":
        return _search_problems(s, name, sensor, scene, cart_from_world, origin, d, t, depth)
    return []


def _search_problems(s: Scenario, name: str, cam, scene, cart_from_world: np.ndarray, origin: np.ndarray,
                     d: np.ndarray, t: np.ndarray, depth: np.ndarray) -> list[tuple[Loc, str]]:
    """A stereo head's disparity search that misses what its start view's rays ``d`` (N, 3) world, cast to range
    ``t`` (N,) m and planar depth ``depth`` (N,) m (the field of view check's cast), see over the cart
    (cosim.scenario.stereo_search); the label cast names the one surface the problem is about."""
    from cosim.world.labelcast import cast_labels

    from .stereo_search import footprint_masks, search_problem

    hit = np.flatnonzero(np.isfinite(t))
    over, around = np.zeros(len(t), dtype=bool), np.zeros(len(t), dtype=bool)
    over[hit], around[hit] = footprint_masks(s, cart_from_world, origin + t[hit, None] * d[hit])
    problem = search_problem(cam, depth, over, around,
                             lambda i: int(cast_labels(scene, origin, d[i:i + 1])[1][0]))
    return [(_where(s, name, "num_disparities"), f"camera {name!r}: {problem}")] if problem else []


def _solids_at(s: Scenario, state: dict, point: np.ndarray) -> str:
    """Which entity's solid holds world ``point`` inside the union of all the scene's solids (boxes and
    cylinders, each entity's body frame): "cart's walls", "tractor's wheels or auger", ...; "" when the point
    is outside or on the surface of the union. Inside the union: every point of its neighbourhood
    (NEIGHBOURHOOD_M) lies in some solid, so a point on a face two solids share counts as inside."""
    from cosim.world.parts import entity_parts

    around = point[None] + _OFFSETS                                   # (27, 3), the point itself at index 13
    covered = np.zeros(len(around), dtype=bool)
    holder = ""
    for entity, p in entity_parts(s).items():
        body = apply(invert(_pose(s, state, entity)), around)
        boxes = _in_boxes(body, p.body_from_box, p.half_extents) if p.mesh_file is None else \
            np.zeros(len(body), dtype=bool)
        cyls = _in_cylinders(body, p.cyl_p0, p.cyl_p1, p.cyl_radius)
        covered |= boxes | cyls
        if not holder and (boxes[13] or cyls[13]):
            holder = f"{entity}'s {'body' if entity != 'cart' else 'walls'}" if boxes[13] else \
                f"{entity}'s wheels or auger"
    return holder if covered.all() else ""


def _hits_cart(s: Scenario, cart_from_world: np.ndarray, points: np.ndarray) -> bool:
    """Whether any world point (K, 3) lies on the cart (within the bounds of its boxes, cart body frame)."""
    boxes = cart_boxes(s)
    lo = np.min([t[:3, 3] - h for t, h in boxes], axis=0) - 0.01
    hi = np.max([t[:3, 3] + h for t, h in boxes], axis=0) + 0.01
    local = apply(cart_from_world, points)
    return bool(np.any(np.all((local >= lo) & (local <= hi), axis=1)))
