"""Rig planning: cameras and pixels the planner picks for a LiDAR pattern and angular error bound.

For the default (Honeycomb-like, 90 x 95 deg) pattern and a narrower pattern aimed at the cart, at several
bounds: the rig (fewest cameras, then fewest pixels), total pixels, and the measured worst nearest-pixel
angular error over the beam table. Prints a Markdown table. Usage: ``python bench/render_rig.py``.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.scenario.config import Scenario  # noqa: E402
from cosim.world.rig import beam_angles, beam_pixel_error, plan_rig  # noqa: E402

PATTERNS = {
    "default honeycomb 90 x 95 deg, 240 x 160": {},
    "grid 120 x 40 deg, 480 x 64": {"preset": "grid", "azimuth_min_deg": -60.0, "azimuth_max_deg": 60.0,
                                    "elevation_min_deg": -20.0, "elevation_max_deg": 20.0,
                                    "azimuth_count": 480, "elevation_count": 64},
    "grid 200 x 30 deg, 800 x 32": {"preset": "grid", "azimuth_min_deg": -100.0, "azimuth_max_deg": 100.0,
                                    "elevation_min_deg": -15.0, "elevation_max_deg": 15.0,
                                    "azimuth_count": 800, "elevation_count": 32},
}


def main() -> None:
    print("| pattern | bound (deg) | cameras | sizes | pixels | worst error (deg) | plan (ms) |")
    print("|---|---:|---:|---|---:|---:|---:|")
    for label, pattern in PATTERNS.items():
        for bound in (0.05, 0.1, 0.2, 0.5):
            s = Scenario.model_validate({"format_version": 1, "sensor": {"pattern": pattern,
                                                                         "max_angular_error_deg": bound}})
            t0 = time.perf_counter()
            rig = plan_rig(s)
            ms = (time.perf_counter() - t0) * 1e3
            el, az = beam_angles(s.sensor.pattern)
            err, cam = beam_pixel_error(rig, el, az)
            assert (cam >= 0).all()
            sizes = ", ".join(f"{c.intrinsics.width}x{c.intrinsics.height}" for c in rig.cameras)
            px = sum(c.intrinsics.width * c.intrinsics.height for c in rig.cameras)
            print(f"| {label} | {bound:g} | {len(rig)} | {sizes} | {px:,} | {math.degrees(err.max()):.4f} | {ms:.0f} |")


if __name__ == "__main__":
    main()
