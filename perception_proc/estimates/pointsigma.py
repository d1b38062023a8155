"""Each point's expected 1-sigma from its own sensor's error model, in the order of ``PerceptionInput.points``
(the LiDAR's returns, then each depth-giving camera's pixels in declaration order): the LiDAR's range sigma,
Z^2 dd / (f B) for a stereo pair, the depth model's axial sigma for a depth camera
(perception_proc.cameras.expected.point_sigma_m, Z the point's planar depth in its camera).

:func:`wall_sigmas` turns a depth camera's into each point's error across the cart's walls: a depth error lies along
the point's ray, so its component along grid x (y) is sigma times the ray's x (y) direction cosine in the grid
frame (:func:`wall_sigma_xy`). The height map keeps a point 3 of that plus its clearance inside each wall: a far
wall's face seen head-on, whose points the model's (z - z0)^2 law spreads tens of cm into the cart, no longer reads
as grain at the wall's height."""
from __future__ import annotations

import numpy as np

from perception_proc.cameras.expected import point_sigma_m
from perception_proc.protocol import PerceptionContext, PerceptionInput

__all__ = ["CAMERA_DEPTH", "camera_sigmas", "point_sigmas", "wall_sigma_xy", "wall_sigmas"]

#: the sensor kinds whose frames carry depth pixels
CAMERA_DEPTH = ("depth_camera", "stereo_camera")


def camera_sigmas(spec, f) -> np.ndarray:
    """(M,) float64 m: the expected depth 1-sigma of each point of the depth-giving camera frame ``f``
    (``SensorFrame``) of camera ``spec``, at its planar depth."""
    lfc = f.level_from_camera
    z = np.asarray(f.ranges, np.float64) if lfc is None else \
        (np.asarray(f.points, np.float64) - lfc[:3, 3]) @ lfc[:3, 2]              # planar depth, m
    return np.asarray(point_sigma_m(spec, float(f.K[0, 0]), z), np.float64)


def point_sigmas(ctx: PerceptionContext, inp: PerceptionInput) -> np.ndarray:
    """(N,) float64 m, one per row of ``inp.points``; the context's typical sigma everywhere when the sensors'
    frames do not add up to the merged points (an algorithm's own input)."""
    sc = ctx.scenario
    parts = []
    for f in inp.sensors.values():
        if f.kind == "lidar":
            parts.append(np.full(len(f.points), sc.lidar.noise.range_sigma_m))
        elif f.kind in CAMERA_DEPTH and len(f.points):
            parts.append(camera_sigmas(sc.cameras[f.name], f))
    out = np.concatenate(parts) if parts else np.zeros(0)
    if out.shape[0] != len(inp.points):
        return np.full(len(inp.points), ctx.noise_sigma_m)
    return out


def wall_sigma_xy(points: np.ndarray, origin: np.ndarray, sigma: np.ndarray,
                  level_from_grid: np.ndarray) -> np.ndarray:
    """(M, 2) float64 m: the 1-sigma along grid x and y of an error ``sigma`` (M,) m along each point's ray,
    ``points`` (M, 3) level frame from the sensor at ``origin`` (3,) level frame: sigma |d . x_grid| and
    sigma |d . y_grid| with d the ray's unit direction; NaN for NaN points or a point at the origin."""
    d = np.asarray(points, np.float64) - np.asarray(origin, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(d @ level_from_grid[:3, :2]) / np.linalg.norm(d, axis=1)[:, None]
    return cos * np.asarray(sigma, np.float64)[:, None]


def wall_sigmas(ctx: PerceptionContext, inp: PerceptionInput, level_from_grid: np.ndarray) -> np.ndarray | None:
    """(N, 2) float64 m, one row per row of ``inp.points``: each point's error across the walls. A depth camera's
    points take :func:`wall_sigma_xy` of their model's sigma; the LiDAR's returns its range sigma along both axes
    (the rule of a LiDAR alone); a stereo camera's points the context's typical sigma (the rule its figures in
    docs/cameras.md were measured with). None without a depth camera's points, or when the sensors' frames do not
    add up to the merged points: the height map's scalar rule then holds."""
    sc = ctx.scenario
    parts, depth = [], False
    for f in inp.sensors.values():
        if f.kind == "lidar":
            parts.append(np.full((len(f.points), 2), sc.lidar.noise.range_sigma_m))
        elif f.kind == "depth_camera" and len(f.points) and f.level_from_camera is not None:
            parts.append(wall_sigma_xy(f.points, f.level_from_camera[:3, 3], camera_sigmas(sc.cameras[f.name], f),
                                       level_from_grid))
            depth = True
        elif f.kind in CAMERA_DEPTH and len(f.points):
            parts.append(np.full((len(f.points), 2), ctx.noise_sigma_m))
    if not depth:
        return None
    out = np.concatenate(parts)
    return out if out.shape[0] == len(inp.points) else None
