"""Perception-stage timings: decode, LiDAR resampling and the three offloading algorithms.

Run: ``python bench/perception_bench.py`` (from the repository root). Prints Markdown tables: ms per frame
(best of repeats, one process, wall clock) at 38,400 beams (160 x 240 grid) from two stitched cameras of
640 x 480 and 1024 x 768, with the LiDAR at the camera centre (co-located: a gather) and 0.2 m away from it
(the general case: back-project every pixel, keep the nearest return per beam), and points per second; then
the whole perception stage (LiDAR from the images, cart, height map, impact) on images of a heaped cart at
both sizes and mounts, and the cost of one accuracy evaluation (every beam vs the default sample).
Timings are medians and bests in one process; on the shared machine compare runs interleaved.
"""
from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.runtime.threadpools import default_to_single_threaded_pools  # noqa: E402

default_to_single_threaded_pools()      # before numpy and cv2 load: one-thread pools, as in a run's processes

import numpy as np  # noqa: E402

from cosim.scenario.config import Codec, Pattern, Scenario  # noqa: E402
from cosim.testing.synthetic import Box, Plane, cart_shapes, encode_linear, render_depth, stitched_rig  # noqa: E402
from cosim.world.camera import beam_directions  # noqa: E402
from cosim.world.geometry import vehicle_pose  # noqa: E402
from cosim.world.patterns import beam_table, pattern_shape  # noqa: E402
from perception_proc.codec import decode_depth  # noqa: E402
from perception_proc.pipeline import Perception  # noqa: E402
from perception_proc.resample import build_table, resample  # noqa: E402
from perception_proc.resample_offset import build_offset_table, resample_offset  # noqa: E402

CODEC = Codec()
PATTERN = Pattern(preset="grid", elevation_min_deg=-23.0, elevation_max_deg=23.0, azimuth_min_deg=-55.0,
                  azimuth_max_deg=55.0, elevation_count=160, azimuth_count=240)
OFFSET_M = (0.2, 0.0, 0.0)


def timeit(fn, repeats: int) -> float:
    """Best wall time of ``fn()`` over ``repeats`` calls after one warm-up, ms (the best, not the median: the
    2-core machine is shared, and the minimum is what the code costs when it has a core)."""
    fn()
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return 1e3 * min(out)


def remap_nearest(imgs, tab) -> np.ndarray:
    """The nearest-pixel gather done with ``cv2.remap`` (INTER_NEAREST on the RGBA bytes, then Eq 3), for
    comparison with the numpy word gather the pipeline uses. OpenCV puts pixel centres at integers."""
    import cv2

    from perception_proc.codec import decode_bytes

    out = np.full(tab.n_beams, np.nan, np.float32)
    for img, cam in zip(imgs, tab.cameras):
        mx = (cam.uv[:, 0] - 0.5).astype(np.float32)[None]
        my = (cam.uv[:, 1] - 0.5).astype(np.float32)[None]
        g = cv2.remap(img, mx, my, cv2.INTER_NEAREST)[0]
        out[cam.beams] = decode_bytes(g[:, 0], g[:, 2], g[:, 3], CODEC) * cam.scale
    return out


def lidar_rows() -> list[tuple]:
    e, a = beam_table(PATTERN)
    d = beam_directions(e, a)
    n = d.shape[0]
    shapes = [Plane((0.0, 1.0, 0.0), -2.5), Box((-2, -2.5, 6), (2, 0.5, 9)), Box((3, -2.5, 4), (5, 1.5, 5))]
    rows = []
    for w, h in ((640, 480), (1024, 768)):
        for offset in (False, True):
            rig = stitched_rig(2, w, h, 60.0, yaw_step_deg=55.0, offset_m=OFFSET_M if offset else (0, 0, 0))
            imgs = [encode_linear(render_depth(shapes, np.eye(4), c), CODEC) for c in rig.cameras]
            dec = timeit(lambda imgs=imgs: [decode_depth(i, CODEC) for i in imgs], 5)
            if offset:
                t0 = time.perf_counter()
                tab = build_offset_table(rig, e, a, pattern_shape(PATTERN))
                build = 1e3 * (time.perf_counter() - t0)
                ms = timeit(lambda imgs=imgs, tab=tab: resample_offset(imgs, tab, CODEC), 20)
                rows.append((f"{w}x{h}", "offset 0.2 m", "back-project + nearest return (column pre-test)", build,
                             dec, ms, n / ms * 1e3))
            else:
                t0 = time.perf_counter()
                tab = build_table(rig, d)
                build = 1e3 * (time.perf_counter() - t0)
                for sampler in ("nearest", "planar"):
                    ms = timeit(lambda imgs=imgs, tab=tab, sampler=sampler: resample(imgs, tab, CODEC, sampler), 30)
                    rows.append((f"{w}x{h}", "co-located", sampler, build, dec, ms, n / ms * 1e3))
                ms = timeit(lambda imgs=imgs, tab=tab: remap_nearest(imgs, tab), 30)
                rows.append((f"{w}x{h}", "co-located", "nearest via cv2.remap (comparison)", build, dec, ms,
                             n / ms * 1e3))
    return rows


