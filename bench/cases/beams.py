"""The LiDAR's render + step on sample frames of the default scene (``renderer_proc.sample.sample_frame`` at times
spread over ``span`` simulated seconds, the vehicles driving), every arm interleaved per frame.

``beam_native``: the two sensor methods' render + LiDAR step on the same frames: ``camera_rig`` (the planned rig drawn,
every camera read, then perception's resample: decode, back-project, planar sampler) and ``beam_native`` (one
pixel per beam, read, the per-beam decode); process CPU time (every thread: llvmpipe's included) and wall time
per frame, and each method's range error against the exact ray cast of the same beams
(``renderer_proc.mock.beam.beam_ranges``) over every beam of every frame.

``mock_cast``: the beam-native mock renderer's frame (``set_scene`` + ``draw`` + ``read_depth``) with each ray caster
(``numpy``; ``embree``, the scene's triangles built every frame; ``embree-static``, the rigid bodies built once per
run, ``cosim.world.rigidcast``) against the GL beam-native renderer's, and how many beams' bytes equal the numpy
cast's. The heap is kept as in a run's processes (``cosim.runtime.heap``).

``mock_instructions``: one ray caster's mock frames counted under ``valgrind --tool=callgrind`` (deterministic,
independent of the machine's load; the first frame uncounted): instructions per frame; ``callgrind_annotate
--inclusive=yes`` on a kept dump (``keep``: a folder) splits out Embree's traversal (embreex's ``EmbreeScene.run``).
"""
from __future__ import annotations

import functools
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from harness import Context, case, rotating

__all__ = ["BeamNative", "CameraRig", "beam_native", "cast_costs", "cast_renderers", "mock_cast",
           "mock_frames_under_callgrind", "mock_instructions", "range_errors", "step_methods", "timed"]

#: the "large error" threshold and the working range, m
ABOVE_M, WORKING_M = 0.05, (2.0, 15.0)
#: the mock renderer's ray casters and the GL renderer
CAST_ARMS = ("numpy", "embree", "embree-static", "gl")


@functools.lru_cache(maxsize=1)
def _context():
    """One GL context for every renderer of the process (moderngl draws into the current context)."""
    from renderer_proc.gl.backend import create_gl_context

    return create_gl_context()


class CameraRig:
    """Render every rig camera and resample to the beams."""

    def __init__(self, sc, renderer: str = "gl"):
        import numpy as np

        from cosim.world.rig import plan_rig
        from perception_proc.pipeline import Perception

        sc = sc.model_copy(update={"renderer": renderer})
        self.sc, self.rig = sc, plan_rig(sc)
        if renderer == "gl":
            from renderer_proc.gl.backend import GLRenderer
            self.r = GLRenderer(self.rig, sc.sensor.codec, context=_context())
        else:
            from renderer_proc.mock.backend import MockRenderer
            self.r = MockRenderer(self.rig, sc.sensor.codec)
        self.pipe = Perception(sc, self.rig)
        self.imgs = [np.zeros((c.intrinsics.height, c.intrinsics.width, 4), np.uint8) for c in self.rig.cameras]

    def frame(self, scene, state):
        from renderer_proc.projection import camera_poses

        self.r.set_scene(scene)
        for k, pose in enumerate(camera_poses(self.sc, state, self.rig)):
            self.r.draw(k, pose)
            self.r.read_depth(k, self.imgs[k])
        return self.pipe.resample(self.imgs)


