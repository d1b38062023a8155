"""The perception stage on synthetic and sample scenes: its cost, and its accuracy against exact ray casts.

``perception_synthetic``: ms per frame (best of repeats, wall clock, one-thread pools as in a run's processes) at
38,400 beams (160 x 240 grid) from two stitched cameras of 640 x 480 and 1024 x 768, with the LiDAR at the camera
centre (co-located: a gather; the nearest and planar samplers, and ``cv2.remap`` for comparison) and 0.2 m away
(back-project every pixel, nearest return per beam); the whole stage (LiDAR, points, cart, height map, impact) on
images of a heaped cart with a stream; and one accuracy evaluation's exact ray cast (every beam and the default
sample) on the default scene.

``perception_accuracy``: the default scenario in-process with the mock renderer at full resolution (the GL
renderer writes the same bytes), accuracy on every beam of every frame, both samplers, and a mount that sees past
the auger tube (:data:`ALT_MOUNT`): range error by distance band and the offloading measures; the standalone reports
go to ``bench/out/perception_accuracy_<label>_<sampler>.{md,json}``.

``offset_accuracy``: the offset-LiDAR resampling (``perception_proc.lidar.resample_offset``) against an exact ray cast:
the default scene's frame at t = 10 s drawn by the mock renderer at full resolution with every rig camera moved
:data:`OFFSET_M` from the LiDAR origin (truth: ``perception_proc.accuracy.stage.exact_ranges`` from the LiDAR origin), and
the synthetic scene of ``perception_synthetic`` (floor and two boxes; truth ``cosim.testing.synthetic.raycast``).
"""
from __future__ import annotations

import json
import statistics
import time
from pathlib import Path

from harness import Context, case

__all__ = ["accuracy_cost_rows", "best_ms", "lidar_rows", "offset_accuracy", "perception_accuracy",
           "perception_synthetic", "stage_rows"]

#: LiDAR-to-camera offset of the offset rows, sensor frame, m
OFFSET_M = (0.2, 0.0, 0.0)
#: the synthetic pattern: a 160 x 240 grid over 46 x 110 deg
GRID = {"preset": "grid", "elevation_min_deg": -23.0, "elevation_max_deg": 23.0, "azimuth_min_deg": -55.0,
        "azimuth_max_deg": 55.0, "elevation_count": 160, "azimuth_count": 240}
#: the image sizes of the synthetic rows
SIZES = ((640, 480), (1024, 768))
#: perception stages of the whole-stage rows
STAGES = ("lidar", "points", "cart", "heightmap", "impact")
#: a mount that sees past the auger tube: behind the auger pivot, looking left and forward
ALT_MOUNT = {"parent": "combine", "xyz_m": [-4.0, 1.5, 6.0], "rpy_deg": [0.0, 45.0, 75.0]}
#: time of the default scenario's sample frame in ``offset_accuracy``, s
SAMPLE_T_S = 10.0


def best_ms(fn, repeats: int) -> float:
    """Best wall time of ``fn()`` over ``repeats`` calls after one warm-up, ms (the minimum is what the code costs
    when it has a core)."""
    fn()
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return 1e3 * min(out)


def _synthetic_shapes():
    from cosim.testing.synthetic import Box, Plane

    return [Plane((0.0, 1.0, 0.0), -2.5), Box((-2, -2.5, 6), (2, 0.5, 9)), Box((3, -2.5, 4), (5, 1.5, 5))]


def _remap_nearest(imgs, tab, codec):
    """The nearest-pixel gather done with ``cv2.remap`` (pixel centres at integers), for comparison."""
    import cv2
    import numpy as np

    from perception_proc.lidar.codec import decode_bytes

    out = np.full(tab.n_beams, np.nan, np.float32)
    for img, cam in zip(imgs, tab.cameras):
        mx = (cam.uv[:, 0] - 0.5).astype(np.float32)[None]
        my = (cam.uv[:, 1] - 0.5).astype(np.float32)[None]
        g = cv2.remap(img, mx, my, cv2.INTER_NEAREST)[0]
        out[cam.beams] = decode_bytes(g[:, 0], g[:, 2], g[:, 3], codec) * cam.scale
    return out