def _cart_scenario() -> Scenario:
    return Scenario.model_validate_json(
        '{"format_version": 1, "sensor": {"mount": {"parent": "combine", "xyz_m": [-2.0, 3.0, 8.0], '
        '"rpy_deg": [0.0, 55.0, 90.0]}, "pattern": {"preset": "grid", "elevation_min_deg": -40.0, '
        '"elevation_max_deg": 30.0, "azimuth_min_deg": -55.0, "azimuth_max_deg": 55.0, "elevation_count": 160, '
        '"azimuth_count": 240}}}')


def _cart_scene(sc: Scenario):
    return cart_shapes(sc.cart, vehicle_pose(-2.0, 7.4, 0.03),
                       grain_height=lambda gx, gy: np.maximum(0.8, 1.7 - 0.42 * np.hypot(gx - 2.0, gy - 1.5)),
                       stream_xy_grid=(2.0, 1.5), stream_top_m=4.8)


STAGES = ("lidar", "points", "cart", "heightmap", "impact")


def stage_rows(repeats: int = 20) -> list[tuple]:
    """The whole perception stage on images of the heaped cart with a stream (two stitched cameras of 70 x 70 deg,
    38,400 beams): decode + resample (``lidar``), the lidar_points record and level points (``points``), cart,
    height map, impact. Median and best ms per stage and for the whole stage, per image size and mount."""
    sc = _cart_scenario()
    shapes = _cart_scene(sc)
    rows = []
    for w, h in ((640, 480), (1024, 768)):
        for offset in (False, True):
            rig = stitched_rig(2, w, h, 70.0, yaw_step_deg=60.0, pitch_deg=-5.0,
                               offset_m=OFFSET_M if offset else (0, 0, 0))
            p = Perception(sc, rig)
            lfs = p.level_from_sensor
            imgs = [encode_linear(render_depth(shapes, lfs, c), CODEC) for c in rig.cameras]
            times = {k: [] for k in STAGES + ("total",)}
            for i in range(repeats + 1):
                t0 = time.perf_counter()
                r = p.lidar(imgs, None)
                t1 = time.perf_counter()
                res = p.perceive(r)
                t2 = time.perf_counter()
                if i == 0:
                    assert res.cart.valid and res.impact.valid, (res.cart.reason, res.impact.reason)
                    continue
                times["lidar"].append(1e3 * (t1 - t0))
                for k in STAGES[1:]:
                    times[k].append(res.timing_ms[k])
                times["total"].append(1e3 * (t2 - t0))
            rows.append((f"{w}x{h}", "offset 0.2 m" if offset else "co-located",
                         {k: (statistics.median(v), min(v)) for k, v in times.items()}, p.n_beams))
    return rows


def accuracy_cost_rows(repeats: int = 5) -> list[tuple]:
    """Cost of one accuracy evaluation's exact ray cast on the default scene (renderer_proc.sample frame):
    every beam vs the default stratified sample (``perception.accuracy_beams``), ms median and best."""
    from cosim.world.rig import plan_rig
    from perception_proc.accuracy import exact_ranges, sample_beams, world_from_parent
    from renderer_proc.sample import sample_frame

    sc = Scenario(format_version=1)
    state, hts, stream = sample_frame(sc, 10.0)
    p = Perception(sc, plan_rig(sc))
    wfs = world_from_parent(sc, state) @ p.level_from_sensor
    rows = []
    for count in (0, sc.perception.accuracy_beams):
        beams = sample_beams(p.n_beams, count, sc.seed, 10)
        d = p.directions[beams]
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            exact_ranges(sc, state, hts, stream, wfs, d)
            ts.append(1e3 * (time.perf_counter() - t0))
        rows.append((beams.size, statistics.median(ts), min(ts), sc.perception.accuracy_every_frames))
    return rows


def main() -> None:
    print("### LiDAR from depth images (38,400 beams, 2 cameras)\n")
    print("| images | LiDAR | sampler | table build (ms, once) | full decode of both images (ms) | "
          "resample per frame (ms) | points/s |")
    print("|---|---|---|---:|---:|---:|---:|")
    for img, kind, sampler, build, dec, ms, pps in lidar_rows():
        print(f"| {img} | {kind} | {sampler} | {build:.1f} | {dec:.2f} | {ms:.2f} | {pps / 1e6:.1f} M |")
    print("\n### Whole perception stage (heaped cart with a stream, images of two 70 x 70 deg cameras)\n")
    print("| images | LiDAR | " + " | ".join(STAGES) + " | whole stage | points/s |")
    print("|---|---|" + "---:|" * (len(STAGES) + 2))
    for img, kind, t, n in stage_rows():
        cells = " | ".join(f"{t[k][0]:.2f} ({t[k][1]:.2f})" for k in STAGES)
        print(f"| {img} | {kind} | {cells} | {t['total'][0]:.2f} ({t['total'][1]:.2f}) | "
              f"{n / t['total'][0] / 1e3:.1f} M ({n / t['total'][1] / 1e3:.1f} M) |")
    print("\nms per frame, median (best) of 20 frames; points/s from the median (best) whole stage.")
    print("\n### Accuracy evaluation (exact ray cast, default scene)\n")
    print("| beams cast | ms median | ms best | ms per frame amortised (every k frames) |")
    print("|---:|---:|---:|---:|")
    for n, med, best, k in accuracy_cost_rows():
        print(f"| {n} | {med:.1f} | {best:.1f} | {med / k:.2f} (k = {k}) |")


if __name__ == "__main__":
    main()
