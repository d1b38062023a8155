"""The per-sensor status records ``sensor_<name>`` of a frame (docs/cameras.md; perception_proc.blocks
``SENSOR_FIELDS``), written when a scenario names its sensors (``sensors:``).

Every frame: the share of valid data, the valid points, the model's time. On frames compared with truth:
the depth error against the exact ray cast (a camera's planar depth, the LiDAR's range: its figures in the
2-15 m working range of ``perc_state``), and the height map the sensor alone gives in the frame's perceived
cart against the true heights (perception_proc.accuracy.sensors.fill_error).
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

import perception_proc.accuracy.sensors as cacc
import perception_proc.accuracy.stage as acc
from perception_proc.blocks import SENSOR_FIELDS
from perception_proc.cameras.sensors import PerceptionCameras
from perception_proc.estimates.heightmap import height_map
from perception_proc.estimates.pointsigma import camera_sigmas, wall_sigma_xy
from perception_proc.pipeline import FrameResult, Perception

__all__ = ["sensor_values", "record_of"]


def _own_map(pipe: Perception, points: np.ndarray, res: FrameResult, camera=None,
             lfp: np.ndarray | None = None) -> np.ndarray | None:
    """The height map (nx, ny) the level-frame ``points`` (N, 3) alone give in the frame's perceived cart (None
    without a cart); ``camera``: the depth-giving camera's ``SensorFrame`` they come from (a depth camera's points
    kept clear of the walls by their own error, as in the fused map), ``lfp`` the frame's level_from_parent."""
    if not res.cart.valid:
        return None
    sc = pipe.scenario
    lfg = res.cart.level_from_grid
    walls = None
    if camera is not None and camera.kind == "depth_camera" and camera.level_from_camera is not None:
        origin = _levelled(camera.level_from_camera[None, :3, 3], lfp)[0]
        walls = wall_sigma_xy(points, origin, camera_sigmas(sc.cameras[camera.name], camera), lfg)
    return height_map(points, lfg, sc.cart, sc.controller.grid_cell_m,
                      sc.perception.min_points_per_cell, pipe.context.noise_sigma_m, wall_sigma_xy=walls).heights


def _levelled(points: np.ndarray, lfp: np.ndarray | None) -> np.ndarray:
    return points if lfp is None else points @ lfp[:3, :3].T + lfp[:3, 3]


def sensor_values(pipe: Perception, cams: PerceptionCameras, frame: int, state: Mapping[str, float],
                  ranges: np.ndarray, lidar_ms: float, res: FrameResult, lidar_acc: dict | None,
                  truth: tuple[np.ndarray, np.ndarray] | None, lfp: np.ndarray | None = None) -> dict[str, dict]:
    """Field values of every depth-giving sensor's record, by sensor name. ``ranges``: the LiDAR's (N,) m;
    ``lidar_acc``: its accuracy fields of ``perc_state`` on an evaluated frame, else None; ``truth``: copies of
    (``heightmap_truth``, ``stream``) on an evaluated frame, else None; ``lfp``: the frame's level_from_parent
    on uneven ground (perception_proc.leveling), None on flat ground."""
    sc = pipe.scenario
    out: dict[str, dict] = {}
    nan_acc = {**cacc.NAN_STATS, **cacc.NAN_FILL, "acc_evaluated": 0}
    truth_grid = scene = None
    if truth is not None:
        from cosim.world.scene import scene_from_state

        truth_grid = acc.truth_on_grid(truth[0], sc.grain.cell_m, pipe.grid, sc.cart)
        scene = scene_from_state(sc, state, truth[0], truth[1])
    name = sc.lidar_name
    if sc.lidar is not None and name in sc.depth_sensors:
        level = pipe.level_points(ranges)
        v = {"t_s": float(state.get("t_s", math.nan)), "frame": frame,
             "valid_fraction": float(np.count_nonzero(np.isfinite(ranges)) / max(len(ranges), 1)),
             "points": int(np.count_nonzero(np.isfinite(level[:, 0]))), "measure_ms": lidar_ms, **nan_acc}
        if truth_grid is not None and lidar_acc is not None:
            v.update({"acc_evaluated": 1, "depth_pixels": lidar_acc["range_beams"],
                      "depth_err_mean_m": lidar_acc["range_err_mean_2_15_m"],
                      "depth_err_median_m": lidar_acc["range_err_median_m"],
                      "depth_err_p99_m": lidar_acc["range_err_p99_2_15_m"],
                      "frac_above_5cm": lidar_acc["frac_above_5cm_2_15"],
                      "coverage": 1.0 - lidar_acc["beam_missing_frac"],
                      "spurious_frac": lidar_acc["beam_spurious_frac"]})
            own = _own_map(pipe, _levelled(level, lfp), res)
            if own is not None:
                v.update(cacc.fill_error(own, truth_grid))
        out[name] = v
    for p in cams.pipes:
        if not p.depth_giving or p.name not in cams.latest:
            continue
        v = {**cams.sensor_values(p.name), **nan_acc}
        if scene is not None and cams.latest[p.name].frame.frame == frame:
            v.update(cams.depth_accuracy(p.name, scene, state, frame))
            v["acc_evaluated"] = 1
            cam = cams.latest[p.name].frame
            own = _own_map(pipe, _levelled(cam.points, lfp), res, cam, lfp)
            if own is not None:
                v.update(cacc.fill_error(own, truth_grid))
        out[p.name] = v
    return out


def record_of(values: dict, dtype: np.dtype) -> np.ndarray:
    """A 0-d structured record of ``dtype`` (a ``sensor_<name>`` block's) holding ``values``."""
    rec = np.zeros((), dtype)
    rec[()] = tuple(values.get(n, math.nan if d == "f8" else 0) for n, _, d, _ in SENSOR_FIELDS)
    return rec
