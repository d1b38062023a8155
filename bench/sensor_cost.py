"""What each sensor kind costs per frame, side by side with the default scenario's LiDAR (docs/cameras.md).

Configurations, each the default scenario's world with other sensors (``sensors:``), GL renderer, perception
feedback, every sensor taking an image every frame (``every_frames: 1``):

* ``lidar``: the default scenario itself (beam-native Honeycomb-like LiDAR, 38,400 beams);
* ``depth_camera``: the ``tof_mast`` camera (Kinect-class profile, 512 x 424);
* ``stereo_camera``: the ``stereo_spout`` head (MultiSense S21B profile, 2 x 1024 x 544, SGBM, 128 disparities);
* ``stereo_camera_bm``: the same with StereoBM;
* ``rgb_camera``: a 640 x 480 colour camera beside the LiDAR (nothing in perception uses it: its cost is the
  renderer's);
* ``lidar_and_stereo``: the LiDAR and the stereo head, fused.

Each runs ``--duration`` simulated seconds through the real launcher (OS processes), the configurations
interleaved ``--reps`` times; the table gives the medians per frame of the renderer's step, perception's step
and the sensor model (``sensor_<name>.measure_ms``: the depth camera's noise model, the stereo matcher), the
frame, and each configuration's frame time over the LiDAR's measured in the same round (median of the rounds'
ratios). Usage: ``python bench/sensor_cost.py --duration 6 --reps 3``.
"""
from __future__ import annotations

import argparse
import csv
import json
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.runtime.launcher import launch  # noqa: E402
from cosim.scenario.config import Scenario  # noqa: E402
from cosim.scenario.loader import load_scenario, packaged_scenarios  # noqa: E402

STEREO = {"kind": "stereo_camera", "profile": "multisense_s21b", "points_stride": 4, "every_frames": 1,
          "mount": {"parent": "combine", "xyz_m": [-2.0, 7.45, 6.0], "rpy_deg": [0.0, 90.0, -90.0]}}
TOF = {"kind": "depth_camera", "profile": "tof_kinect_class", "range_max_m": 8.0, "points_stride": 3,
       "mount": {"parent": "combine", "xyz_m": [-3.5, 5.0, 6.0], "rpy_deg": [0.0, 52.0, 116.0]}}
LIDAR = {"kind": "lidar", "method": "beam_native"}
RGB = {"kind": "rgb_camera", "width_px": 640, "height_px": 480, "hfov_deg": 70.0,
       "mount": {"parent": "combine", "xyz_m": [-3.5, 5.0, 6.0], "rpy_deg": [0.0, 52.0, 116.0]}}
#: configuration -> the ``sensors:`` overlay on the default scenario (None: the default itself)
CONFIGS = {
    "lidar": None,
    "depth_camera": {"tof": TOF},
    "stereo_camera": {"spout": STEREO},
    "stereo_camera_bm": {"spout": {**STEREO, "matcher": "bm"}},
    "rgb_camera": {"mast": LIDAR, "eye": RGB},
    "lidar_and_stereo": {"mast": LIDAR, "spout": STEREO},
}


def run_once(sensors: dict | None, duration: float, out: Path) -> dict:
    """Medians per frame of one launched run: render, perception, sensor model, frame (ms)."""
    sc = load_scenario(packaged_scenarios()["default"], extra={"duration_s": duration})
    if sensors is not None:                        # the default's world, its LiDAR replaced by these sensors
        data = sc.model_dump(mode="json")
        data.pop("sensor")
        sc = Scenario.model_validate_json(json.dumps({**data, "sensors": sensors}))
    res = launch(sc, out, console_log=False)
    if not res.completed:
        raise RuntimeError(f"run failed: {res.error}")
    rows = list(csv.DictReader((out / "timing.csv").open()))[2:]       # past the start-up frames

    def med(col: str) -> float:
        v = [float(r[col]) for r in rows if col in r and r[col] not in ("", "nan")]
        return statistics.median(v) if v else float("nan")

    measure = sum(med(c) for c in (rows[0] if rows else {}) if c.endswith(".measure_ms"))
    t = res.summary["timing_ms"]
    return {"render": med("render_state.render_ms"), "perception": med("perc_state.perception_ms"),
            "measure": measure, "frame": t.get("frame", float("nan")), "rtf": res.summary["real_time_factor"]}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=6.0, help="simulated seconds per run")
    ap.add_argument("--reps", type=int, default=3, help="interleaved rounds of every configuration")
    ap.add_argument("--only", default="", help="comma-separated configurations (default all; lidar always runs)")
    args = ap.parse_args(argv)
    names = [n for n in CONFIGS if not args.only or n == "lidar" or n in args.only.split(",")]
    got: dict[str, list[dict]] = {n: [] for n in names}
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(args.reps):
            for n in names:
                got[n].append(run_once(CONFIGS[n], args.duration, Path(tmp) / f"{n}{rep}"))
                print(f"round {rep + 1} {n}: {got[n][-1]}", file=sys.stderr, flush=True)
    print("| sensors | render ms | perception ms | sensor model ms | frame ms | frame / LiDAR's | real-time factor |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for n in names:
        rows = got[n]
        ratio = statistics.median(r["frame"] / b["frame"] for r, b in zip(rows, got["lidar"]))
        m = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
        print(f"| {n} | {m['render']:.1f} | {m['perception']:.1f} | {m['measure']:.1f} | {m['frame']:.1f} | "
              f"{ratio:.2f} | {m['rtf']:.2f} |")


if __name__ == "__main__":
    main()
