"""Depth accuracy of the GL renderer against the exact ray cast, linear vs mishandled gamma.

Renders the default scene's sample frame with one 640 x 480 camera (hfov 60 deg) on the LiDAR mount, decodes
the bytes with Eq 3, and compares with the planar depth of an exact ray cast of the same scene
(``cosim.world.raycast``) at every pixel centre. Depth edges (3 x 3 neighbourhood spanning more than
EDGE_M in exact depth) are reported separately. Prints a Markdown table. Usage: ``python bench/render_accuracy.py``.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from scipy.ndimage import maximum_filter, minimum_filter  # noqa: E402

from cosim.scenario.config import Scenario  # noqa: E402
from cosim.scenario.config.sensing import Codec  # noqa: E402
from cosim.world.camera import Pinhole, Rig, RigCamera  # noqa: E402
from cosim.world.raycast import raycast  # noqa: E402
from cosim.world.scene import scene_from_state  # noqa: E402
from renderer_proc.codec import decode_depth  # noqa: E402
from renderer_proc.gl_backend import GLRenderer  # noqa: E402
from renderer_proc.projection import camera_poses, pixel_rays  # noqa: E402
from renderer_proc.sample import sample_frame  # noqa: E402

#: neighbourhood depth span that marks a depth edge, m
EDGE_M = 0.05
W, H, HFOV_DEG = 640, 480, 60.0


def main() -> None:
    s = Scenario(format_version=1)
    state, heights, stream = sample_frame(s)
    scene = scene_from_state(s, state, heights, stream)
    cam = Pinhole(W, H, math.radians(HFOV_DEG))
    rig = Rig((RigCamera("cam0", cam, np.eye(4)),))
    pose = camera_poses(s, state, rig)[0]
    origin, dirs, cos = pixel_rays(cam, pose)
    t0 = time.perf_counter()
    t = raycast(scene, np.broadcast_to(origin, (W * H, 3)), dirs.reshape(-1, 3)).reshape(H, W)
    cast_s = time.perf_counter() - t0
    exact = t * cos
    exact = np.where(exact < s.sensor.codec.max_depth_m, exact, np.nan)
    edge = (maximum_filter(np.nan_to_num(exact, nan=1e3), 3) - minimum_filter(np.nan_to_num(exact, nan=1e3), 3)) > EDGE_M
    print(f"GL depth vs exact ray cast: default scene sample frame, one {W} x {H} camera, hfov {HFOV_DEG:g} deg; "
          f"ray cast of {W * H} pixels took {cast_s:.2f} s\n")
    print("| gamma mode | valid px agree | px compared | mean abs err (mm) | p99 (mm) | max (mm) | "
          "within beta/510 | max at edges (mm) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for mode in ("linear", "mishandled"):
        codec = Codec(gamma_mode=mode)
        r = GLRenderer(rig, codec)
        r.set_scene(scene)
        r.draw(0, pose)
        img = np.zeros((H, W, 4), np.uint8)
        r.read_depth(0, img)
        r.close()
        d = decode_depth(img, codec)
        agree = np.mean(np.isfinite(d) == np.isfinite(exact))
        both = np.isfinite(d) & np.isfinite(exact)
        err = np.abs(d - exact)
        inner = both & ~edge
        e = err[inner] * 1e3
        print(f"| {mode} | {agree:.4f} | {inner.sum()} | {e.mean():.3f} | {np.percentile(e, 99):.3f} | "
              f"{e.max():.1f} | {np.mean(e <= codec.bound_m * 1e3 + 0.02):.4f} | "
              f"{err[both & edge].max() * 1e3:.0f} |")


if __name__ == "__main__":
    main()
