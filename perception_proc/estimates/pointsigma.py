"""Each point's expected 1-sigma from its own sensor's error model, in the order of ``PerceptionInput.points``
(the LiDAR's returns, then each depth-giving camera's pixels in declaration order): the LiDAR's range sigma,
Z^2 dd / (f B) for a stereo pair, the depth model's axial sigma for a depth camera
(perception_proc.cameras.expected.point_sigma_m, Z the point's planar depth in its camera)."""
from __future__ import annotations

import numpy as np

from perception_proc.cameras.expected import point_sigma_m
from perception_proc.protocol import PerceptionContext, PerceptionInput

__all__ = ["CAMERA_DEPTH", "point_sigmas"]

#: the sensor kinds whose frames carry depth pixels
CAMERA_DEPTH = ("depth_camera", "stereo_camera")


def point_sigmas(ctx: PerceptionContext, inp: PerceptionInput) -> np.ndarray:
    """(N,) float64 m, one per row of ``inp.points``; the context's typical sigma everywhere when the sensors'
    frames do not add up to the merged points (an algorithm's own input)."""
    sc = ctx.scenario
    parts = []
    for f in inp.sensors.values():
        if f.kind == "lidar":
            parts.append(np.full(len(f.points), sc.lidar.noise.range_sigma_m))
        elif f.kind in CAMERA_DEPTH and len(f.points):
            lfc = f.level_from_camera
            z = np.asarray(f.ranges, np.float64) if lfc is None else \
                (np.asarray(f.points, np.float64) - lfc[:3, 3]) @ lfc[:3, 2]      # planar depth, m
            parts.append(np.asarray(point_sigma_m(sc.cameras[f.name], float(f.K[0, 0]), z), np.float64))
    out = np.concatenate(parts) if parts else np.zeros(0)
    if out.shape[0] != len(inp.points):
        return np.full(len(inp.points), ctx.noise_sigma_m)
    return out