def lidar_rows(repeats: int) -> dict:
    """LiDAR from depth images: table build, decode, resample per frame and points per second, per size and mount."""
    import numpy as np

    from cosim.scenario.config import Codec, Pattern
    from cosim.testing.synthetic import encode_linear, render_depth, stitched_rig
    from cosim.world.camera import beam_directions
    from cosim.world.patterns import beam_table, pattern_shape
    from perception_proc.lidar.codec import decode_depth
    from perception_proc.lidar.resample import build_table, resample
    from perception_proc.lidar.resample_offset import build_offset_table, resample_offset

    codec, pattern, shapes = Codec(), Pattern(**GRID), _synthetic_shapes()
    e, a = beam_table(pattern)
    d = beam_directions(e, a)
    n = d.shape[0]
    rows = {}
    for w, h in SIZES:
        for offset in (False, True):
            rig = stitched_rig(2, w, h, 60.0, yaw_step_deg=55.0, offset_m=OFFSET_M if offset else (0, 0, 0))
            imgs = [encode_linear(render_depth(shapes, np.eye(4), c), codec) for c in rig.cameras]
            dec = best_ms(lambda imgs=imgs: [decode_depth(i, codec) for i in imgs], max(repeats // 4, 1))
            t0 = time.perf_counter()
            if offset:
                tab = build_offset_table(rig, e, a, pattern_shape(pattern))
                build = 1e3 * (time.perf_counter() - t0)
                runs = {"offset 0.2 m, back-project + nearest return":
                        lambda imgs=imgs, tab=tab: resample_offset(imgs, tab, codec)}
            else:
                tab = build_table(rig, d)
                build = 1e3 * (time.perf_counter() - t0)
                runs = {f"co-located, {s}": (lambda s=s, imgs=imgs, tab=tab: resample(imgs, tab, codec, s))
                        for s in ("nearest", "planar")}
                runs["co-located, nearest via cv2.remap (comparison)"] = \
                    lambda imgs=imgs, tab=tab: _remap_nearest(imgs, tab, codec)
            for label, fn in runs.items():
                ms = best_ms(fn, repeats)
                rows[f"{w}x{h}, {label}"] = {"table build ms (once)": build, "decode of both images ms": dec,
                                             "resample ms per frame": ms, "M points/s": n / ms / 1e3}
    return rows


def _cart_scenario():
    from cosim.scenario.config import Scenario

    return Scenario.model_validate_json(json.dumps({"format_version": 1, "sensor": {
        "mount": {"parent": "combine", "xyz_m": [-2.0, 3.0, 8.0], "rpy_deg": [0.0, 55.0, 90.0]},
        "pattern": {**GRID, "elevation_min_deg": -40.0, "elevation_max_deg": 30.0}}}))


def stage_rows(repeats: int) -> dict:
    """The whole perception stage on images of the heaped cart: median (best) ms per stage and in all."""
    import numpy as np

    from cosim.scenario.config import Codec
    from cosim.testing.synthetic import cart_shapes, encode_linear, render_depth, stitched_rig
    from cosim.world.geometry import vehicle_pose
    from perception_proc.pipeline import Perception

    sc, codec = _cart_scenario(), Codec()
    shapes = cart_shapes(sc.cart, vehicle_pose(-2.0, 7.4, 0.03),
                         grain_height=lambda gx, gy: np.maximum(0.8, 1.7 - 0.42 * np.hypot(gx - 2.0, gy - 1.5)),
                         stream_xy_grid=(2.0, 1.5), stream_top_m=4.8)
    rows = {}
    for w, h in SIZES:
        for offset in (False, True):
            rig = stitched_rig(2, w, h, 70.0, yaw_step_deg=60.0, pitch_deg=-5.0,
                               offset_m=OFFSET_M if offset else (0, 0, 0))
            p = Perception(sc, rig)
            imgs = [encode_linear(render_depth(shapes, p.level_from_sensor, c), codec) for c in rig.cameras]
            times = {k: [] for k in STAGES + ("whole stage",)}
            for i in range(repeats + 1):
                t0 = time.perf_counter()
                r = p.lidar(imgs, None)
                t1 = time.perf_counter()
                res = p.perceive(r)
                t2 = time.perf_counter()
                if i == 0:
                    if not (res.cart.valid and res.impact.valid):
                        raise RuntimeError(f"synthetic cart not perceived: {res.cart.reason}, {res.impact.reason}")
                    continue
                times["lidar"].append(1e3 * (t1 - t0))
                for k in STAGES[1:]:
                    times[k].append(res.timing_ms[k])
                times["whole stage"].append(1e3 * (t2 - t0))
            row = {f"{k} ms": statistics.median(v) for k, v in times.items()}
            row["whole stage best ms"] = min(times["whole stage"])
            row["M points/s"] = p.n_beams / row["whole stage ms"] / 1e3
            rows[f"{w}x{h}, {'offset 0.2 m' if offset else 'co-located'}"] = row
    return rows


def accuracy_cost_rows(repeats: int) -> dict:
    """One accuracy evaluation's exact ray cast on the default scene: every beam, and the default sample."""
    from cosim.scenario.config import Scenario
    from cosim.world.rig import plan_rig
    from perception_proc.accuracy.stage import exact_ranges, sample_beams, world_from_parent
    from perception_proc.pipeline import Perception
    from renderer_proc.sample import sample_frame

    sc = Scenario(format_version=1)
    state, hts, stream = sample_frame(sc, 10.0)
    p = Perception(sc, plan_rig(sc))
    wfs = world_from_parent(sc, state) @ p.level_from_sensor
    rows = {}
    for count in (0, sc.perception.accuracy_beams):
        beams = sample_beams(p.n_beams, count, sc.seed, 10)
        d = p.directions[beams]
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            exact_ranges(sc, state, hts, stream, wfs, d)
            ts.append(1e3 * (time.perf_counter() - t0))
        k = sc.perception.accuracy_every_frames
        rows[f"{beams.size} beams"] = {"ms median": statistics.median(ts), "ms best": min(ts),
                                       f"ms per frame at every {k} frames": statistics.median(ts) / k}
    return rows


@case("perception_synthetic", "the perception stage on synthetic images: decode, resampling, the stages, the "
      "accuracy evaluation's ray cast", options={"repeats": 20}, quick={"repeats": 2}, rounds=1,
      compare=("resample ms per frame", "whole stage ms", "ms median"))
def perception_synthetic(ctx: Context) -> dict:
    """The three tables of the module docstring."""
    from cosim.runtime.threadpools import default_to_single_threaded_pools

    default_to_single_threaded_pools()
    r = ctx["repeats"]
    return {"LiDAR from depth images (38,400 beams, 2 cameras; best of repeats)": lidar_rows(r),
            "whole perception stage (heaped cart with a stream; medians)": stage_rows(r),
            "accuracy evaluation (exact ray cast, default scene)": accuracy_cost_rows(max(r // 4, 1))}


def _accuracy_run(sampler: str, frames: int, mount: dict | None = None) -> dict:
    from cosim.runtime.inprocess import simulate
    from cosim.scenario.config import Scenario
    from perception_proc.summary import summarize

    doc = {"format_version": 1, "renderer": "mock", "render": {"mock_scale": 1.0},
           "perception": {"accuracy_every_frames": 1, "accuracy_beams": 0, "sampler": sampler}}
    if mount is not None:
        doc["sensor"] = {"mount": mount}
    sc = Scenario.model_validate_json(json.dumps(doc))
    t0 = time.perf_counter()
    res = simulate(sc, frames=frames)
    wall = time.perf_counter() - t0
    series = {k: v for k, v in res.recorder.series().items() if k.startswith("perc_state.")}
    seg = res.segment
    out = summarize(sc, series, seg.view("heightmap_truth"), seg.view("heightmap_perceived"))["perception"]
    out["wall_s"] = wall
    return out


@case("perception_accuracy", "perception's accuracy on the default scene against the exact ray cast: range error by "
      "band, offloading measures", options={"frames": 4, "reports": True}, quick={"frames": 1, "reports": False})
def perception_accuracy(ctx: Context) -> dict:
    """Three runs of ``frames`` frames (module docstring); ``reports``: write the standalone reports."""
    from perception_proc.accuracy.report import write_report

    out: dict = {"range error (mm)": {}, "offloading measures": {}}
    bands: dict = {}
    for label, sampler, mount in (("default", "planar", None), ("default", "nearest", None),
                                  ("alt_mount", "planar", ALT_MOUNT)):
        sec = _accuracy_run(sampler, ctx["frames"], mount)
        name = f"{label} mount, {sampler}"
        re_ = sec.get("range_error") or {}
        out["range error (mm)"][name] = {
            "beams": re_.get("beams"), "mean": 1e3 * re_["mean_m"], "median": 1e3 * re_["median_m"],
            "p99": 1e3 * re_["p99_m"], "max": 1e3 * re_["max_m"], "% above 5 cm": 100 * re_["frac_above_5cm"],
            "% missing": 100 * re_.get("beam_missing_frac", float("nan"))}
        for band in re_.get("bands", []):
            if band.get("beams"):
                bands.setdefault(f"range error by band, {name} (mm)", {})[f"{band['lo_m']:g}-{band['hi_m']:g} m"] = {
                    "beams": band["beams"], "mean": 1e3 * band["mean_m"], "p99": 1e3 * band["p99_m"],
                    "% above 5 cm": 100 * band["frac_above_5cm"]}
        measures = {k: v for k, v in sec.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
        out["offloading measures"][name] = measures
        if ctx["reports"]:
            write_report(sec, Path(__file__).resolve().parents[1] / "out", stem=f"perception_accuracy_{label}_{sampler}")
    return {**out, **bands}


def _offset_rig(rig):
    """``rig`` with every camera centre moved by OFFSET_M (sensor frame, m)."""
    import numpy as np

    from cosim.world.camera import Rig, RigCamera

    cams = []
    for c in rig.cameras:
        m = c.sensor_from_camera.copy()
        m[:3, 3] += np.asarray(OFFSET_M, float)
        cams.append(RigCamera(c.name, c.intrinsics, m))
    return Rig(tuple(cams))


def _default_offset_case():
    import numpy as np

    from cosim.scenario.config import Scenario
    from cosim.world.patterns import beam_table, pattern_shape
    from cosim.world.rig import plan_rig
    from cosim.world.scene import scene_from_state
    from perception_proc.accuracy.stage import exact_ranges
    from perception_proc.pipeline import Perception
    from renderer_proc.mock.backend import MockRenderer
    from renderer_proc.projection import camera_poses, world_from_sensor
    from renderer_proc.sample import sample_frame

    sc = Scenario.model_validate({"format_version": 1, "renderer": "mock", "render": {"mock_scale": 1.0}})
    rig = _offset_rig(plan_rig(sc))
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
    exact = exact_ranges(sc, state, hts, stream, world_from_sensor(sc, state), Perception(sc, rig).directions)
    e, a = beam_table(sc.sensor.pattern)
    return imgs, rig, e, a, pattern_shape(sc.sensor.pattern), codec, exact, (sc.sensor.range_min_m,
                                                                               sc.sensor.range_max_m)


def _synthetic_offset_case(w: int, h: int):
    import numpy as np

    from cosim.scenario.config import Codec, Pattern
    from cosim.testing.synthetic import encode_linear, raycast, render_depth, stitched_rig
    from cosim.world.camera import beam_directions
    from cosim.world.patterns import beam_table, pattern_shape

    codec, pattern, shapes = Codec(), Pattern(**GRID), _synthetic_shapes()
    rig = stitched_rig(2, w, h, 60.0, yaw_step_deg=55.0, offset_m=OFFSET_M)
    imgs = [encode_linear(render_depth(shapes, np.eye(4), c), codec) for c in rig.cameras]
    e, a = beam_table(pattern)
    return imgs, rig, e, a, pattern_shape(pattern), codec, raycast(shapes, np.zeros(3), beam_directions(e, a)), (0.0, 40.0)


@case("offset_accuracy", "the offset-LiDAR resampling against an exact ray cast: range errors, missing and spurious "
      "beams", options={"repeats": 3}, quick={"repeats": 1})
def offset_accuracy(ctx: Context) -> dict:
    """Range errors of ``resample_offset`` on each scene (module docstring), ``range_error_stats``' beams."""
    import numpy as np

    from perception_proc.accuracy.stage import range_error_stats
    from perception_proc.lidar import resample_offset as mod

    cases = {"default scene": _default_offset_case, **{f"synthetic {w}x{h}": (lambda w=w, h=h: _synthetic_offset_case(w, h))
                                                        for w, h in SIZES}}
    rows = {}
    for scene, make in cases.items():
        imgs, rig, e, a, shape, codec, exact, (lo, hi) = make()
        table = mod.build_offset_table(rig, e, a, shape)
        rng = mod.resample_offset(imgs, table, codec)
        ms = best_ms(lambda imgs=imgs, table=table, codec=codec: mod.resample_offset(imgs, table, codec),
                     ctx["repeats"])
        s = range_error_stats(rng, exact, lo, hi)
        both = np.isfinite(rng) & np.isfinite(exact) & (exact >= lo) & (exact <= hi)
        err = np.abs(rng[both] - exact[both])
        rows[scene] = {"beams": s["range_beams"], "mean mm": 1e3 * s["range_err_mean_m"],
                       "median mm": 1e3 * s["range_err_median_m"], "p99 mm": 1e3 * s["range_err_p99_m"],
                       "max mm": 1e3 * float(err.max()) if err.size else None,
                       "% > 5 cm": 100 * s["frac_above_5cm"], "> 5 cm": int(np.count_nonzero(err > 0.05)),
                       "% missing": 100 * s["beam_missing_frac"], "% spurious": 100 * s["beam_spurious_frac"],
                       "ms (best)": ms}
    return {"offset LiDAR resampling": rows}
