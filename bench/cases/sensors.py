"""Sensors other than the default LiDAR (docs/cameras.md): what each kind costs per frame, and the stereo camera's
pile height beside the published stereo result.

``sensor_cost``: configurations, each the default scenario's world with other sensors (``sensors:``), GL renderer,
perception feedback, every sensor taking an image every frame: ``lidar`` (the default itself: beam-native
Honeycomb-like LiDAR, 38,400 beams), ``depth_camera`` (a Kinect-class camera on ``tof_mast``'s mount, profile
``kinect_class_structured_light``, 512 x 424), ``stereo_camera`` (the ``stereo_spout`` head, MultiSense S21B profile, 2 x 1024 x 544, SGBM, 128 disparities),
``stereo_camera_bm`` (the same with StereoBM), ``rgb_camera`` (a 640 x 480 colour camera beside the LiDAR: its cost is
the renderer's) and ``lidar_and_stereo`` (fused). Each a launched run (OS processes) of ``duration`` simulated
seconds, the configurations in rotating order: medians per frame of the renderer's step, perception's step, the
sensor model (``sensor_<name>.measure_ms``: the depth camera's noise model, the stereo matcher) and the frame, and
the frame over the same round's LiDAR frame.

``stereo_pile_height``: the packaged ``stereo_spout`` scenario (a stereo head on the spout, camera only, perception
feedback) with each matcher: the mean relative error of the fill height the camera alone measures against the true
heights (mean |h - h_true| / h_true over the cells it maps, each evaluated frame, h above the cart floor), its depth
error, and what the run did with it (peak overfill, spill); beside it Sensors 2024, 24(22):7204, stereo pile height
on a transport container: 3.35 % with SGBM and 3.70 % with BM. Not the same measurement: theirs is a real camera
over a real pile (calibration error 0.15 px, lighting, dust), ours a simulated pair, rectified exactly, over a
rendered, textured surface: the matcher's error alone.
"""
from __future__ import annotations

import csv
import json
import statistics
import tempfile
from pathlib import Path

from harness import Context, case, rotating

__all__ = ["sensor_cost", "stereo_pile_height"]

STEREO = {"kind": "stereo_camera", "profile": "multisense_s21b", "points_stride": 4, "every_frames": 1,
          "mount": {"parent": "combine", "xyz_m": [-2.0, 7.45, 6.0], "rpy_deg": [0.0, 90.0, -90.0]}}
TOF = {"kind": "depth_camera", "profile": "kinect_class_structured_light", "range_max_m": 8.0, "points_stride": 3,
       "mount": {"parent": "combine", "xyz_m": [-3.5, 5.0, 6.0], "rpy_deg": [0.0, 52.0, 116.0]}}
LIDAR = {"kind": "lidar", "method": "beam_native"}
RGB = {"kind": "rgb_camera", "width_px": 640, "height_px": 480, "hfov_deg": 70.0,
       "mount": {"parent": "combine", "xyz_m": [-3.5, 5.0, 6.0], "rpy_deg": [0.0, 52.0, 116.0]}}
#: configuration -> the ``sensors:`` overlay on the default scenario (None: the default itself)
CONFIGS = {"lidar": None, "depth_camera": {"tof": TOF}, "stereo_camera": {"spout": STEREO},
           "stereo_camera_bm": {"spout": {**STEREO, "matcher": "bm"}}, "rgb_camera": {"mast": LIDAR, "eye": RGB},
           "lidar_and_stereo": {"mast": LIDAR, "spout": STEREO}}
#: matcher -> (scenario overrides, the published mean relative pile-height error or None)
MATCHERS = {"sgbm": ({}, 0.0335), "bm": ({"sensors.spout.matcher": "bm"}, 0.0370),
            "sgbm_3way": ({"sensors.spout.sgbm_mode": "3way"}, None)}
PUBLISHED = "Sensors 2024, 24(22):7204"


def _scaled(v, k: float) -> float | None:
    """``v * k``, None where the run had no value (too short to evaluate)."""
    return None if v is None else k * v


