"""The same plug-in in ``cosim.Simulation`` (one process): step the run, read what the camera gave perception.

    python examples/own_camera_perception/in_python.py
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cosim import Simulation

HERE = Path(__file__).resolve().parent
QUICK = os.environ.get("GRAINCOSIM_EXAMPLE_QUICK") == "1"


def main() -> None:
    frames = 10 if QUICK else 100
    with Simulation(HERE / "scenario.yaml", duration=frames * 0.1 + 0.1) as sim:
        state = sim.step(frames)
        heights = state["heightmap_perceived"]         # array blocks by name: read-only live views
        rgb = state["cam_rgbd_rgb"]
        depth = state["cam_rgbd_measured"]
        print(f"frame {state['frame']:.0f}: cart found {state['perc_state.cart_valid']:.0f}, "
              f"{np.count_nonzero(np.isfinite(heights))} of {heights.size} cells measured, "
              f"colour image {rgb.shape}, {np.count_nonzero(np.isfinite(depth))} valid depth pixels")


if __name__ == "__main__":
    main()
