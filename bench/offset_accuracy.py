"""Accuracy of the offset-LiDAR resampling (``perception_proc.resample_offset``) against an exact ray cast.

Run: ``python bench/offset_accuracy.py [module.py ...]`` (from the repository root). For each implementation
(default: the package's ``perception_proc/resample_offset.py``; pass file paths to compare other versions of
the module, e.g. a saved copy of an older one) prints one Markdown table of range errors per scene:

* ``default scene``: the default scenario's frame at t = 10 s (``renderer_proc.sample``), drawn at full
  resolution by the mock renderer (the GL renderer writes the same bytes), with every rig camera moved
  :data:`OFFSET_M` (sensor frame) away from the LiDAR origin; truth is the renderer's exact ray cast of the
  same beams from the LiDAR origin (``perception_proc.accuracy.exact_ranges``).
* ``bench 640x480`` / ``bench 1024x768``: the scene and rig of ``bench/perception_bench.py`` (floor and two
  boxes, two stitched 60 deg cameras, 240 x 160 grid), truth from ``cosim.testing.synthetic.raycast``.

Statistics follow ``perception_proc.accuracy.range_error_stats`` (beams whose exact range lies within the
sensor's range limits; missing = truth valid but no return, spurious = a return where truth has none), plus
the share of beams with a return more than 5 cm off and the worst error.
"""
from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.scenario.config import Codec, Pattern, Scenario  # noqa: E402
from cosim.testing.synthetic import Box, Plane, encode_linear, raycast, render_depth, stitched_rig  # noqa: E402
from cosim.world.camera import Rig, RigCamera, beam_directions  # noqa: E402
from cosim.world.patterns import beam_table, pattern_shape  # noqa: E402
from perception_proc.accuracy import exact_ranges, range_error_stats  # noqa: E402

#: LiDAR-to-camera offset of the study, sensor frame, m (as in bench/perception_bench.py)
OFFSET_M = (0.2, 0.0, 0.0)
#: time of the default scenario's sample frame, s
SAMPLE_T_S = 10.0
BENCH_PATTERN = Pattern(preset="grid", elevation_min_deg=-23.0, elevation_max_deg=23.0, azimuth_min_deg=-55.0,
                        azimuth_max_deg=55.0, elevation_count=160, azimuth_count=240)
BENCH_SHAPES = [Plane((0.0, 1.0, 0.0), -2.5), Box((-2, -2.5, 6), (2, 0.5, 9)), Box((3, -2.5, 4), (5, 1.5, 5))]


def offset_rig(rig: Rig, offset_m=OFFSET_M) -> Rig:
    """``rig`` with every camera centre moved by ``offset_m`` (sensor frame, m)."""
    cams = []
    for c in rig.cameras:
        m = c.sensor_from_camera.copy()
        m[:3, 3] += np.asarray(offset_m, float)
        cams.append(RigCamera(c.name, c.intrinsics, m))
    return Rig(tuple(cams))


def default_case():
    """(images, rig, elevation, azimuth, shape, codec, exact, range limits) of the default scene."""
    from cosim.world.rig import plan_rig
    from cosim.world.scene import scene_from_state
    from perception_proc.pipeline import Perception
    from renderer_proc.mock_backend import MockRenderer
    from renderer_proc.projection import camera_poses
    from renderer_proc.sample import sample_frame

    sc = Scenario.model_validate_json(json.dumps(
        {"format_version": 1, "renderer": "mock", "render": {"mock_scale": 1.0}}))
    rig = offset_rig(plan_rig(sc))
    state, hts, stream = sample_frame(sc, SAMPLE_T_S)
    codec = sc.sensor.codec
    mock = MockRenderer(rig, codec)
    mock.set_scene(scene_from_state(sc, state, hts, stream))
    imgs = []
    for k, pose in enumerate(camera_poses(sc, state, rig)):
        mock.draw(k, pose)
        c = rig.cameras[k].intrinsics
        img = np.zeros((c.height, c.width, 4), np.uint8)
        mock.read_depth(k, img)
        imgs.append(img)
    p = Perception(sc, rig)
    from renderer_proc.projection import world_from_sensor
    exact = exact_ranges(sc, state, hts, stream, world_from_sensor(sc, state), p.directions)
    e, a = beam_table(sc.sensor.pattern)
    return imgs, rig, e, a, pattern_shape(sc.sensor.pattern), codec, exact, (sc.sensor.range_min_m,
                                                                               sc.sensor.range_max_m)


def bench_case(w: int, h: int):
    codec = Codec()
    rig = stitched_rig(2, w, h, 60.0, yaw_step_deg=55.0, offset_m=OFFSET_M)
    imgs = [encode_linear(render_depth(BENCH_SHAPES, np.eye(4), c), codec) for c in rig.cameras]
    e, a = beam_table(BENCH_PATTERN)
    exact = raycast(BENCH_SHAPES, np.zeros(3), beam_directions(e, a))
    return imgs, rig, e, a, pattern_shape(BENCH_PATTERN), codec, exact, (0.0, 40.0)


def load(path: str | None):
    if path is None:
        from perception_proc import resample_offset
        return resample_offset
    spec = importlib.util.spec_from_file_location("perception_proc._offset_under_test", path,
                                                  submodule_search_locations=None)
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = "perception_proc"
    sys.modules[spec.name] = mod                       # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def evaluate(mod, case) -> dict:
    imgs, rig, e, a, shape, codec, exact, (lo, hi) = case
    table = mod.build_offset_table(rig, e, a, shape)
    rng = mod.resample_offset(imgs, table, codec)
    ts = []
    for _ in range(3):
        t0 = time.perf_counter()
        mod.resample_offset(imgs, table, codec)
        ts.append(1e3 * (time.perf_counter() - t0))
    s = range_error_stats(rng, exact, lo, hi)
    both = np.isfinite(rng) & np.isfinite(exact) & (exact >= lo) & (exact <= hi)
    err = np.abs(rng[both] - exact[both])
    s["max"] = float(err.max()) if err.size else float("nan")
    s["n_above_5cm"] = int(np.count_nonzero(err > 0.05))
    s["ms_best"] = min(ts)
    return s


def main() -> None:
    paths = sys.argv[1:] or [None]
    cases = {"default scene": default_case, "bench 640x480": lambda: bench_case(640, 480),
             "bench 1024x768": lambda: bench_case(1024, 768)}
    built = {k: f() for k, f in cases.items()}
    print("| implementation | scene | beams | mean (mm) | median (mm) | p99 (mm) | max (mm) | > 5 cm | "
          "missing | spurious | ms (best of 3) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for path in paths:
        mod = load(path)
        name = "current" if path is None else Path(path).stem
        for scene, case in built.items():
            s = evaluate(mod, case)
            print(f"| {name} | {scene} | {s['range_beams']:.0f} | {1e3 * s['range_err_mean_m']:.2f} | "
                  f"{1e3 * s['range_err_median_m']:.2f} | {1e3 * s['range_err_p99_m']:.1f} | {1e3 * s['max']:.0f} | "
                  f"{100 * s['frac_above_5cm']:.3f} % ({s['n_above_5cm']}) | {100 * s['beam_missing_frac']:.3f} % | "
                  f"{100 * s['beam_spurious_frac']:.3f} % | {s['ms_best']:.1f} |")


if __name__ == "__main__":
    main()
