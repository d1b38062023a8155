"""Beam-native LiDAR against the camera rig: render + LiDAR step CPU and range error, same frames.

For each of ``--frames`` sample frames of the default scene (``renderer_proc.sample.sample_frame`` at times
spread over ``--span`` s, the vehicles driving), interleaved per frame (A B, B A, ...):

* ``camera_rig``: the planned rig drawn by the GL renderer, every camera read, then perception's resample
  (Eqs 3, 5-7: decode, back-project, planar sampler) to the beams;
* ``beam_native``: the GL beam-native renderer (one pixel per beam), read, then the per-beam decode (Eq 3).

CPU is process CPU time (user + system of every thread, llvmpipe's included) per frame, and wall time; the
ratio is of medians. The range error of each method is taken against the exact ray cast of the same beams
(``renderer_proc.beam_mock.beam_ranges``) over every beam of every frame. ``--mock`` also times the two mock
renderers (camera rig at ``render.mock_scale``, beams). Prints Markdown. Usage::

    python bench/beam_native.py --frames 40 [--mock]
"""
from __future__ import annotations

import argparse
import functools
import os
import statistics
import sys
import time
from datetime import datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from cosim.scenario.config import Scenario  # noqa: E402
from cosim.world.beamtarget import beam_layout  # noqa: E402
from cosim.world.rig import plan_rig  # noqa: E402
from cosim.world.scene import scene_from_state  # noqa: E402
from perception_proc.pipeline import Perception  # noqa: E402
from renderer_proc.beam_mock import MockBeamRenderer, beam_ranges  # noqa: E402
from renderer_proc.projection import camera_poses, world_from_sensor  # noqa: E402
from renderer_proc.sample import sample_frame  # noqa: E402

#: the "large error" threshold and the working range, m
ABOVE_M, WORKING_M = 0.05, (2.0, 15.0)


@functools.lru_cache(maxsize=1)
def _context():
    """One GL context for both renderers (moderngl draws into the current context: two standalone contexts in
    one process would need switching)."""
    from renderer_proc.gl_backend import create_gl_context
    return create_gl_context()


class CameraRig:
    """Render every rig camera and resample to the beams."""

    def __init__(self, sc: Scenario, renderer: str = "gl"):
        sc = sc.model_copy(update={"renderer": renderer})
        self.sc, self.rig = sc, plan_rig(sc)
        if renderer == "gl":
            from renderer_proc.gl_backend import GLRenderer
            self.r = GLRenderer(self.rig, sc.sensor.codec, context=_context())
        else:
            from renderer_proc.mock_backend import MockRenderer
            self.r = MockRenderer(self.rig, sc.sensor.codec)
        self.pipe = Perception(sc, self.rig)
        self.imgs = [np.zeros((c.intrinsics.height, c.intrinsics.width, 4), np.uint8) for c in self.rig.cameras]

    def frame(self, scene, state) -> np.ndarray:
        self.r.set_scene(scene)
        for k, pose in enumerate(camera_poses(self.sc, state, self.rig)):
            self.r.draw(k, pose)
            self.r.read_depth(k, self.imgs[k])
        return self.pipe.resample(self.imgs)


class BeamNative:
    """Render the beams and decode them."""

    def __init__(self, sc: Scenario, renderer: str = "gl"):
        sc = sc.model_copy(update={"renderer": renderer,
                                   "sensor": sc.sensor.model_copy(update={"method": "beam_native"})})
        self.sc, self.lay = sc, beam_layout(sc.sensor.pattern)
        if renderer == "gl":
            from renderer_proc.beam_gl import GLBeamRenderer
            self.r = GLBeamRenderer(self.lay, sc.sensor.codec, context=_context())
        else:
            self.r = MockBeamRenderer(self.lay, sc.sensor.codec)
        self.pipe = Perception(sc, None)
        self.img = np.zeros(self.lay.shape + (4,), np.uint8)

    def frame(self, scene, state) -> np.ndarray:
        self.r.set_scene(scene)
        self.r.draw(0, world_from_sensor(self.sc, state))
        self.r.read_depth(0, self.img)
        return self.pipe.resample([self.img])


