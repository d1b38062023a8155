"""The per-pixel cost behind the camera pixel budget (cosim.scenario.sizes.CAMERA_PIXEL_BUDGET, docs/cameras.md):
the depth camera's noise model, the costliest per-pixel stage, timed and its peak memory traced on a 1280 x 960
image.

    python bench/camera_pixel_cost.py
"""
from __future__ import annotations

import time
import tracemalloc

import numpy as np

from cosim.scenario.config.cameras import DepthCamera
from cosim.scenario.memory import size_text
from cosim.scenario.sizes import CAMERA_PIXEL_BUDGET
from cosim.world.camera import Pinhole
from perception_proc.cameras.tof import frame_generator, tof_depth

__all__ = ["main"]

#: the image measured, px
WIDTH, HEIGHT = 1280, 960
#: timed repetitions
ROUNDS = 3


def main() -> None:
    """Print the model's time and peak memory a pixel, and what the budget costs a frame at that rate."""
    cam = DepthCamera(kind="depth_camera", mount={"parent": "combine"}, width_px=WIDTH, height_px=HEIGHT)
    pin = Pinhole(WIDTH, HEIGHT, float(np.radians(60.0)))
    z = np.random.default_rng(0).uniform(2.0, 8.0, (HEIGHT, WIDTH)).astype(np.float32)
    tof_depth(z, pin, cam, frame_generator(0, 0, 0))
    t = time.perf_counter()
    for i in range(ROUNDS):
        tof_depth(z, pin, cam, frame_generator(0, i, 0))
    ns = (time.perf_counter() - t) / ROUNDS / z.size * 1e9
    tracemalloc.start()
    tof_depth(z, pin, cam, frame_generator(0, 9, 0))
    peak = tracemalloc.get_traced_memory()[1] / z.size
    print(f"depth camera noise model: {ns:.0f} ns and {peak:.0f} B a pixel; the budget of {CAMERA_PIXEL_BUDGET:,} "
          f"pixels: {CAMERA_PIXEL_BUDGET * ns * 1e-9:.1f} s and {size_text(CAMERA_PIXEL_BUDGET * peak)} a frame")


if __name__ == "__main__":
    main()
