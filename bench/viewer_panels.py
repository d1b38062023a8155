"""CPU time of one dashboard panel drawing (PNG bytes included), per image panel, for a code tree.

    python bench/viewer_panels.py [--tree DIR] [--reps 30]           # one tree, prints JSON
    python bench/viewer_panels.py --ab OLD_DIR NEW_DIR [--rounds 4]  # interleaved A/B/A/B, Markdown table

The snapshot has a default run's payload sizes: two 640 x 480 RGBA camera images (shaded and depth-encoded),
38,400 LiDAR rows (a tilted plane and a box, 10 % invalid), a 60 x 30 truth and a 30 x 15 perceived height map
(a heap, 20 % of the perceived cells unknown); where the tree draws the point clouds in the cart frame (it takes
a ``view``), the run's view is ``lidar_and_stereo``'s (the LiDAR and a stereo camera on the combine) with the
camera's 28,625 rows (its strided pixels: ground and grain, 10 % invalid) and the machines' poses, so each
point-cloud drawing places and draws both sensors' points. Time is the drawing thread's CPU time
(``time.thread_time``), so a loaded machine slows it less than wall time would; each panel is drawn once to warm
up (OpenCV's per-thread set-up), then ``--reps`` times; the median is reported. Figures: bench/README.md.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

#: the machines' poses of the snapshot (dyn_state): the cart beside the combine, as Machine Sync holds it
POSES = {"combine_x_m": 10.0, "combine_y_m": 0.0, "combine_yaw_rad": 0.0, "tractor_x_m": 17.5, "tractor_y_m": 5.9,
         "tractor_yaw_rad": 0.0, "cart_x_m": 10.8, "cart_y_m": 5.9, "cart_yaw_rad": 0.0}


def view():
    """The ViewInfo of lidar_and_stereo, or None in a tree without one."""
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
    import numpy as np

    from cosim.viewer.snapshot import Snapshot

    rng = np.random.default_rng(0)
    cam = rng.integers(0, 255, (480, 640, 4), dtype=np.uint8)
    n = 38400
    pts = np.empty((n, 4), np.float32)
    u, v = rng.uniform(-1, 1, n), rng.uniform(0, 1, n)
    pts[:, 0] = 6 * u                      # X right
    pts[:, 1] = -4 + 2 * v * (np.abs(u) < 0.3)  # Y up: ground, and a box in the middle
    pts[:, 2] = 4 + 12 * v                 # Z forward
    pts[:, 3] = np.linalg.norm(pts[:, :3], axis=1)
    pts[rng.random(n) < 0.1] = np.nan
    x, y = np.meshgrid(np.linspace(0, 6, 60), np.linspace(0, 3, 30), indexing="ij")
    truth = (1.8 * np.exp(-((x - 1.5) ** 2 + (y - 1.5) ** 2))).astype(np.float32)
    perceived = truth[::2, ::2].copy()
    perceived[rng.random(perceived.shape) < 0.2] = np.nan
    arrays = {"lidar_points": pts, "heightmap_truth": truth, "heightmap_perceived": perceived}
    structs = {"dyn_state": dict(POSES, **{f"section{k}_fullness": 0.5 for k in range(1, 10)})}
    vi = view()
    if vi is not None:
        arrays["cam_spout_points"] = _camera_points(vi, 28625, rng)
    return Snapshot(frame=10, images={"cam0_rgb": cam, "cam1_rgb": cam, "cam0_depth": cam, "cam1_depth": cam},
                    arrays=arrays, structs=structs, frames={k: 10 for k in ("cam0_rgb", "cam1_rgb", "cam0_depth",
                                                                           "cam1_depth", *arrays)})


def measure(reps: int) -> dict:
    import inspect

    from cosim.viewer.panels import IMAGE_PANELS, render_panel

    snap = snapshot()
    params = inspect.signature(render_panel).parameters
    kw = {"view": view()} if "view" in params else {}
    out = {}
    for pid in IMAGE_PANELS:
        args = (snap, pid, (6.0, 3.0)) if "size_m" in params else (snap, pid)
        png = render_panel(*args, **kw)
        if png is None:                                 # a panel the snapshot has no blocks for
            continue
        times = []
        for _ in range(reps):
            t0 = time.thread_time()
            render_panel(*args, **kw)
            times.append((time.thread_time() - t0) * 1e3)
        out[pid] = {"cpu_ms": statistics.median(times), "png_kib": len(png) / 1024}
    return out


def run_tree(tree: str, reps: int) -> dict:
    r = subprocess.run([sys.executable, __file__, "--tree", tree, "--reps", str(reps)], capture_output=True,
                       text=True, check=True, cwd=tree)
    return json.loads(r.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", help="code tree to import cosim from (default: this script's repository)")
    ap.add_argument("--reps", type=int, default=30)
    ap.add_argument("--ab", nargs=2, metavar=("OLD", "NEW"))
    ap.add_argument("--rounds", type=int, default=4)
    args = ap.parse_args()
    if args.ab:
        res = {t: [] for t in args.ab}
        for _ in range(args.rounds):
            for t in args.ab:
                res[t].append(run_tree(t, args.reps))
        panels = list(res[args.ab[0]][0])
        print("| panel | " + " | ".join(f"{t} CPU ms (range) | KiB" for t in args.ab) + " |")
        print("|---|" + "---:|---:|" * len(args.ab))
        for pid in panels:
            cells = []
            for t in args.ab:
                v = [r[pid]["cpu_ms"] for r in res[t]]
                cells.append(f"{statistics.median(v):.2f} ({min(v):.2f}-{max(v):.2f}) | {res[t][0][pid]['png_kib']:.0f}")
            print(f"| {pid} | " + " | ".join(cells) + " |")
        return
    sys.path.insert(0, str(Path(args.tree or Path(__file__).resolve().parent.parent).resolve()))
    print(json.dumps(measure(args.reps)))


if __name__ == "__main__":
    main()
