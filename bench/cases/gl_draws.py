"""The GL beam-native renderer's draw calls on sample frames of the default scene
(``renderer_proc.sample.sample_frame`` at times spread over ``span`` simulated seconds).

``beam_solids``: the convex solids. Each frame is drawn once (``GLBeamRenderer.draw``), then each solid draw (the
boxes, those with a covered top included, and the cylinders) again alone: fragments shaded (with ``solid.frag``
replaced by a constant write, no discard, and the depth test off, an occlusion query counts every fragment of the
geometry shader's rectangles), CPU of the draw and ``ctx.finish()`` (process CPU time, llvmpipe's threads included,
median of ``reps``), and of the same draw with ``GL_RASTERIZER_DISCARD`` on (the vertex and geometry shaders alone).

``beam_surface``: the grain surface's draw, grid quads (``SurfaceMesh.quads``, ``renderer_proc/gl/surface.py``)
against single triangles, interleaved per frame: surface CPU per draw (``reps`` draws after the frame's ``draw``),
fragments shaded (occlusion query over a twin renderer whose fragment shaders write a constant) and primitives; the
two paths' images are compared byte for byte and against the exact ray cast. Frames: ``sample`` and ``rough`` (the
same poses with a rough mid-run heap: random cones and 1-3 cm steps, nearly every merge block fine).
"""
from __future__ import annotations

import statistics
import time

from harness import Context, case

__all__ = ["beam_solids", "beam_surface", "rough_heights", "solid_draws", "surface_paths"]

#: GL_RASTERIZER_DISCARD: primitives end after the geometry shader (its cost alone)
RASTERIZER_DISCARD = 0x8C89
#: a fragment shader that shades every fragment its rectangle makes (no discard)
CONSTANT_FRAG = "#version 330\nlayout(location = 0) out uvec4 o_encoded;\nvoid main() { o_encoded = uvec4(1u); }\n"


def solid_draws(frames: int, span: float, reps: int) -> dict[str, list[float]]:
    """Per frame: ``{draw}_frags``, ``{draw}_ms`` and ``{draw}_geom_ms`` of each solid draw (boxes, cylinders)."""
    import numpy as np

    import renderer_proc.gl.beam as beam_gl
    from cosim.scenario.config import Scenario
    from cosim.world.beamtarget import beam_layout
    from cosim.world.scene import scene_from_state
    from renderer_proc.gl.backend import create_gl_context
    from renderer_proc.projection import world_from_sensor
    from renderer_proc.sample import sample_frame

    sc = Scenario(format_version=1)
    lay, ctx = beam_layout(sc.sensor.pattern), create_gl_context()
    real = beam_gl.GLBeamRenderer(lay, sc.sensor.codec, context=ctx)
    assemble = beam_gl._assemble
    beam_gl._assemble = lambda name, *a, **k: CONSTANT_FRAG if name == "solid.frag" else assemble(name, *a, **k)
    try:
        count = beam_gl.GLBeamRenderer(lay, sc.sensor.codec, context=ctx)
    finally:
        beam_gl._assemble = assemble
    draws = {"boxes": [k for k in real._units if k.startswith("box")], "cylinders": ["cyl"]}
    out: dict[str, list[float]] = {}
    for t in np.linspace(0.0, span, frames):
        state, heights, stream = sample_frame(sc, float(t))
        scene, pose = scene_from_state(sc, state, heights, stream), world_from_sensor(sc, state)
        for r in (real, count):
            r.set_scene(scene)
            r.draw(0, pose)
        for draw, units in draws.items():
            real._frame.draw.use()
            for key, discard in (("ms", False), ("geom_ms", True)):
                if discard:
                    ctx.enable_direct(RASTERIZER_DISCARD)
                ms = []
                for _ in range(reps):
                    ctx.finish()
                    c0 = time.process_time()
                    for u in units:
                        real._render(u)
                    ctx.finish()
                    ms.append(1e3 * (time.process_time() - c0))
                if discard:
                    ctx.disable_direct(RASTERIZER_DISCARD)
                out.setdefault(f"{draw}_{key}", []).append(statistics.median(ms))
            count._frame.draw.use()
            ctx.disable(ctx.DEPTH_TEST)
            q = ctx.query(samples=True)
            with q:
                for u in units:
                    count._render(u)
            out.setdefault(f"{draw}_frags", []).append(q.samples)
    return out


@case("beam_solids", "the beam-native GL renderer's convex solids: fragments shaded and CPU of the box and cylinder "
      "draws", options={"frames": 10, "span": 8.0, "reps": 5}, quick={"frames": 1, "reps": 1}, rounds=4)
