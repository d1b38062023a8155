"""CPU time of one dashboard panel drawing (PNG bytes included), per image panel of the live viewer.

The snapshot has a default run's payload sizes: two 640 x 480 RGBA camera images (shaded and depth-encoded),
38,400 LiDAR rows (a tilted plane and a box, 10 % invalid), a 60 x 30 truth and a 30 x 15 perceived height map (a
heap, 20 % of the perceived cells unknown), and two camera sensors: a 640 x 480 colour camera and a 512 x 424
depth camera's measured depth (m, 5 % holes). Time is the drawing thread's CPU time (``time.thread_time``), so a
loaded machine slows it less than wall time would; each panel is drawn once to warm up (OpenCV's per-thread
set-up), then ``reps`` times; the median is reported.
"""
from __future__ import annotations

import statistics
import time

from harness import Context, case

__all__ = ["snapshot", "viewer_panels"]


def snapshot():
    """A ``cosim.viewer.snapshot.Snapshot`` with a default run's payload sizes (module docstring)."""
    import numpy as np

    from cosim.viewer.snapshot import Snapshot

    rng = np.random.default_rng(0)
    cam = rng.integers(0, 255, (480, 640, 4), dtype=np.uint8)
    n = 38400
    pts = np.empty((n, 4), np.float32)
    u, v = rng.uniform(-1, 1, n), rng.uniform(0, 1, n)
    pts[:, 0] = 6 * u                                   # X right
    pts[:, 1] = -4 + 2 * v * (np.abs(u) < 0.3)          # Y up: ground, and a box in the middle
    pts[:, 2] = 4 + 12 * v                              # Z forward
    pts[:, 3] = np.linalg.norm(pts[:, :3], axis=1)
    pts[rng.random(n) < 0.1] = np.nan
    x, y = np.meshgrid(np.linspace(0, 6, 60), np.linspace(0, 3, 30), indexing="ij")
    truth = (1.8 * np.exp(-((x - 1.5) ** 2 + (y - 1.5) ** 2))).astype(np.float32)
    perceived = truth[::2, ::2].copy()
    perceived[rng.random(perceived.shape) < 0.2] = np.nan
    measured = (2.0 + 3.0 * rng.random((424, 512))).astype(np.float32)
    measured[rng.random(measured.shape) < 0.05] = np.nan
    images = {"cam0_rgb": cam, "cam1_rgb": cam, "cam0_depth": cam, "cam1_depth": cam, "cam_eye_rgb": cam}
    arrays = {"lidar_points": pts, "heightmap_truth": truth, "heightmap_perceived": perceived,
              "cam_tof_measured": measured}
    return Snapshot(frame=10, images=images, arrays=arrays, frames={k: 10 for k in (*images, *arrays)})


@case("viewer_panels", "CPU time of one dashboard panel drawing (PNG included), per image panel",
      options={"reps": 30}, quick={"reps": 2}, rounds=4, compare=("CPU ms",))
def viewer_panels(ctx: Context) -> dict:
    """Every image panel of ``cosim.viewer.panels`` drawn ``reps`` times from :func:`snapshot`."""
    import inspect

    from cosim.viewer.panels import IMAGE_PANELS, render_panel

    snap = snapshot()
    metres = "size_m" in inspect.signature(render_panel).parameters
    rows = {}
    for pid in IMAGE_PANELS:
        args = (snap, pid, (6.0, 3.0)) if metres and pid == "heightmaps" else (snap, pid)
        png = render_panel(*args)
        if png is None:                                   # a panel this tree's snapshot has nothing for
            continue
        times = []
        for _ in range(ctx["reps"]):
            t0 = time.thread_time()
            render_panel(*args)
            times.append((time.thread_time() - t0) * 1e3)
        rows[pid] = {"CPU ms": statistics.median(times), "PNG KiB": len(png) / 1024}
    return {"panel drawings": rows}
