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

__all__ = ["main", "noise_model_input", "peak_bytes"]

#: the image measured, px
WIDTH, HEIGHT = 1280, 960
#: timed repetitions
ROUNDS = 3


def noise_model_input(width: int = WIDTH, height: int = HEIGHT) -> tuple[np.ndarray, Pinhole, DepthCamera]:
    """(depth (H, W) float32 m, uniform in 2-8 m; pinhole of 60 deg; the default depth camera) for the model."""
    cam = DepthCamera(kind="depth_camera", mount={"parent": "combine"}, width_px=width, height_px=height)
    pin = Pinhole(width, height, float(np.radians(60.0)))
    z = np.random.default_rng(0).uniform(2.0, 8.0, (height, width)).astype(np.float32)
    return z, pin, cam


def peak_bytes(z: np.ndarray, pin: Pinhole, cam: DepthCamera) -> int:
    """The noise model's peak traced memory (tracemalloc) for one frame of ``z``, bytes (after one untraced call,
    so that nothing made once is counted)."""
    tof_depth(z, pin, cam, frame_generator(0, 0, 0))
    tracemalloc.start()
    try:
        tof_depth(z, pin, cam, frame_generator(0, 9, 0))
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def main() -> None:
    """Print the model's time and peak memory a pixel, and what the budget costs a frame at that rate."""
    z, pin, cam = noise_model_input()
    tof_depth(z, pin, cam, frame_generator(0, 0, 0))
    t = time.perf_counter()
    for i in range(ROUNDS):
        tof_depth(z, pin, cam, frame_generator(0, i, 0))
    ns = (time.perf_counter() - t) / ROUNDS / z.size * 1e9
    peak = peak_bytes(z, pin, cam) / z.size
    print(f"depth camera noise model: {ns:.0f} ns and {peak:.0f} B a pixel; the budget of {CAMERA_PIXEL_BUDGET:,} "
          f"pixels: {CAMERA_PIXEL_BUDGET * ns * 1e-9:.1f} s and {size_text(CAMERA_PIXEL_BUDGET * peak)} a frame")


if __name__ == "__main__":
    main()
