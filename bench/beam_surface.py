"""The grain surface's draw in the GL beam-native renderer: grid quads against triangles.

Two GL beam-native renderers in one context, ``quads`` (``SurfaceMesh.quads``: a quad's two triangles bounded and
tested at once, ``renderer_proc/surface_gl.py``) and ``triangles`` (every triangle of
``SurfaceMesh.triangles`` through the triangle path), draw the same frames, interleaved per frame (A B, B A,
...). Per frame and renderer:

* surface CPU: after the frame's ``draw`` (uniforms, target bound), the surface alone drawn ``--reps`` times with
  ``ctx.finish()``; process CPU time (every thread, llvmpipe's included) per draw, ms;
* fragments shaded: an occlusion query (depth test off) over the surface drawn by a twin renderer whose fragment
  shaders write a constant (no discard), i.e. the beam pixels of every emitted rectangle;
* the surface's beams (depth test on, whole frame) must agree: the two renderers' images are compared byte for byte
  and against the exact ray cast (``renderer_proc.beam_mock.beam_ranges``).

Frames: ``sample``, ``--frames`` sample frames of the default scene (``renderer_proc.sample.sample_frame`` over
``--span`` s); ``rough``, the same poses with a rough mid-run heap (random cones and 1-3 cm steps over most of the
cart: nearly every merge block fine). Prints Markdown (medians). Usage::

    python bench/beam_surface.py --frames 20 [--reps 20]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from datetime import datetime
from pathlib import Path
from unittest import mock

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from cosim.scenario.config import Scenario  # noqa: E402
from cosim.world.beamtarget import beam_layout  # noqa: E402
from cosim.world.scene import scene_from_state  # noqa: E402
from renderer_proc import beam_gl  # noqa: E402
from renderer_proc.beam_mock import beam_ranges  # noqa: E402
from renderer_proc.codec import decode_depth  # noqa: E402
from renderer_proc.gl_backend import create_gl_context  # noqa: E402
from renderer_proc.projection import world_from_sensor  # noqa: E402
from renderer_proc.sample import sample_frame  # noqa: E402

#: the counting twins' fragment shader: every fragment of every emitted rectangle writes, none is discarded
CONSTANT_FRAG = "#version 330\nlayout(location = 0) out uvec4 o_encoded;\nvoid main() { o_encoded = uvec4(1u); }\n"


def rough_heights(sc: Scenario, heights: np.ndarray, seed: int) -> np.ndarray:
    """A rough mid-run heap (nx, ny) float32 m: cones of random height and place on the sample fill, plus steps
    of 1-3 cm on a random 60 % of the cells, clipped to the cart's depth."""
    rng = np.random.default_rng(seed)
    nx, ny = heights.shape
    cell = sc.grain.cell_m
    x, y = np.meshgrid((np.arange(nx) + 0.5) * cell, (np.arange(ny) + 0.5) * cell, indexing="ij")
    h = heights.astype(np.float64).copy()
    for _ in range(6):
        cx, cy, top = rng.uniform(0, nx * cell), rng.uniform(0, ny * cell), rng.uniform(0.2, 0.8)
        h = np.maximum(h, sc.grain.initial_fill_m + top - np.hypot(x - cx, y - cy) * np.tan(sc.crop.repose_rad))
    h += np.where(rng.random(h.shape) < 0.6, rng.choice([0.01, 0.02, 0.03], h.shape), 0.0)
    return np.minimum(h, sc.cart.interior_depth_m).astype(np.float32)


def renderers(lay, codec, ctx, quads: bool):
    """(renderer, counting twin) for one surface path."""
    real = beam_gl.GLBeamRenderer(lay, codec, context=ctx, surface_quads=quads)
    src = beam_gl._src
    constant = {"beam.frag", "beam_quad.frag"}
    with mock.patch.object(beam_gl, "_src", lambda n: CONSTANT_FRAG if n in constant else src(n)):
        twin = beam_gl.GLBeamRenderer(lay, codec, context=ctx, surface_quads=quads)
    return real, twin