def beam_solids(ctx: Context) -> dict:
    """Medians over ``frames`` sample frames of each solid draw (module docstring)."""
    med = {k: statistics.median(v) for k, v in solid_draws(ctx["frames"], ctx["span"], ctx["reps"]).items()}
    return {"solid draws, per frame": {d: {"fragments": med[f"{d}_frags"], "CPU ms": med[f"{d}_ms"],
                                           "of which geometry ms": med[f"{d}_geom_ms"]} for d in ("boxes", "cylinders")}}


def rough_heights(sc, heights, seed: int):
    """A rough mid-run heap (nx, ny) float32 m: cones of random height and place on the sample fill, plus steps
    of 1-3 cm on a random 60 % of the cells, clipped to the cart's depth."""
    import numpy as np

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


def _surface_renderers(lay, codec, ctx, quads: bool):
    """(renderer, counting twin) for one surface path."""
    from unittest import mock

    from renderer_proc.gl import beam as beam_gl

    real = beam_gl.GLBeamRenderer(lay, codec, context=ctx, surface_quads=quads)
    src = beam_gl._src
    constant = {"beam.frag", "beam_quad.frag"}
    with mock.patch.object(beam_gl, "_src", lambda n: CONSTANT_FRAG if n in constant else src(n)):
        twin = beam_gl.GLBeamRenderer(lay, codec, context=ctx, surface_quads=quads)
    return real, twin


def _surface_frame(real, twin, scene, pose, reps: int, img) -> tuple[float, int]:
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


def surface_paths(frames: int, span: float, reps: int, context=None) -> dict:
    """The ``beam_surface`` sample (module docstring); ``context``: a GL context to draw in (default a new one)."""
    import numpy as np

    from cosim.scenario.config import Scenario
    from cosim.world.beamtarget import beam_layout
    from cosim.world.scene import scene_from_state
    from renderer_proc.codec import decode_depth
    from renderer_proc.gl.backend import create_gl_context
    from renderer_proc.mock.beam import beam_ranges
    from renderer_proc.projection import world_from_sensor
    from renderer_proc.sample import sample_frame

    sc = Scenario(format_version=1, sensor={"method": "beam_native"})
    lay, codec = beam_layout(sc.sensor.pattern), sc.sensor.codec
    ctx = context if context is not None else create_gl_context()
    paths = {"triangles": _surface_renderers(lay, codec, ctx, False), "quads": _surface_renderers(lay, codec, ctx, True)}
    img = {k: np.zeros(lay.shape + (4,), np.uint8) for k in paths}
    rows, checks = {}, {}
    for kind in ("sample", "rough"):
        cpu, frags, prims = ({k: [] for k in paths} for _ in range(3))
        same, err = [], []
        for i, t in enumerate(np.linspace(0.0, span, frames)):
            state, heights, stream = sample_frame(sc, float(t))
            if kind == "rough":
                heights = rough_heights(sc, heights, seed=i)
            scene, pose = scene_from_state(sc, state, heights, stream), world_from_sensor(sc, state)
            for k in (list(paths) if i % 2 == 0 else list(paths)[::-1]):
                c, n = _surface_frame(*paths[k], scene, pose, reps, img[k])
                cpu[k].append(c)
                frags[k].append(n)
                prims[k].append(paths[k][0]._surface.primitives)
            same.append(float(np.mean(np.all(img["quads"] == img["triangles"], axis=2))))
            exact = beam_ranges(scene, pose, lay.directions)
            got = lay.beams_of(decode_depth(img["quads"], codec))
            ok = np.isfinite(exact) & (exact < codec.max_depth_m) & np.isfinite(got)
            err.append(float(np.abs(got - exact)[ok].max()))
        for k in paths:
            rows[f"{kind}, {k}"] = {"primitives drawn": statistics.median(prims[k]),
                                    "fragments shaded": statistics.median(frags[k]),
                                    "surface CPU ms/draw": statistics.median(cpu[k])}
        rows[f"{kind}, quads / triangles"] = {
            "fragments shaded": statistics.median(frags["quads"]) / statistics.median(frags["triangles"]),
            "surface CPU ms/draw": statistics.median(cpu["quads"]) / statistics.median(cpu["triangles"])}
        checks[kind] = {"% beams byte-identical (worst frame)": 100.0 * min(same),
                        "max error against the exact cast mm": 1e3 * max(err)}
    return {"grain surface draw, per frame": rows, "quads against triangles, checks": checks}


@case("beam_surface", "the beam-native GL grain surface, quads against triangles: fragments shaded and draw CPU",
      options={"frames": 20, "span": 8.0, "reps": 20}, quick={"frames": 1, "reps": 1})
def beam_surface(ctx: Context) -> dict:
    """Both surface paths on ``frames`` sample and rough frames (module docstring)."""
    return surface_paths(ctx["frames"], ctx["span"], ctx["reps"])
