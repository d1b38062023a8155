"""Checks a valid scenario must also pass before anything starts: the world at frame 0 makes sense.

Each check returns ``(loc, message)`` pairs (``loc`` the key path the problem belongs to); the loader turns them
into ``file:line:col: path: message`` problems (exit 2). They use the same geometry as the run (the frame-0
world of ``dynamics_proc.model.initial_world``, the scene of ``cosim.world.scene`` and its exact ray caster), so
what they refuse is what the run would have got wrong:

* the sensor below the ground (z < 0), or inside a solid of the scene (a cart wall, a vehicle body, a wheel, the
  auger tube), or inside the cart's walls below its rim (in the grain);
* the combine standing inside the cart (a cart far larger than the machines);
* the cart never in the sensor's field of view at the start pose: no beam (of at most ``FOV_BEAMS``, spread over
  the pattern) hits the cart within ``range_max_m``;
* a ``mesh_file`` that trimesh cannot load (or that holds no triangles);
* a beam pattern whose memory (at least ``SHARED_BYTES_PER_BEAM`` of shared memory and
  ``PROCESS_BYTES_PER_BEAM`` in the processes per beam) exceeds what /dev/shm and the machine have free.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cosim.scenario.config import Scenario
from cosim.world.camera import Pinhole, beam_directions
from cosim.world.geometry import apply, body_from_camera_axes, invert, mount_transform, vehicle_pose
from cosim.world.parts import cart_boxes
from cosim.world.patterns import PatternError, beam_table, pattern_shape

__all__ = ["implausible", "memory_problems", "FOV_BEAMS", "SHARED_BYTES_PER_BEAM", "PROCESS_BYTES_PER_BEAM",
           "available_bytes", "size_text"]

Loc = tuple
#: beams cast for the field-of-view check (spread evenly over the pattern's table)
FOV_BEAMS = 4096
#: rays cast over a camera's image for the field-of-view check (columns; rows keep the aspect ratio)
FOV_PIXELS = (64, 48)
#: shared memory per beam, bytes: the ``lidar_points`` block, (N, 4) float32
SHARED_BYTES_PER_BEAM = 16
#: process memory per beam, at least, bytes: each of renderer and perception holds the beam table (2 float64)
#: and the unit directions (3 float64) = 40 B, plus perception's points (16 B) and ranges (8 B)
PROCESS_BYTES_PER_BEAM = 2 * 40 + 24
SHM_DIR = "/dev/shm"
#: a point this close to a surface counts as on it, not inside, m
_EPS_M = 1e-6


def available_bytes() -> tuple[int, int]:
    """(free bytes of /dev/shm, MemAvailable bytes of the machine); a figure that cannot be read is a large
    number (never the reason for a refusal)."""
    big = 1 << 62
    try:
        st = os.statvfs(SHM_DIR)
        shm = st.f_bavail * st.f_frsize
    except OSError:
        shm = big
    mem = big
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                mem = int(line.split()[1]) * 1024
                break
    except (OSError, ValueError, IndexError):
        pass
    return shm, mem


def size_text(n: float) -> str:
    """``n`` bytes for a message: "614.4 KiB"."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} TiB"


def memory_problems(s: Scenario, free: tuple[int, int] | None = None) -> list[tuple[Loc, str]]:
    """The beam pattern's memory against /dev/shm's free space and the machine's available memory."""
    lidar = s.lidar
    shape = pattern_shape(lidar.pattern) if lidar is not None else None
    if shape is None:
        return []
    beams = shape[0] * shape[1]
    shm_free, mem_free = free or available_bytes()
    shared, private = beams * SHARED_BYTES_PER_BEAM, beams * PROCESS_BYTES_PER_BEAM
    if shared <= shm_free and shared + private <= mem_free:
        return []
    return [((("sensor",) if not s.sensors else ("sensors", s.lidar_name)) + ("pattern",),
             f"{shape[1]} x {shape[0]} = {beams:,} beams need at least {size_text(shared)} of shared memory (block "
             f"lidar_points) and {size_text(private)} in the processes, but {SHM_DIR} has {size_text(shm_free)} free "
             f"and the machine {size_text(mem_free)} available; lower azimuth_count or elevation_count")]


