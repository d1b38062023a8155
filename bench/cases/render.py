"""The camera renderer: throughput on the default scene, and the rig the planner picks.

``render_fps``: the renderer participant in-process over ``Segment.local`` (the code path of a run: scene from the
dynamics blocks, upload, draw, ``read_into`` the image blocks under their seqlocks) on the default scenario's sample
frame moving at the harvest speed, for 640 x 480 and 1024 x 768, one and two cameras, RGB, float depth, the
auto-planned rig and the mock renderer; and the auto-planned rig on the frames of a run (the states, height maps
and streams the dynamics participant writes from frame :data:`RUN_FIRST_FRAME` on, ground-truth feedback), once
more without the grain surface (wrong images: the surface's share). The sample frame's pile is a cone on a flat
fill, so most of its surface merges into large triangles (``renderer_proc.gl.hfmesh``); a run's fill leaves few blocks
flat and costs more. llvmpipe reads ``LP_NUM_THREADS`` and ``LP_NATIVE_VECTOR_WIDTH``; the renderer sets neither.

``rig_plan``: the cameras and pixels the rig planner picks for a LiDAR pattern and angular error bound (fewest
cameras, then fewest pixels), and the measured worst nearest-pixel angular error over the beam table.
"""
from __future__ import annotations

import math
import statistics
import time

from harness import Context, case

__all__ = ["render_fps", "renderer_frames", "rig_plan", "run_frames", "triangles"]

#: untimed frames before timing (shader compilation, first allocation)
WARMUP_FRAMES = 5
#: first dynamics frame of the "run frames" rows (30 s into the default fill: a heaped, rough grain surface)
RUN_FIRST_FRAME = 300
#: (backend, width, height, cameras (0: the auto rig), render settings) of the sample-frame rows
CONFIGS = (("gl", 640, 480, 1, {}), ("gl", 640, 480, 2, {}), ("gl", 1024, 768, 1, {}), ("gl", 1024, 768, 2, {}),
           ("gl", 640, 480, 1, {"rgb": "on"}), ("gl", 640, 480, 1, {"float_depth": True}), ("gl", 0, 0, 0, {}),
           ("mock", 320, 240, 1, {}))


def run_frames(s, count: int) -> list:
    """``count`` consecutive (dyn_state mapping, heightmap, stream) of scenario ``s`` from frame RUN_FIRST_FRAME, as
    the dynamics participant writes them (ground-truth feedback, no renderer)."""
    from cosim.runtime.specs import build_schema, ring_specs
    from dynamics_proc.participant import create as create_dynamics
    from shm_schema import Segment

    g = s.model_copy(update={"feedback": "ground_truth", "renderer": "none"})
    seg = Segment.local(build_schema(g, ring_specs(g)), frames=RUN_FIRST_FRAME + count)
    p = create_dynamics(g)
    p.start(seg)
    out = []
    try:
        for k in range(RUN_FIRST_FRAME + count):
            p.step(k)
            if k >= RUN_FIRST_FRAME:
                out.append((seg.view("dyn_state").as_dict(), seg.view("heightmap_truth").copy(),
                            seg.view("stream").copy()))
    finally:
        p.close()
    return out


def _without_grain(backend) -> None:
    """Make ``backend`` (a GLRenderer) skip the grain surface's draw call (uploads unchanged; diagnostic)."""
    draw = backend.draw

    def draw_without_grain(k, world_from_camera):
        surface = backend._surface
        count, surface.count = surface.count, 0
        try:
            draw(k, world_from_camera)
        finally:
            surface.count = count

    backend.draw = draw_without_grain


def renderer_frames(s, frames: int, source=None, grain: bool = True) -> dict:
    """Median wall ms, best wall ms and median process CPU ms (llvmpipe's threads included) per frame of the renderer
    participant of scenario ``s``; ``source``: the frames' (state, heights, stream), default the sample frame moving
    along; ``grain=False``: the grain surface not drawn."""
    from cosim.testing.renderer_inputs import dynamics_blocks, publish
    from cosim.world.rig import plan_rig
    from renderer_proc.blocks import declare_blocks
    from renderer_proc.participant import create
    from renderer_proc.sample import sample_frame
    from shm_schema import Schema, Segment

    if source is None:
        source = [sample_frame(s, t_s=0.1 * k) for k in range(frames + WARMUP_FRAMES)]
    state, heights, stream = source[0]
    seg = Segment.local(Schema(dynamics_blocks(state, heights) + declare_blocks(s), ["dynamics", "renderer"]))
    p = create(s)
    p.start(seg)
    if not grain:
        _without_grain(p.backend)
    times, cpu = [], []
    try:
        for k in range(frames + WARMUP_FRAMES):
            publish(seg, *source[k], k)
            t0, c0 = time.perf_counter(), time.process_time()
            p.step(k)
            if k >= WARMUP_FRAMES:
                times.append((time.perf_counter() - t0) * 1e3)
                cpu.append((time.process_time() - c0) * 1e3)
    finally:
        p.close()
    rig = plan_rig(s)
    med = statistics.median(times)
    return {"cameras": " + ".join(f"{c.intrinsics.width}x{c.intrinsics.height}" for c in rig.cameras),
            "wall ms/frame": med, "frames/s": 1e3 / med, "best wall ms": min(times), "CPU ms/frame": statistics.median(cpu)}


