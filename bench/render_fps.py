"""Renderer throughput: render plus read into shared memory, per frame, on the default scene.

Runs the renderer participant in-process over ``Segment.local`` (the same code path as a run: scene from the
dynamics blocks, upload, draw, ``read_into`` the image blocks under their seqlocks) on the sample frame of
the default scenario, for 640 x 480 and 1024 x 768, one and two cameras, plus the auto-planned rig and the
mock renderer; and the auto-planned rig on the frames of a run ("run frames": the states, height maps and streams
the dynamics participant produces from ``RUN_FIRST_FRAME`` on, ground-truth feedback). The sample frame's pile is
a cone on a flat fill, so most of its grain surface merges into large triangles (``renderer_proc.hfmesh``); a
run's fill model leaves few blocks flat, so its surface keeps most of the grid and it costs more; a diagnostic row
renders the same run frames without the grain surface (wrong images), to put a number on the surface's share.
Prints a Markdown table with the load average before and after (on a shared machine the "best" and CPU columns
are the steadier figures). Usage: ``python bench/render_fps.py [--frames N]``.

llvmpipe reads ``LP_NUM_THREADS`` (rasteriser threads, default: one per CPU) and ``LP_NATIVE_VECTOR_WIDTH``;
the renderer sets neither (on 2 cores neither 0-4 threads nor 128-bit vectors beat the defaults measurably).
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


import numpy as np  # noqa: E402  (after the sys.path line above)

from cosim.scenario.config import Scenario  # noqa: E402
from cosim.world.heightfield import padded_heights  # noqa: E402
from cosim.world.meshes import unit_cube, unit_cylinder  # noqa: E402
from cosim.world.rig import plan_rig  # noqa: E402
from cosim.world.scene import scene_from_state  # noqa: E402
from renderer_proc.blocks import declare_blocks  # noqa: E402
from renderer_proc.hfmesh import SurfaceMesh  # noqa: E402
from renderer_proc.participant import create  # noqa: E402
from renderer_proc.sample import sample_frame  # noqa: E402
from shm_schema import ArrayBlock, Field, Schema, Segment, StructBlock  # noqa: E402

#: untimed frames before timing (shader compilation, first allocation)
WARMUP_FRAMES = 5
#: first dynamics frame of the "run frames" row (30 s into the default fill: a heaped, rough grain surface)
RUN_FIRST_FRAME = 300


def run_frames(s: Scenario, count: int) -> list[tuple[dict, "np.ndarray", "np.ndarray"]]:
    """``count`` consecutive (dyn_state mapping, heightmap, stream) of the default scenario from frame
    RUN_FIRST_FRAME, as the dynamics participant writes them (ground-truth feedback, no renderer)."""
    from cosim.runtime.specs import build_schema, ring_specs
    from dynamics_proc.participant import create as create_dynamics

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


def triangles(s: Scenario) -> tuple[int, int]:
    """(triangles drawn per camera, triangles of the full scene) for the default scene's sample frame: the
    grain surface with its flat blocks merged (``renderer_proc.hfmesh``) and without the hidden floor top,
    against every grid triangle and every box face."""
    state, h, stream = sample_frame(s)
    sc = scene_from_state(s, state, h, stream)
    nx, ny = h.shape
    hf = sc.heightfield
    merged = len(SurfaceMesh(nx, ny, hf.cell_m, hf.length_m, hf.width_m).triangles(padded_heights(h))[0])
    rest = len(sc.cylinders) * len(unit_cylinder()[1]) + sum(len(m.faces) for m in sc.meshes)
    boxes = len(sc.boxes) * len(unit_cube()[1])
    hidden = 0 if sc.boxes.hidden_top is None else int(sc.boxes.hidden_top.sum())
    drawn = rest + boxes - hidden * (len(unit_cube()[1]) - len(unit_cube(open_top=True)[1])) + merged
    return drawn, rest + boxes + 2 * (nx + 1) * (ny + 1)


def _without_grain(backend) -> None:
    """Diagnostic: make ``backend`` (a GLRenderer) skip the grain surface's draw call (uploads unchanged), so
    the difference to a normal row is what the surface costs. The images are then wrong (the cart floor shows)."""
    draw = backend.draw

    def draw_without_grain(k, world_from_camera):
        surface = backend._surface
        count, surface.count = surface.count, 0
        try:
            draw(k, world_from_camera)
        finally:
            surface.count = count

    backend.draw = draw_without_grain


def measure(s: Scenario, frames: int, source=None, grain: bool = True) -> tuple[float, float, float, str]:
    """(median wall ms per frame, best wall ms, median CPU ms per frame of the whole process, including
    llvmpipe's rasteriser threads, rig description) for scenario ``s``. On a shared machine the CPU time is
    the steadier figure: wall time rises with other load, CPU time much less. ``source``: the frames'
    (state, heights, stream), default the sample frame moving along at the harvest speed. ``grain=False``:
    the grain surface is not drawn (diagnostic, :func:`_without_grain`)."""
    if source is None:
        source = [sample_frame(s, t_s=0.1 * k) for k in range(frames + WARMUP_FRAMES)]
    state, heights, stream = source[0]
    dyn = [StructBlock("dyn_state", "dynamics", tuple(Field(k, "", "i8" if k == "stream_points" else "f8")
                                                      for k in state)),
           ArrayBlock("heightmap_truth", "dynamics", "f4", heights.shape),
           ArrayBlock("stream", "dynamics", "f4", (64, 4))]
    seg = Segment.local(Schema(dyn + declare_blocks(s), ["dynamics", "renderer"]))
    p = create(s)
    p.start(seg)
    if not grain:
        _without_grain(p.backend)
    times, cpu = [], []
    try:
        for k in range(frames + WARMUP_FRAMES):
            state, heights, stream = source[k]
            with seg.write("dyn_state", k) as v:
                v.update({n: int(x) if n == "stream_points" else x for n, x in state.items()})
            with seg.write("heightmap_truth", k) as v:
                v[...] = heights
            with seg.write("stream", k) as v:
                v[...] = stream
            t0, c0 = time.perf_counter(), time.process_time()
            p.step(k)
            if k >= WARMUP_FRAMES:
                times.append((time.perf_counter() - t0) * 1e3)
                cpu.append((time.process_time() - c0) * 1e3)
    finally:
        p.close()
    rig = plan_rig(s)
    desc = " + ".join(f"{c.intrinsics.width}x{c.intrinsics.height}" for c in rig.cameras)
    return statistics.median(times), min(times), statistics.median(cpu), desc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    args = ap.parse_args()
    base = Scenario(format_version=1)
    load0 = os.getloadavg()
    rows = []
    for backend, w, h, n, extra in [("gl", 640, 480, 1, {}), ("gl", 640, 480, 2, {}), ("gl", 1024, 768, 1, {}),
                                    ("gl", 1024, 768, 2, {}), ("gl", 640, 480, 1, {"rgb": "on"}),
                                    ("gl", 640, 480, 1, {"float_depth": True}), ("gl", 0, 0, 0, {}),
                                    ("mock", 320, 240, 1, {})]:
        render = {"rig": "auto"} if n == 0 else {"rig": "fixed", "cameras": n, "width_px": w, "height_px": h,
                                                   "hfov_deg": 60.0}
        s = Scenario.model_validate({"format_version": 1, "renderer": backend, "render": {**render, **extra}})
        frames = args.frames if backend == "gl" else max(3, args.frames // 20)
        med, best, cpu, desc = measure(s, frames)
        label = ", ".join(f"{k}={v}" for k, v in extra.items()) or "depth only"
        rows.append((backend, desc + (" (auto rig)" if n == 0 else ""), label, med, best, cpu))
    s = Scenario.model_validate({"format_version": 1, "renderer": "gl", "render": {"rig": "auto"}})
    source = run_frames(s, args.frames + WARMUP_FRAMES)
    label = f"run frames {RUN_FIRST_FRAME}-{RUN_FIRST_FRAME + args.frames + WARMUP_FRAMES - 1}"
    for grain in (True, False):
        med, best, cpu, desc = measure(s, args.frames, source, grain=grain)
        rows.append(("gl", desc + " (auto rig)", label + ("" if grain else ", grain surface not drawn (diagnostic)"),
                     med, best, cpu))
    load1 = os.getloadavg()
    drawn, full = triangles(base)
    print(f"Renderer benchmark: default scene ({drawn} triangles drawn of {full}), render + read into shared "
          f"memory; {platform.machine()}, {os.cpu_count()} CPUs, {frames_note(args.frames)}; load average "
          f"(1 min) {load0[0]:.2f} before, {load1[0]:.2f} after\n")
    print("| backend | cameras | outputs | wall ms/frame (median) | frames/s (median) | wall ms (best) | "
          "frames/s (best) | CPU ms/frame |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    for b, d, label, med, best, cpu in rows:
        print(f"| {b} | {d} | {label} | {med:.2f} | {1e3 / med:.0f} | {best:.2f} | {1e3 / best:.0f} | {cpu:.2f} |")


def frames_note(n: int) -> str:
    return f"{n} timed frames per GL row after {WARMUP_FRAMES} warm-up frames"


if __name__ == "__main__":
    main()
