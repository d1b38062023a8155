"""The beam-native mock renderer's cost per frame against the GL renderer's, on the same frames.

For ``--frames`` sample frames of the default scene (``renderer_proc.sample.sample_frame`` spread over
``--span`` s), interleaved per frame (the arms' order rotating), one frame = ``set_scene`` + ``draw`` +
``read_depth`` of a renderer made once: the mock (:class:`renderer_proc.beam_mock.MockBeamRenderer`) with
each ray caster (``cosim.world.fastcast.CASTERS``: ``numpy``; ``embree``, the scene's triangles built every
frame; ``embree-static``, the rigid bodies built once per run, ``cosim.world.rigidcast``) and the GL beam-native
renderer (:class:`renderer_proc.beam_gl.GLBeamRenderer`, when a context can be made). CPU is process CPU time
(every thread: llvmpipe's, Embree's); medians. The heap is kept as in a run's processes
(``cosim.runtime.heap``). Also checks that every arm's bytes agree with the numpy ray cast. Prints Markdown and
returns the figures. Usage::

    python bench/mock_cast.py --frames 30
    python bench/mock_cast.py --frames 10 --arms embree-static,gl

``--callgrind`` counts instructions instead (deterministic, independent of the machine's load): under
``valgrind --tool=callgrind --collect-atstart=no`` the first arm's frames are collected alone (after one
uncounted frame) and dumped as ``frame``; ``python bench/mock_cast.py totals bench/out/cg.mock.*`` prints
instructions per frame, and ``callgrind_annotate --inclusive=yes`` on the dump the share of Embree's traversal
(embreex's ``EmbreeScene.run``, ``__pyx_pw_..._EmbreeScene_3run``)::

    PYTHONHASHSEED=0 valgrind --tool=callgrind --collect-atstart=no --callgrind-out-file=bench/out/cg.mock.%p \
        python bench/mock_cast.py --frames 8 --arms embree-static --callgrind
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from datetime import datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from cosim.runtime.heap import keep_heap  # noqa: E402
from cosim.scenario.config import Scenario  # noqa: E402
from cosim.world.beamtarget import beam_layout  # noqa: E402
from cosim.world.parts import entity_parts  # noqa: E402
from cosim.world.scene import scene_from_state  # noqa: E402
from renderer_proc.beam_mock import MockBeamRenderer  # noqa: E402
from renderer_proc.projection import world_from_sensor  # noqa: E402
from renderer_proc.sample import sample_frame  # noqa: E402

ARMS = ("numpy", "embree", "embree-static", "gl")


def renderers(sc: Scenario, arms: list[str]) -> dict:
    """One renderer per arm (GL left out where no context can be made)."""
    lay, codec = beam_layout(sc.sensor.pattern), sc.sensor.codec
    out = {}
    for arm in arms:
        if arm == "gl":
            from cosim.errors import RendererUnavailable
            from renderer_proc.beam_gl import GLBeamRenderer

            try:
                out[arm] = GLBeamRenderer(lay, codec)
            except RendererUnavailable as exc:
                print(f"gl left out: {exc}")
        else:
            backend = "numpy" if arm == "numpy" else "embree"
            r = MockBeamRenderer(lay, codec, backend=backend, parts=entity_parts(sc) if arm == "embree-static" else None)
            if r.caster.name != arm:
                raise RuntimeError(f"arm {arm} runs the {r.caster.name} ray cast")
            out[arm] = r
    return out


def measure(frames: int, span: float, arms: list[str]) -> dict:
    """CPU and wall ms per frame (medians) of each arm, and the worst frame's share of beams whose bytes equal
    the numpy cast's (the first arm's when numpy is not measured)."""
    keep_heap()
    sc = Scenario(format_version=1)
    lay = beam_layout(sc.sensor.pattern)
    rend = renderers(sc, arms)
    names = list(rend)
    img = {a: np.zeros(lay.shape + (4,), np.uint8) for a in names}
    cpu = {a: [] for a in names}
    wall = {a: [] for a in names}
    same = {a: [] for a in names}
    for i, t in enumerate(np.linspace(0.0, span, frames)):
        state, heights, stream = sample_frame(sc, float(t))
        pose = world_from_sensor(sc, state)
        scene = scene_from_state(sc, state, heights, stream)
        for a in names[i % len(names):] + names[:i % len(names)]:
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
    return {a: {"cpu_ms": statistics.median(cpu[a]), "wall_ms": statistics.median(wall[a]),
                "bytes_equal_min": min(same[a])} for a in names}


def count(frames: int, span: float, arm: str) -> None:
    """Callgrind dump ``frame N`` of ``arm``'s N frames (see the module docstring)."""
    from perception_replay import _Callgrind

    lib = _Callgrind().lib
    keep_heap()
    sc = Scenario(format_version=1)
    lay = beam_layout(sc.sensor.pattern)
    r = renderers(sc, [arm])[arm]
    img = np.zeros(lay.shape + (4,), np.uint8)
    times = np.linspace(0.0, span, frames + 1)
    for k, t in enumerate(times):                       # the first frame: warm-up, not counted
        state, heights, stream = sample_frame(sc, float(t))
        scene = scene_from_state(sc, state, heights, stream)
        if k:
            lib.cg_toggle()
        r.set_scene(scene)
        r.draw(0, world_from_sensor(sc, state))
        r.read_depth(0, img)
        if k:
            lib.cg_toggle()
    lib.cg_dump(f"frame {frames}".encode())
    r.close()


def totals(paths: list[str]) -> dict:
    """Instructions per frame of the ``frame`` dump in callgrind output files."""
    from perception_replay import dump_totals

    out = {}
    for name, ir in dump_totals([Path(p) for p in paths]).items():
        what, n = name.rsplit(" ", 1)
        out[what] = ir / int(n)
    for k, v in out.items():
        print(f"{k}: {v / 1e6:.2f} M instructions per frame")
    return out


def main(argv: list[str] | None = None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["totals"]:
        return totals(argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--callgrind", action="store_true", help="count the first arm's instructions (valgrind)")
    ap.add_argument("--span", type=float, default=8.0, help="simulated seconds the sample frames spread over")
    ap.add_argument("--arms", default=",".join(ARMS), help=f"comma-separated, of {', '.join(ARMS)}")
    a = ap.parse_args(argv)
    arms = [x for x in a.arms.split(",") if x]
    unknown = set(arms) - set(ARMS)
    if unknown:
        ap.error(f"unknown arms {sorted(unknown)}")
    if a.callgrind:
        count(a.frames, a.span, arms[0])
        return {}
    res = measure(a.frames, a.span, arms)
    n = beam_layout(Scenario(format_version=1).sensor.pattern).n_beams
    print(f"Beam renderers, default scene, {a.frames} frames x {n} beams, interleaved; {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}, {datetime.now():%Y-%m-%d %H:%M}; medians.\n")
    gl = res.get("gl", {}).get("cpu_ms")
    print("| renderer | CPU ms/frame | wall ms/frame | CPU / GL | bytes equal to numpy's (worst frame) |")
    print("|---|---:|---:|---:|---:|")
    for arm, r in res.items():
        ratio = f"{r['cpu_ms'] / gl:.2f}x" if gl else "-"
        print(f"| {arm} | {r['cpu_ms']:.2f} | {r['wall_ms']:.2f} | {ratio} | {100 * r['bytes_equal_min']:.3f} % |")
    return res


if __name__ == "__main__":
    main()