class BeamNative:
    """Render the beams and decode them."""

    def __init__(self, sc, renderer: str = "gl"):
        import numpy as np

        from cosim.world.beamtarget import beam_layout
        from perception_proc.pipeline import Perception
        from renderer_proc.mock.beam import MockBeamRenderer

        sc = sc.model_copy(update={"renderer": renderer,
                                   "sensor": sc.sensor.model_copy(update={"method": "beam_native"})})
        self.sc, self.lay = sc, beam_layout(sc.sensor.pattern)
        if renderer == "gl":
            from renderer_proc.gl.beam import GLBeamRenderer
            self.r = GLBeamRenderer(self.lay, sc.sensor.codec, context=_context())
        else:
            self.r = MockBeamRenderer(self.lay, sc.sensor.codec)
        self.pipe = Perception(sc, None)
        self.img = np.zeros(self.lay.shape + (4,), np.uint8)

    def frame(self, scene, state):
        from renderer_proc.projection import world_from_sensor

        self.r.set_scene(scene)
        self.r.draw(0, world_from_sensor(self.sc, state))
        self.r.read_depth(0, self.img)
        return self.pipe.resample([self.img])


def range_errors(ranges: list, exact: list, max_m: float) -> dict:
    """Range error figures (mm, counts) of ``ranges`` against ``exact`` (lists of (N,) arrays, m)."""
    import numpy as np

    r, x = np.concatenate(ranges).astype(np.float64), np.concatenate(exact)
    ok = np.isfinite(r) & np.isfinite(x) & (x < max_m)
    e = np.abs(r - x)[ok]
    w = (x[ok] >= WORKING_M[0]) & (x[ok] < WORKING_M[1])
    miss = np.isfinite(x) & (x < max_m * 254.5 / 255.0) & ~np.isfinite(r)
    above = int(np.count_nonzero(e[w] > ABOVE_M))
    return {"mean err mm": 1e3 * float(e.mean()), "p99 mm": 1e3 * float(np.percentile(e, 99)),
            "max mm": 1e3 * float(e.max()), "p99 in 2-15 m mm": 1e3 * float(np.percentile(e[w], 99)),
            "beams > 5 cm in 2-15 m": above, "% > 5 cm in 2-15 m": 100.0 * above / max(int(w.sum()), 1),
            "missing beams": int(miss.sum())}


def timed(method, scene, state):
    """(ranges (N,) float32 copy, CPU ms, wall ms) of one frame of ``method``."""
    c0, w0 = time.process_time(), time.perf_counter()
    r = method.frame(scene, state)
    return r.copy(), 1e3 * (time.process_time() - c0), 1e3 * (time.perf_counter() - w0)


def step_methods(frames: int, span: float, renderers: list[str], errors: bool = True) -> dict:
    """CPU and wall ms per frame (medians) of each (renderer, method), interleaved per frame, with the range
    errors where ``errors``; and per renderer the ratios beam_native / camera_rig."""
    import numpy as np

    from cosim.scenario.config import Scenario
    from cosim.world.beamtarget import beam_layout
    from cosim.world.scene import scene_from_state
    from renderer_proc.mock.beam import beam_ranges
    from renderer_proc.projection import world_from_sensor
    from renderer_proc.sample import sample_frame

    sc = Scenario(format_version=1)
    methods = {(k, m): cls(sc, k) for k in renderers for m, cls in (("camera_rig", CameraRig),
                                                                    ("beam_native", BeamNative))}
    lay = beam_layout(sc.sensor.pattern)
    cpu, wall, out = ({k: [] for k in methods} for _ in range(3))
    exact = []
    for i, t in enumerate(np.linspace(0.0, span, frames)):
        state, heights, stream = sample_frame(sc, float(t))
        scene = scene_from_state(sc, state, heights, stream)
        if errors:
            exact.append(beam_ranges(scene, world_from_sensor(sc, state), lay.directions))
        for key in (list(methods) if i % 2 == 0 else list(methods)[::-1]):
            r, c, w = timed(methods[key], scene, state)
            out[key].append(r)
            cpu[key].append(c)
            wall[key].append(w)
    rows = {}
    for key in methods:
        rows[f"{key[0]} {key[1]}"] = {"CPU ms/frame": statistics.median(cpu[key]),
                                      "wall ms/frame": statistics.median(wall[key]),
                                      **(range_errors(out[key], exact, sc.sensor.codec.max_depth_m) if errors else {})}
    ratios = {}
    for k in renderers:
        bn, cr = rows[f"{k} beam_native"], rows[f"{k} camera_rig"]
        ratios[k] = {"CPU": bn["CPU ms/frame"] / cr["CPU ms/frame"], "wall": bn["wall ms/frame"] / cr["wall ms/frame"]}
    return {"render + LiDAR step": rows, "beam_native / camera_rig": ratios}