def _initial_state(s: Scenario) -> tuple[dict, np.ndarray]:
    """dyn_state fields and the truth height map (float32) of frame 0."""
    from dynamics_proc.model import ModelParams, initial_world, signals

    # the frame-0 poses come from the scenario alone: the built-in controller and vehicle model stand in for any
    # plug-in or FMU (nothing of the user's is opened or stepped to check the geometry)
    geometry = s.model_copy(update={
        "controller": s.controller.model_copy(update={"model": "section_fill", "model_options": {},
                                                      "strategy": "front_to_back", "strategy_options": {}, "fmu": None}),
        "vehicles": type(s.vehicles)()})
    p = ModelParams.from_scenario(geometry)
    w = initial_world(geometry, p)
    state = signals(w, p)
    state["stream_points"] = 0
    return state, np.asarray(w.heights, dtype=np.float32)


def _pose(s: Scenario, state: dict, entity: str) -> np.ndarray:
    if entity == "world":
        return np.eye(4)
    return vehicle_pose(float(state[f"{entity}_x_m"]), float(state[f"{entity}_y_m"]), float(state[f"{entity}_yaw_rad"]))


def _inside_boxes(point: np.ndarray, world_from_box: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(N,) bool: ``point`` (3,) strictly inside each of N oriented boxes."""
    local = np.einsum("nij,nj->ni", np.linalg.inv(world_from_box)[:, :3, :3],
                      point[None] - world_from_box[:, :3, 3])
    return np.all(np.abs(local) < half - _EPS_M, axis=1)


def _inside_cylinders(point: np.ndarray, p0: np.ndarray, p1: np.ndarray, radius: np.ndarray) -> np.ndarray:
    axis = p1 - p0
    length = np.linalg.norm(axis, axis=1)
    u = axis / np.maximum(length, 1e-12)[:, None]
    t = np.einsum("ni,ni->n", point[None] - p0, u)
    radial = np.linalg.norm(point[None] - p0 - t[:, None] * u, axis=1)
    return (t > _EPS_M) & (t < length - _EPS_M) & (radial < radius - _EPS_M)


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


def implausible(s: Scenario) -> list[tuple[Loc, str]]:
    """Every plausibility problem of ``s`` as (loc, message); [] when the world at frame 0 makes sense."""
    problems = memory_problems(s) + _mesh_problems(s)
    if problems:
        return problems  # the geometry below would load the same meshes, or allocate the huge pattern
    from cosim.world.scene import scene_from_state

    state, heights = _initial_state(s)
    cart_from_world = invert(_pose(s, state, "cart"))
    c = s.cart
    hl, hw = c.interior_length_m / 2.0, c.interior_width_m / 2.0
    combine = apply(cart_from_world, np.array([[state["combine_x_m"], state["combine_y_m"], 0.0]]))[0]
    if abs(combine[0]) < hl + c.wall_thickness_m and abs(combine[1]) < hw + c.wall_thickness_m:
        where_first = _where(s, next(iter(s.sensor_set)), "mount", "xyz_m")
        origin = _world_from_sensor(s, state, next(iter(s.sensor_set.values())))[:3, 3]
        if _under_grain(s, cart_from_world, origin):
            return [(where_first, f"the sensor is inside the cart, under the grain surface {_at(origin)}")]
        return [(("cart",), f"the combine stands inside the cart at the start pose (cart interior "
                            f"{c.interior_length_m:g} x {c.interior_width_m:g} m, machine_sync offsets "
                            f"{s.machine_sync.longitudinal_offset_m:g}, {s.machine_sync.lateral_offset_m:g} m)")]
    scene = scene_from_state(s, state, heights, np.zeros((64, 4), np.float32))
    for name, sensor in s.sensor_set.items():
        problems += _sensor_problems(s, name, sensor, state, scene, cart_from_world)
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


def _sensor_problems(s: Scenario, name: str, sensor, state: dict, scene, cart_from_world: np.ndarray
                     ) -> list[tuple[Loc, str]]:
    """The problems of one sensor: an origin (each of a stereo pair's two) below the ground, under the grain or
    inside a solid; the cart never in its field of view within its range."""
    from cosim.world.raycast import raycast
    from cosim.world.sensors import camera_views

    wfs = _world_from_sensor(s, state, sensor)
    where = _where(s, name, "mount", "xyz_m")
    is_lidar = sensor.kind == "lidar"
    views = [("", np.eye(4))] if is_lidar else camera_views(name, sensor)
    for view, sensor_from_view in views:
        origin = (wfs @ sensor_from_view)[:3, 3]
        what = "the sensor" if is_lidar else f"camera {name!r}" + (f" ({view})" if len(views) > 1 else "")
        if origin[2] < 0.0:
            return [(where, f"{what} is {-origin[2]:.2f} m below the ground {_at(origin)}")]
        if _under_grain(s, cart_from_world, origin):
            return [(where, f"{what} is inside the cart, under the grain surface {_at(origin)}")]
        inside = _solids_at(s, state, origin)
        if inside:
            return [(where, f"{what} is inside the {inside} {_at(origin)}")]
    origin = wfs[:3, 3]
    if is_lidar:
        try:
            elev, az = beam_table(sensor.pattern)
        except PatternError:
            return []  # the pattern's own checks report it
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
    t = raycast(scene, np.broadcast_to(origin, d.shape), d)
    depth = t * along                                   # range for the LiDAR, planar depth for a camera
    hit = np.isfinite(t) & (depth <= sensor.range_max_m) & (depth >= sensor.range_min_m)
    if not hit.any() or not _hits_cart(s, cart_from_world, origin + t[hit, None] * d[hit]):
        what = "the sensor's" if is_lidar else f"camera {name!r}'s"
        return [(_where(s, name, "mount"), f"the cart is never in {what} field of view at the start pose: none of "
                                           f"{rays} hits it within range_max_m {sensor.range_max_m:g} m "
                                           f"({'sensor' if is_lidar else 'camera'} {_at(origin)})")]
    return []


def _solids_at(s: Scenario, state: dict, point: np.ndarray) -> str:
    """Which entity's solid (box or cylinder, its body frame) holds world ``point`` strictly inside: "cart's
    solid parts (...)" or "", from the parts the scene is built of (cosim.world.parts)."""
    from cosim.world.parts import entity_parts

    for entity, p in entity_parts(s).items():
        body = apply(invert(_pose(s, state, entity)), point[None])[0]
        boxes = p.mesh_file is None and _inside_boxes(body, p.body_from_box, p.half_extents).any()
        if boxes or _inside_cylinders(body, p.cyl_p0, p.cyl_p1, p.cyl_radius).any():
            return f"{entity}'s {'body' if entity != 'cart' else 'walls'}" if boxes else f"{entity}'s wheels or auger"
    return ""


def _hits_cart(s: Scenario, cart_from_world: np.ndarray, points: np.ndarray) -> bool:
    """Whether any world point (K, 3) lies on the cart (within the bounds of its boxes, cart body frame)."""
    boxes = cart_boxes(s)
    lo = np.min([t[:3, 3] - h for t, h in boxes], axis=0) - 0.01
    hi = np.max([t[:3, 3] + h for t, h in boxes], axis=0) + 0.01
    local = apply(cart_from_world, points)
    return bool(np.any(np.all((local >= lo) & (local <= hi), axis=1)))
