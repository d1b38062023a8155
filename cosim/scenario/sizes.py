"""What a scenario's cameras and ground cost, checked before anything is allocated (cosim.scenario.plausibility
runs these first).

* the cameras: every camera view's pixels (a stereo pair counts twice, at the size the run renders them,
  ``cosim.world.sensors.camera_pinhole``) together at most :data:`CAMERA_PIXEL_BUDGET` a frame, and their memory
  (shared blocks and each process's working arrays, :data:`CAMERA_PROCESS_BYTES_PER_PIXEL`) within what /dev/shm,
  the machine and the address space allow (cosim.scenario.memory.room);
* the ground: a height-map file read safely and within bounds (cosim.world.height_map), and the square its
  roughness is drawn on within ``MAX_TERRAIN_CELLS``.

The pixel budget is a start-up and frame budget, derived from measurements on a 2-core laptop (reproduced by
``python bench/camera_pixel_cost.py``): the depth camera's noise model, the costliest per-pixel stage, takes about
300-460 ns and 200 B of working memory a pixel; 2^23 pixels (27 VGA views, two 2048 x 2048 ones) are then about
2.5-3.9 s and 1.6 GiB a frame in perception, which a start-up of ``timing.startup_timeout_s`` (120 s) and a short
run still absorb. More is refused with the figures, not found out 40 s into the run.
"""
from __future__ import annotations

from cosim.scenario.config import Scenario
from cosim.scenario.config.terrain import MAX_TERRAIN_CELLS

from .memory import Room, room, size_text

__all__ = ["CAMERA_PIXEL_BUDGET", "CAMERA_PROCESS_BYTES_PER_PIXEL", "camera_pixels", "camera_problems",
           "terrain_problems", "size_problems"]

#: most camera pixels rendered in one frame, over every view of every camera (see the module docstring)
CAMERA_PIXEL_BUDGET = 1 << 23
#: working memory a camera pixel costs in the processes, bytes: the depth camera's noise model's peak (200 B,
#: measured with tracemalloc on perception_proc.cameras.tof.tof_depth for a 1280 x 960 image;
#: tests/test_input_surfaces.py holds the model to it)
CAMERA_PROCESS_BYTES_PER_PIXEL = 200
#: shared bytes a pixel of each camera part costs (renderer's blocks, cosim.world.sensors.camera_parts)
_PART_BYTES = {"rgb": 4, "right": 4, "depth": 4, "labels": 1}
#: perception's shared bytes per pixel of a depth-giving camera: ``cam_<name>_measured`` float32
_MEASURED_BYTES = 4

Problem = tuple[tuple, str]


def camera_pixels(s: Scenario) -> dict[str, tuple[int, int, int]]:
    """Camera name -> (width px, height px, views) as the run renders it."""
    from cosim.world.sensors import camera_pinhole, camera_views

    out = {}
    for name, cam in s.cameras.items():
        pin = camera_pinhole(cam, s)
        out[name] = (pin.width, pin.height, len(camera_views(name, cam)))
    return out


def _shared_bytes(s: Scenario, name: str, pixels: int) -> int:
    from cosim.world.sensors import camera_parts, points_stride

    cam = s.cameras[name]
    per_view = sum(_PART_BYTES[part] for _, part in camera_parts(cam))
    if cam.kind in ("depth_camera", "stereo_camera"):
        stride = points_stride(cam, s)
        per_view += _MEASURED_BYTES + 16 / (stride * stride)
    return int(pixels * per_view)


def camera_problems(s: Scenario, free: tuple | None = None) -> list[Problem]:
    """The cameras over the pixel budget or beyond the memory (``free``: a :class:`Room`, default measured)."""
    sizes = camera_pixels(s)
    if not sizes:
        return []
    total, first_over = 0, None
    for name, (w, h, views) in sizes.items():
        total += w * h * views
        if total > CAMERA_PIXEL_BUDGET and first_over is None:
            first_over = name
    shown = ", ".join(f"{n} {w} x {h}" + (f" x {v}" if v > 1 else "") for n, (w, h, v) in list(sizes.items())[:4])
    shown += f", ... ({len(sizes)} cameras)" if len(sizes) > 4 else ""
    if first_over is not None:
        return [(("sensors", first_over), f"the cameras render {total:,} pixels a frame ({shown}); at most "
                 f"{CAMERA_PIXEL_BUDGET:,} fit the start-up and frame budget (docs/cameras.md): use fewer or "
                 "smaller cameras")]
    have = Room(*(free if free is not None else room()))
    shared = sum(_shared_bytes(s, n, w * h * v) for n, (w, h, v) in sizes.items())
    private = total * CAMERA_PROCESS_BYTES_PER_PIXEL
    if shared <= have.shm and shared + private <= min(have.memory, have.address_space):
        return []
    return [(("sensors",), f"the cameras ({shown}) need {size_text(shared)} of shared memory and "
             f"{size_text(private)} in the processes, but /dev/shm has {size_text(have.shm)} free and the machine "
             f"{size_text(min(have.memory, have.address_space))} available: use fewer or smaller cameras")]


def terrain_problems(s: Scenario) -> list[Problem]:
    """The height-map file's problems (cosim.world.height_map), each at ``terrain.height_map_file``."""
    from cosim.world.height_map import HeightMapError, height_map_header, read_height_map

    t = s.terrain
    if t.height_map_file is None:
        return []
    key = ("terrain", "height_map_file")
    try:
        shape, _ = height_map_header(t.height_map_file)
        if t.roughness_rms_m > 0.0 and max(shape) ** 2 > MAX_TERRAIN_CELLS:
            return [(key, f"roughness over a {shape[0]:,} x {shape[1]:,} height map is drawn on a square of "
                          f"{max(shape):,} samples a side; at most {MAX_TERRAIN_CELLS:,} samples fit: use a "
                          "squarer or smaller map, or no roughness_rms_m")]
        read_height_map(t.height_map_file)
    except HeightMapError as exc:
        return [(key, f"{str(t.height_map_file)!r}: {exc}")]
    return []


def size_problems(s: Scenario, free: tuple | None = None) -> list[Problem]:
    """Every problem of this module (cameras, then the ground)."""
    return camera_problems(s, free) + terrain_problems(s)