@case("beam_native", "beam-native LiDAR against the camera rig: render + LiDAR step CPU and range error, same frames",
      options={"frames": 40, "span": 8.0, "renderers": "gl", "errors": True}, quick={"frames": 2}, rounds=1,
      compare=("CPU ms/frame", "wall ms/frame"))
def beam_native(ctx: Context) -> dict:
    """Both sensor methods on ``frames`` sample frames (module docstring); ``renderers``: comma-separated, of gl
    and mock; ``errors``: the range errors against the exact ray cast too."""
    return step_methods(ctx["frames"], ctx["span"], ctx["renderers"].split(","), ctx["errors"])


def cast_renderers(sc, arms: list[str]) -> dict:
    """One renderer per arm (GL left out where no context can be made)."""
    import sys

    from cosim.errors import RendererUnavailable
    from cosim.world.beamtarget import beam_layout
    from cosim.world.parts import entity_parts
    from renderer_proc.mock.beam import MockBeamRenderer

    lay, codec = beam_layout(sc.sensor.pattern), sc.sensor.codec
    out = {}
    for arm in arms:
        if arm == "gl":
            from renderer_proc.gl.beam import GLBeamRenderer

            try:
                out[arm] = GLBeamRenderer(lay, codec)
            except RendererUnavailable as exc:
                print(f"gl left out: {exc}", file=sys.stderr)
        else:
            backend = "numpy" if arm == "numpy" else "embree"
            r = MockBeamRenderer(lay, codec, backend=backend, parts=entity_parts(sc) if arm == "embree-static" else None)
            if r.caster.name != arm:
                raise RuntimeError(f"arm {arm} runs the {r.caster.name} ray cast")
            out[arm] = r
    return out


def cast_costs(frames: int, span: float, arms: list[str]) -> dict:
    """Per arm: CPU and wall ms per frame (medians) and the worst frame's share of beams whose bytes equal the numpy
    cast's (the first arm's where numpy is not measured)."""
    import numpy as np

    from cosim.runtime.heap import keep_heap
    from cosim.scenario.config import Scenario
    from cosim.world.beamtarget import beam_layout
    from cosim.world.scene import scene_from_state
    from renderer_proc.projection import world_from_sensor
    from renderer_proc.sample import sample_frame

    unknown = set(arms) - set(CAST_ARMS)
    if unknown:
        raise ValueError(f"unknown arms {sorted(unknown)}; choose from {', '.join(CAST_ARMS)}")
    keep_heap()
    sc = Scenario(format_version=1)
    lay = beam_layout(sc.sensor.pattern)
    rend = cast_renderers(sc, arms)
    names = list(rend)
    img = {a: np.zeros(lay.shape + (4,), np.uint8) for a in names}
    cpu, wall, same = ({a: [] for a in names} for _ in range(3))
    for i, t in enumerate(np.linspace(0.0, span, frames)):
        state, heights, stream = sample_frame(sc, float(t))
        pose = world_from_sensor(sc, state)
        scene = scene_from_state(sc, state, heights, stream)
        for a in rotating(names, i):
            c0, w0 = time.process_time(), time.perf_counter()
            rend[a].set_scene(scene)
            rend[a].draw(0, pose)
            rend[a].read_depth(0, img[a])
            cpu[a].append(1e3 * (time.process_time() - c0))
            wall[a].append(1e3 * (time.perf_counter() - w0))
        ref = img["numpy" if "numpy" in img else names[0]]
        for a in names:
            same[a].append(float(np.all(img[a] == ref, axis=-1).reshape(-1)[:lay.n_beams].mean()))
    for r in rend.values():
        r.close()
    gl = statistics.median(cpu["gl"]) if "gl" in cpu else None
    return {a: {"CPU ms/frame": statistics.median(cpu[a]), "wall ms/frame": statistics.median(wall[a]),
                "CPU / GL": statistics.median(cpu[a]) / gl if gl else None,
                "% bytes equal to the reference's (worst frame)": 100.0 * min(same[a])} for a in names}