def triangles(s) -> dict:
    """Triangles drawn per camera of the default scene's sample frame (flat blocks merged, hidden floor top left
    out) and of the full scene (every grid triangle and box face)."""
    from cosim.world.heightfield import padded_heights
    from cosim.world.meshes import unit_cube, unit_cylinder
    from cosim.world.scene import scene_from_state
    from renderer_proc.gl.hfmesh import SurfaceMesh
    from renderer_proc.sample import sample_frame

    state, h, stream = sample_frame(s)
    sc = scene_from_state(s, state, h, stream)
    nx, ny = h.shape
    hf = sc.heightfield
    merged = len(SurfaceMesh(nx, ny, hf.cell_m, hf.length_m, hf.width_m).triangles(padded_heights(h))[0])
    rest = len(sc.cylinders) * len(unit_cylinder()[1]) + sum(len(m.faces) for m in sc.meshes)
    boxes = len(sc.boxes) * len(unit_cube()[1])
    hidden = 0 if sc.boxes.hidden_top is None else int(sc.boxes.hidden_top.sum())
    drawn = rest + boxes - hidden * (len(unit_cube()[1]) - len(unit_cube(open_top=True)[1])) + merged
    return {"drawn": drawn, "full scene": rest + boxes + 2 * (nx + 1) * (ny + 1)}


@case("render_fps", "camera renderer throughput: render + read into shared memory per frame, rigs and outputs",
      options={"frames": 60, "configs": "all"}, quick={"frames": 2, "configs": "gl-640x480x1,mock"},
      compare=("wall ms/frame", "CPU ms/frame"))
def render_fps(ctx: Context) -> dict:
    """Every configuration of :data:`CONFIGS` on ``frames`` timed frames (mock: a twentieth, at least 3), then the
    run frames with and without the grain surface; ``configs``: "all" or comma-separated row prefixes."""
    from cosim.scenario.config import Scenario

    frames, want = ctx["frames"], ctx["configs"]
    rows = {}
    for backend, w, h, n, extra in CONFIGS:
        render = {"rig": "auto"} if n == 0 else {"rig": "fixed", "cameras": n, "width_px": w, "height_px": h,
                                                   "hfov_deg": 60.0}
        label = f"{backend}-" + ("auto" if n == 0 else f"{w}x{h}x{n}") + "".join(f", {k}={v}" for k, v in extra.items())
        if want != "all" and not any(label.startswith(x) for x in want.split(",")):
            continue
        s = Scenario.model_validate({"format_version": 1, "renderer": backend, "render": {**render, **extra}})
        rows[label] = renderer_frames(s, frames if backend == "gl" else max(3, frames // 20))
    if want == "all" or "run" in want.split(","):
        s = Scenario.model_validate({"format_version": 1, "renderer": "gl", "render": {"rig": "auto"}})
        source = run_frames(s, frames + WARMUP_FRAMES)
        for grain in (True, False):
            label = f"gl-auto, run frames {RUN_FIRST_FRAME}+" + ("" if grain else ", grain surface not drawn")
            rows[label] = renderer_frames(s, frames, source, grain=grain)
    return {"renderer frames": rows, "default scene's sample frame": {"triangles": triangles(Scenario(format_version=1))}}


#: patterns of ``rig_plan``: label -> sensor.pattern settings
PATTERNS = {
    "default honeycomb 90 x 95 deg, 240 x 160": {},
    "grid 120 x 40 deg, 480 x 64": {"preset": "grid", "azimuth_min_deg": -60.0, "azimuth_max_deg": 60.0,
                                    "elevation_min_deg": -20.0, "elevation_max_deg": 20.0,
                                    "azimuth_count": 480, "elevation_count": 64},
    "grid 200 x 30 deg, 800 x 32": {"preset": "grid", "azimuth_min_deg": -100.0, "azimuth_max_deg": 100.0,
                                    "elevation_min_deg": -15.0, "elevation_max_deg": 15.0,
                                    "azimuth_count": 800, "elevation_count": 32},
}


@case("rig_plan", "the cameras and pixels the rig planner picks for a LiDAR pattern and angular error bound",
      options={"bounds": "0.05,0.1,0.2,0.5"}, quick={"bounds": "0.2"})
def rig_plan(ctx: Context) -> dict:
    """Each pattern of :data:`PATTERNS` at each bound (deg): the rig, its pixels, the worst error, planning time."""
    from cosim.scenario.config import Scenario
    from cosim.world.rig import beam_angles, beam_pixel_error, plan_rig

    rows = {}
    for label, pattern in PATTERNS.items():
        for bound in (float(b) for b in str(ctx["bounds"]).split(",")):
            s = Scenario.model_validate({"format_version": 1, "sensor": {"pattern": pattern,
                                                                         "max_angular_error_deg": bound}})
            t0 = time.perf_counter()
            rig = plan_rig(s)
            ms = (time.perf_counter() - t0) * 1e3
            el, az = beam_angles(s.sensor.pattern)
            err, cam = beam_pixel_error(rig, el, az)
            if not (cam >= 0).all():
                raise RuntimeError(f"{label} at {bound} deg: beams no camera sees")
            rows[f"{label}, bound {bound:g} deg"] = {
                "cameras": len(rig), "sizes": ", ".join(f"{c.intrinsics.width}x{c.intrinsics.height}"
                                                         for c in rig.cameras),
                "pixels": sum(c.intrinsics.width * c.intrinsics.height for c in rig.cameras),
                "worst error deg": math.degrees(float(err.max())), "plan ms": ms}
    return {"planned rigs": rows}