def measure(real, twin, scene, pose, reps: int, img: np.ndarray) -> tuple[float, int]:
    """(surface CPU ms per draw, fragments shaded) of one frame; ``img`` gets the real renderer's frame."""
    ctx = real.ctx
    real.set_scene(scene)
    real.draw(0, pose)
    real.read_depth(0, img)
    real.draw(0, pose)
    ctx.finish()
    c0 = time.process_time()
    for _ in range(reps):
        real._surface.render()
        ctx.finish()
    cpu = 1e3 * (time.process_time() - c0) / reps
    twin.set_scene(scene)
    twin.draw(0, pose)
    ctx.disable(ctx.DEPTH_TEST)
    q = ctx.query(samples=True)
    with q:
        twin._surface.render()
    ctx.enable(ctx.DEPTH_TEST)
    return cpu, q.samples


def main(argv: list[str] | None = None, context=None) -> None:
    """Run the benchmark and print its table; ``context``: a GL context to draw in (default: a new one)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--span", type=float, default=8.0, help="simulated seconds the sample frames spread over")
    ap.add_argument("--reps", type=int, default=20, help="surface draws timed per frame and path")
    a = ap.parse_args(argv)
    sc = Scenario(format_version=1, sensor={"method": "beam_native"})
    lay, codec = beam_layout(sc.sensor.pattern), sc.sensor.codec
    ctx = context if context is not None else create_gl_context()
    paths = {"triangles": renderers(lay, codec, ctx, False), "quads": renderers(lay, codec, ctx, True)}
    img = {k: np.zeros(lay.shape + (4,), np.uint8) for k in paths}
    rows = []
    for kind in ("sample", "rough"):
        cpu = {k: [] for k in paths}
        frags = {k: [] for k in paths}
        prims = {k: [] for k in paths}
        same, err = [], []
        for i, t in enumerate(np.linspace(0.0, a.span, a.frames)):
            state, heights, stream = sample_frame(sc, float(t))
            if kind == "rough":
                heights = rough_heights(sc, heights, seed=i)
            scene, pose = scene_from_state(sc, state, heights, stream), world_from_sensor(sc, state)
            for k in (list(paths) if i % 2 == 0 else list(paths)[::-1]):
                c, n = measure(*paths[k], scene, pose, a.reps, img[k])
                cpu[k].append(c)
                frags[k].append(n)
                prims[k].append(paths[k][0]._surface.primitives)
            same.append(np.mean(np.all(img["quads"] == img["triangles"], axis=2)))
            exact = beam_ranges(scene, pose, lay.directions)
            got = lay.beams_of(decode_depth(img["quads"], codec))
            ok = np.isfinite(exact) & (exact < codec.max_depth_m) & np.isfinite(got)
            err.append(float(np.abs(got - exact)[ok].max()))
        for k in paths:
            rows.append(f"| {kind} | {k} | {statistics.median(prims[k]):.0f} | {statistics.median(frags[k]):.0f} | "
                        f"{statistics.median(cpu[k]):.3f} |")
        rows.append(f"| {kind} | quads / triangles | | "
                    f"{statistics.median(frags['quads']) / statistics.median(frags['triangles']):.2f}x | "
                    f"{statistics.median(cpu['quads']) / statistics.median(cpu['triangles']):.2f}x |")
        rows.append(f"| {kind} | check | min byte-identical beams {100 * min(same):.3f} % | max error vs exact cast "
                    f"{1e3 * max(err):.2f} mm | |")
    print(f"GL beam-native grain surface, default scene and pattern ({lay.n_beams} beams), {a.frames} frames per "
          f"kind, {a.reps} surface draws timed per frame and path, interleaved; {os.cpu_count()} cores, "
          f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}, {datetime.now():%Y-%m-%d %H:%M}; medians.\n")
    print("| frames | surface path | primitives drawn | fragments shaded | surface CPU ms/draw |")
    print("|---|---|---:|---:|---:|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