@case("mock_cast", "the beam mock renderer's frame with each ray caster against the GL renderer's, same frames",
      options={"frames": 30, "span": 8.0, "arms": ",".join(CAST_ARMS)}, quick={"frames": 2},
      compare=("CPU ms/frame", "wall ms/frame"))
def mock_cast(ctx: Context) -> dict:
    """Each arm on ``frames`` sample frames, rotating per frame (module docstring); ``arms``: comma-separated, of
    numpy, embree, embree-static, gl."""
    return {"beam renderers, default scene": cast_costs(ctx["frames"], ctx["span"], ctx["arms"].split(","))}


def mock_frames_under_callgrind(frames: int, span: float, arm: str) -> int:
    """Inside valgrind: ``frames`` mock frames of ``arm`` (after one uncounted) collected and dumped as ``frames``;
    returns the frames counted."""
    import numpy as np
    from harness.callgrind import ClientRequests

    from cosim.runtime.heap import keep_heap
    from cosim.scenario.config import Scenario
    from cosim.world.beamtarget import beam_layout
    from cosim.world.scene import scene_from_state
    from renderer_proc.projection import world_from_sensor
    from renderer_proc.sample import sample_frame

    keep_heap()
    lib = ClientRequests().lib
    sc = Scenario(format_version=1)
    r = cast_renderers(sc, [arm])[arm]
    img = np.zeros(beam_layout(sc.sensor.pattern).shape + (4,), np.uint8)
    for k, t in enumerate(np.linspace(0.0, span, frames + 1)):
        state, heights, stream = sample_frame(sc, float(t))
        scene = scene_from_state(sc, state, heights, stream)
        if k:
            lib.cg_toggle()
        r.set_scene(scene)
        r.draw(0, world_from_sensor(sc, state))
        r.read_depth(0, img)
        if k:
            lib.cg_toggle()
    lib.cg_dump(b"frames")
    r.close()
    return frames


@case("mock_instructions", "the beam mock renderer's frame in callgrind instructions (one ray caster)",
      options={"frames": 8, "span": 8.0, "arm": "embree-static", "keep": ""}, quick={"frames": 1},
      compare=("M instructions per frame",))
def mock_instructions(ctx: Context) -> dict:
    """Instructions per mock frame of ``arm`` (module docstring)."""
    from harness.callgrind import dump_totals

    bench = Path(__file__).resolve().parents[1]
    code = (f"import sys; sys.path.insert(0, {str(bench)!r}); from cases import beams; "
            f"print(beams.mock_frames_under_callgrind({ctx['frames']!r}, {ctx['span']!r}, {ctx['arm']!r}))")
    env = dict(os.environ, PYTHONPATH=str(ctx.tree), PYTHONHASHSEED="0")
    with tempfile.TemporaryDirectory(prefix="bench-cg-") as tmp:
        out = Path(ctx["keep"]) if ctx["keep"] else Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        proc = subprocess.run(["valgrind", "--tool=callgrind", "--collect-atstart=no",
                               f"--callgrind-out-file={out}/cg.mock.%p", sys.executable, "-c", code], cwd=ctx.tree,
                              env=env, check=True, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        counted = json.loads(proc.stdout.strip().splitlines()[-1])
        ir = dump_totals(sorted(out.glob("cg.mock.*"))).get("frames", 0)
    return {f"mock frame, {ctx['arm']}": {"frame": {"M instructions per frame": ir / counted / 1e6}}}