def _sensor_run(ctx: Context, sensors: dict | None, duration: float, out: Path) -> dict:
    """Medians per frame of one launched run: render, perception, sensor model, frame (ms); real-time factor."""
    from cosim.runtime.launcher import launch
    from cosim.scenario.config import Scenario

    sc = ctx.scenario("default", extra={"duration_s": duration})
    if sensors is not None:                        # the default's world, its LiDAR replaced by these sensors
        data = sc.model_dump(mode="json")
        data.pop("sensor")
        sc = Scenario.model_validate_json(json.dumps({**data, "sensors": sensors}))
    res = launch(sc, out, console_log=False)
    if not res.completed:
        raise RuntimeError(f"run failed: {res.error}")
    rows = list(csv.DictReader((out / "timing.csv").open()))[2:]       # past the start-up frames

    def med(col: str) -> float | None:
        v = [float(r[col]) for r in rows if col in r and r[col] not in ("", "nan")]
        return statistics.median(v) if v else None

    measure = sum((med(c) or 0.0 for c in (rows[0] if rows else {}) if c.endswith(".measure_ms")), 0.0)
    return {"render ms": med("render_state.render_ms"), "perception ms": med("perc_state.perception_ms"),
            "sensor model ms": measure, "frame ms": res.summary["timing_ms"].get("frame"),
            "real-time factor": res.summary["real_time_factor"]}


@case("sensor_cost", "what each sensor kind costs per frame (render, perception, its model) beside the default "
      "LiDAR run", options={"configs": ",".join(CONFIGS), "duration": 6.0}, quick={"configs": "lidar,depth_camera",
                                                                                  "duration": 0.5},
      rounds=3, settings=True, compare=("frame ms",))
def sensor_cost(ctx: Context) -> dict:
    """Every configuration of ``configs`` (``lidar`` always), rotating order (module docstring)."""
    names = ["lidar"] + [n for n in ctx["configs"].split(",") if n and n != "lidar"]
    unknown = set(names) - set(CONFIGS)
    if unknown:
        raise ValueError(f"unknown configurations {sorted(unknown)}; choose from {', '.join(CONFIGS)}")
    with tempfile.TemporaryDirectory(prefix="bench-sensors-") as tmp:
        rows = {n: _sensor_run(ctx, CONFIGS[n], ctx["duration"], Path(tmp) / n) for n in rotating(names, ctx.round)}
    for n in names:
        f, base = rows[n]["frame ms"], rows["lidar"]["frame ms"]
        rows[n]["frame / LiDAR's"] = f / base if f and base else None
    return {f"sensors, {ctx['duration']:g} s runs": {n: rows[n] for n in names}}


@case("stereo_pile_height", "the stereo camera's fill-height error per matcher in stereo_spout, beside the published "
      "stereo pile-height result", options={"matchers": "sgbm,bm", "duration": 120.0, "every": 30},
      quick={"matchers": "bm", "duration": 3.0, "every": 10}, settings=True)
def stereo_pile_height(ctx: Context) -> dict:
    """Each matcher of ``matchers`` (of sgbm, bm, sgbm_3way); truth every ``every`` frames (module docstring)."""
    from cosim.runtime.launcher import launch

    rows = {}
    with tempfile.TemporaryDirectory(prefix="bench-stereo-") as tmp:
        for name in ctx["matchers"].split(","):
            extra, published = MATCHERS[name]
            sc = ctx.scenario("stereo_spout", extra={**extra, "duration_s": ctx["duration"],
                                                     "perception.accuracy_every_frames": ctx["every"]})
            res = launch(sc, Path(tmp) / name, console_log=False)
            if not res.completed:
                raise RuntimeError(f"{name}: run failed: {res.error}")
            s = res.summary
            spout = s["perception"]["sensors"]["spout"]
            fill, depth = spout.get("fill_height") or {}, spout.get("depth_error") or {}
            rows[name] = {"fill height mean rel. error %": _scaled(fill.get("mean_rel_error"), 100),
                          f"published ({PUBLISHED}) %": _scaled(published, 100),
                          "height bias cm": _scaled(fill.get("bias_m"), 100),
                          "depth error mean cm": _scaled(depth.get("mean_m"), 100),
                          "depth error p99 cm": _scaled(depth.get("p99_m"), 100),
                          "% > 5 cm": _scaled(depth.get("frac_above_5cm"), 100),
                          "frames compared": spout["frames_evaluated"],
                          "max overfill cm": _scaled(s["fill"]["max_overfill_m"], 100), "spill kg": s["spill"]["mass_kg"],
                          "wall s": s["wall_time_s"]}
    return {"stereo_spout": rows}
