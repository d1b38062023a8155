"""One camera's images of a frame as perception holds them (:class:`CameraImages`), the value passed from the
camera pipeline (perception_proc.cameras.pipeline) through its effects (perception_proc.cameras.effects, such as
dust: perception_proc.atmosphere.camera), and the distance at which a camera's typical depth error is quoted.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CameraImages", "SIGMA_DISTANCE_M"]

#: distance at which a camera's typical depth 1-sigma is quoted to the built-in algorithm (the cart seen
#: from a spout or a mast), m
SIGMA_DISTANCE_M = 3.0

@dataclass
class CameraImages:
    """One camera's images of a frame (copies): ``rgb`` / ``right`` (H, W, 4) uint8, ``depth`` (H, W) float32
    exact planar depth m, ``labels`` (H, W) uint8; each None where the camera has no such part; ``t_s`` the run
    time of the state they show, s (what time-varying effects such as a dust gust go by)."""

    frame: int
    rgb: np.ndarray | None = None
    right: np.ndarray | None = None
    depth: np.ndarray | None = None
    labels: np.ndarray | None = None
    t_s: float = 0.0
