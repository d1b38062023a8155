"""Convex solids of the GL beam-native renderer: fragments shaded and CPU per frame of the box
and cylinder draws, for one source tree or several interleaved (A/B).

For each of ``--frames`` sample frames of the default scene (``renderer_proc.sample.sample_frame`` at times spread
over ``--span`` s) the LiDAR's frame is drawn once (``GLBeamRenderer.draw``), then each solid draw (the boxes, the
boxes with a covered top where the tree has them, the cylinders) again alone:

* fragments: with ``solid.frag`` replaced by a constant write (no discard) and the depth test off, an occlusion
  query (``ctx.query(samples=True)``) counts every fragment the geometry shader's rectangles make;
* CPU: process CPU time (llvmpipe's threads included) of the draw and ``ctx.finish()``, median of ``--reps``;
  and of the same draw with ``GL_RASTERIZER_DISCARD`` on (the vertex and geometry shaders alone).

Each tree runs in its own process (``--tree name=path``, its code first on sys.path), the order alternating per
round (A B, B A, ...); medians over frames and rounds. Prints Markdown. Usage::

    python bench/beam_solids.py --tree main=/work/main --tree new=. --rounds 4 --frames 10
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

#: GL_RASTERIZER_DISCARD: primitives end after the geometry shader (its cost alone)
RASTERIZER_DISCARD = 0x8C89
#: a fragment shader that shades every fragment its rectangle makes (no discard)
COUNT_FRAG = "#version 330\nlayout(location = 0) out uvec4 o_encoded;\nvoid main() { o_encoded = uvec4(1u); }\n"


def measure(frames: int, span: float, reps: int) -> dict[str, list[float]]:
    """In the tree first on sys.path: per frame, {draw}_frags and {draw}_ms of each solid draw."""
    import numpy as np

    import renderer_proc.beam_gl as beam_gl
    from cosim.scenario.config import Scenario
    from cosim.world.beamtarget import beam_layout
    from cosim.world.scene import scene_from_state
    from renderer_proc.gl_backend import create_gl_context
    from renderer_proc.projection import world_from_sensor
    from renderer_proc.sample import sample_frame

    sc = Scenario(format_version=1)
    lay, ctx = beam_layout(sc.sensor.pattern), create_gl_context()
    real = beam_gl.GLBeamRenderer(lay, sc.sensor.codec, context=ctx)
    assemble = beam_gl._assemble
    beam_gl._assemble = lambda name, *a, **k: COUNT_FRAG if name == "solid.frag" else assemble(name, *a, **k)
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


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", action="append", default=[], help="name=path (default: this tree)")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--span", type=float, default=8.0, help="simulated seconds the sample frames spread over")
    ap.add_argument("--reps", type=int, default=5, help="timed repeats of each draw per frame")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        sys.path.insert(0, a.worker)
        print(json.dumps(measure(a.frames, a.span, a.reps)))
        return
    trees = dict(t.split("=", 1) for t in a.tree) or {"this": str(Path(__file__).resolve().parents[1])}
    got: dict[str, dict[str, list[float]]] = {n: {} for n in trees}
    names = list(trees)
    for i in range(a.rounds):
        for name in names if i % 2 == 0 else names[::-1]:
            path = str(Path(trees[name]).resolve())
            cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", path, "--frames", str(a.frames),
                   "--span", str(a.span), "--reps", str(a.reps)]
            res = json.loads(subprocess.run(cmd, cwd=path, check=True, capture_output=True, text=True).stdout)
            for k, v in res.items():
                got[name].setdefault(k, []).extend(v)
    load = os.getloadavg()[0]
    print(f"Default scene, {a.frames} sample frames over {a.span:g} s x {a.rounds} rounds, trees interleaved per "
          f"round; {os.cpu_count()} cores, load {load:.1f}, {datetime.now():%Y-%m-%d %H:%M}, "
          f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}\n")
    print("| tree | box fragments | box CPU ms | of which geometry ms | cylinder fragments | cylinder CPU ms | "
          "of which geometry ms |")
    print("|---|---|---|---|---|---|---|")
    for name in names:
        g = got[name]
        med = {k: statistics.median(v) for k, v in g.items()}
        print(f"| {name} | {med['boxes_frags']:.0f} | {med['boxes_ms']:.3f} | {med['boxes_geom_ms']:.3f} | "
              f"{med['cylinders_frags']:.0f} | {med['cylinders_ms']:.3f} | {med['cylinders_geom_ms']:.3f} |")


if __name__ == "__main__":
    main()