def errors(ranges: list[np.ndarray], exact: list[np.ndarray], max_m: float) -> dict:
    r, x = np.concatenate(ranges).astype(np.float64), np.concatenate(exact)
    ok = np.isfinite(r) & np.isfinite(x) & (x < max_m)
    e = np.abs(r - x)[ok]
    w = (x[ok] >= WORKING_M[0]) & (x[ok] < WORKING_M[1])
    miss = np.isfinite(x) & (x < max_m * 254.5 / 255.0) & ~np.isfinite(r)
    return {"beams": int(ok.sum()), "mean_mm": 1e3 * e.mean(), "p99_mm": 1e3 * np.percentile(e, 99),
            "max_mm": 1e3 * e.max(), "above_2_15": int(np.count_nonzero(e[w] > ABOVE_M)),
            "frac_2_15": float(np.count_nonzero(e[w] > ABOVE_M) / max(w.sum(), 1)),
            "p99_2_15_mm": 1e3 * np.percentile(e[w], 99), "missing": int(miss.sum())}


def timed(method, scene, state) -> tuple[np.ndarray, float, float]:
    c0, w0 = time.process_time(), time.perf_counter()
    r = method.frame(scene, state)
    return r.copy(), 1e3 * (time.process_time() - c0), 1e3 * (time.perf_counter() - w0)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--span", type=float, default=8.0, help="simulated seconds the sample frames spread over")
    ap.add_argument("--mock", action="store_true", help="also time the two mock renderers")
    a = ap.parse_args(argv)
    sc = Scenario(format_version=1)
    kinds = ["gl"] + (["mock"] if a.mock else [])
    methods = {(k, m): cls(sc, k) for k in kinds for m, cls in (("camera_rig", CameraRig), ("beam_native", BeamNative))}
    lay = beam_layout(sc.sensor.pattern)
    cpu = {k: [] for k in methods}
    wall = {k: [] for k in methods}
    out = {k: [] for k in methods}
    exact = []
    for i, t in enumerate(np.linspace(0.0, a.span, a.frames)):
        state, heights, stream = sample_frame(sc, float(t))
        scene = scene_from_state(sc, state, heights, stream)
        exact.append(beam_ranges(scene, world_from_sensor(sc, state), lay.directions))
        order = list(methods) if i % 2 == 0 else list(methods)[::-1]
        for key in order:
            r, c, w = timed(methods[key], scene, state)
            out[key].append(r)
            cpu[key].append(c)
            wall[key].append(w)
    print(f"Default scene, {a.frames} sample frames over {a.span:g} s, interleaved per frame; {os.cpu_count()} cores, "
          f"{datetime.now():%Y-%m-%d %H:%M}; medians. Errors against the exact ray cast of every beam "
          f"({lay.n_beams} per frame).\n")
    print("| renderer | method | CPU ms/frame | wall ms/frame | mean err mm | p99 mm | max mm | p99 2-15 m mm | "
          "beams > 5 cm in 2-15 m | missing beams |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for key in methods:
        e = errors(out[key], exact, sc.sensor.codec.max_depth_m)
        print(f"| {key[0]} | {key[1]} | {statistics.median(cpu[key]):.2f} | {statistics.median(wall[key]):.2f} | "
              f"{e['mean_mm']:.3f} | {e['p99_mm']:.3f} | {e['max_mm']:.2f} | {e['p99_2_15_mm']:.3f} | "
              f"{e['above_2_15']} ({100 * e['frac_2_15']:.3f} %) | {e['missing']} |")
    for k in kinds:
        rc = statistics.median(cpu[(k, "beam_native")]) / statistics.median(cpu[(k, "camera_rig")])
        rw = statistics.median(wall[(k, "beam_native")]) / statistics.median(wall[(k, "camera_rig")])
        print(f"\n{k}: beam_native / camera_rig = {rc:.2f}x CPU, {rw:.2f}x wall (render + LiDAR step)")


if __name__ == "__main__":
    main()
