"""CPU time of one dashboard panel drawing (PNG bytes included), per image panel of the live viewer.

The snapshot has a default run's payload sizes: two 640 x 480 RGBA camera images (shaded and depth-encoded),
38,400 LiDAR rows (a tilted plane and a box, 10 % invalid), a 60 x 30 truth and a 30 x 15 perceived height map (a
heap, 20 % of the perceived cells unknown), and two camera sensors: a 640 x 480 colour camera and a 512 x 424
depth camera's measured depth (m, 5 % holes). Where the tree draws the point clouds in the cart frame (its
``render_panel`` takes a ``view``), the run's view is ``lidar_and_stereo``'s (the LiDAR and a stereo camera on the
combine) with the stereo camera's 28,625 rows (its strided pixels: ground and grain, 10 % invalid) and the
machines' poses, so each point-cloud drawing places and draws both sensors' points. Time is the drawing thread's CPU time (``time.thread_time``), so a
loaded machine slows it less than wall time would; each panel is drawn once to warm up (OpenCV's per-thread
set-up), then ``reps`` times; the median is reported.
"""
from __future__ import annotations

import statistics
import time

from harness import Context, case

__all__ = ["snapshot", "view", "viewer_panels"]

#: the machines' poses of the snapshot (dyn_state): the cart beside the combine, as Machine Sync holds it
POSES = {"combine_x_m": 10.0, "combine_y_m": 0.0, "combine_yaw_rad": 0.0, "tractor_x_m": 17.5, "tractor_y_m": 5.9,
         "tractor_yaw_rad": 0.0, "cart_x_m": 10.8, "cart_y_m": 5.9, "cart_yaw_rad": 0.0}


def view():
    """The ``cosim.viewer.viewinfo.ViewInfo`` of lidar_and_stereo, or None in a tree without one."""
    try:
        from cosim.scenario.loader import load_scenario, resolve_scenario_arg
        from cosim.viewer.viewinfo import ViewInfo
    except ImportError:
        return None
    return ViewInfo.of(load_scenario(resolve_scenario_arg("lidar_and_stereo")))


def _camera_points(v, n, rng):
    """(n, 4) float32 rows of the stereo camera of view ``v``: grain and ground seen from its mount, 10 % NaN."""
    import numpy as np

    from cosim.viewer.clouds import grid_from_sensor

    cam = next(s for s in v.sensors if s.kind == "stereo_camera")
    g = grid_from_sensor(v.cart, cam, POSES)
    grid = np.column_stack([rng.uniform(-2, 7, n), rng.uniform(-2, 4, n), np.zeros(n)])
    inside = (grid[:, 0] > 0) & (grid[:, 0] < 6) & (grid[:, 1] > 0) & (grid[:, 1] < 3)
    grid[:, 2] = np.where(inside, 1.0 + 0.5 * np.exp(-((grid[:, 0] - 1.5) ** 2)), -v.cart.floor_height_m)
    p = (grid - g[:3, 3]) @ g[:3, :3]                       # grid -> camera axes
    out = np.column_stack([p, np.linalg.norm(p, axis=1)]).astype(np.float32)
    out[rng.random(n) < 0.1] = np.nan
    return out


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
    vi = view()
    if vi is not None:
        arrays["cam_spout_points"] = _camera_points(vi, 28625, rng)
    structs = {"dyn_state": dict(POSES, **{f"section{k}_fullness": 0.5 for k in range(1, 10)})}
    return Snapshot(frame=10, images=images, arrays=arrays, structs=structs,
                    frames={k: 10 for k in (*images, *arrays)})


@case("viewer_panels", "CPU time of one dashboard panel drawing (PNG included), per image panel",
      options={"reps": 30}, quick={"reps": 2}, rounds=4, compare=("CPU ms",))
def viewer_panels(ctx: Context) -> dict:
    """Every image panel of ``cosim.viewer.panels`` drawn ``reps`` times from :func:`snapshot`."""
    import inspect

    from cosim.viewer.panels import IMAGE_PANELS, render_panel

    snap = snapshot()
    params = inspect.signature(render_panel).parameters
    kw = {"view": view()} if "view" in params else {}
    rows = {}
    for pid in IMAGE_PANELS:
        args = (snap, pid, (6.0, 3.0)) if "size_m" in params else (snap, pid)
        png = render_panel(*args, **kw)
        if png is None:                                   # a panel this tree's snapshot has nothing for
            continue
        times = []
        for _ in range(ctx["reps"]):
            t0 = time.thread_time()
            render_panel(*args, **kw)
            times.append((time.thread_time() - t0) * 1e3)
        rows[pid] = {"CPU ms": statistics.median(times), "PNG KiB": len(png) / 1024}
    return {"panel drawings": rows}
