"""The ``atmosphere:`` block applied to a LiDAR frame: dust (perception_proc.atmosphere.dust) and the grain stream's
kernels (perception_proc.atmosphere.stream), one reported return per beam (docs/field.md).

:class:`LidarAtmosphere` is made once per run (None in clear air with a solid stream: nothing is applied, the
ranges pass to the bit); :meth:`LidarAtmosphere.apply` maps the frame's exact ranges (the renderer's first hits,
the stream left out of the scene when it is particles) to what the sensor reports, before the sensor's own noise
and limits. The hard target's, each kernel's and the dust's returns compete per beam: the strongest, or the last
above the detection limit, is reported. Seeded per frame; deterministic.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from cosim.scenario.config import Scenario
from perception_proc.atmosphere.crossings import beam_crossings
from perception_proc.atmosphere.dust import DustModel, dust_blows, dust_model, hard_power
from perception_proc.atmosphere.stream import STREAM_PARTICLES, kernel_density, occlude

__all__ = ["LidarAtmosphere", "lidar_atmosphere", "stream_row_time"]

GRAVITY_MPS2 = 9.80665


def stream_row_time(rows: np.ndarray, exit_speed_mps: float, exit_down_rad: float) -> float:
    """Time (s) between consecutive ``rows`` (M, 4) of the stream, which sample its parabola at equal times from
    the spout to the impact: the fall time T of ``z_end - z_0 = -v sin(down) T - g T^2 / 2`` over M - 1."""
    vz = -exit_speed_mps * math.sin(exit_down_rad)
    drop = float(rows[0, 2] - rows[-1, 2])
    t = (vz + math.sqrt(vz * vz + 2.0 * GRAVITY_MPS2 * max(drop, 0.0))) / GRAVITY_MPS2
    return max(t, 1e-6) / max(len(rows) - 1, 1)


class LidarAtmosphere:
    """What the LiDAR of ``scenario`` reports through its atmosphere; ``directions`` (N, 3) its unit beams,
    sensor frame."""

    def __init__(self, scenario: Scenario, directions: np.ndarray, dust: DustModel | None):
        a = scenario.atmosphere
        self.scenario, self.directions, self.dust = scenario, np.asarray(directions, np.float64), dust
        self.particles = a.stream_particles
        self.p_min = float(hard_power(scenario.lidar.range_max_m, 0.0, a.detection_reflectivity, 0.0, 0.0))
        self.last = a.return_mode == "last"

    def apply(self, ranges: np.ndarray, frame: int, state: Mapping[str, float], stream: np.ndarray | None,
              world_from_sensor: np.ndarray) -> np.ndarray:
        """The reported ranges (N,) float32 m (NaN: no return) for the exact first hits ``ranges`` (N,) float32 m
        of frame ``frame``; ``state`` the frame's ``dyn_state`` (its time and flow), ``stream`` its ``stream``
        rows (M, 4) (world), ``world_from_sensor`` (4, 4). New array."""
        dust = self.dust
        if dust is not None and not dust_blows(self.scenario.atmosphere, float(state.get("t_s", 0.0))):
            dust = None                                              # outside the gust: clear air
        out = dust.returns(ranges) if dust is not None else np.array(ranges, np.float32)
        n_rows = int(state.get("stream_points", 0)) if state else 0
        flow = float(state.get("flow_m3ps", 0.0)) if state else 0.0
        if not self.particles or stream is None or n_rows < 2 or flow <= 0.0:
            return out
        a, sc = self.scenario.atmosphere, self.scenario
        rows = np.asarray(stream[:n_rows], np.float64)
        origin = world_from_sensor[:3, 3]
        beams, seg, mids, chords = beam_crossings(origin, self.directions, rows, world_from_sensor[:3, :3])
        if beams.size == 0:
            return out
        dt = stream_row_time(rows, sc.auger.exit_speed_mps, math.radians(sc.auger.exit_down_deg))
        density = kernel_density(rows, flow, a.packing_fraction, a.kernel_diameter_m, dt)[seg]
        rng = np.random.default_rng(np.random.SeedSequence(sc.seed, spawn_key=(STREAM_PARTICLES, frame)))
        r0 = np.asarray(ranges, np.float64)
        ids, row, kr, took, left = occlude(r0, beams, mids, chords, density, a.kernel_diameter_m,
                                           a.beam_divergence_mrad * 1e-3, rng)
        if ids.size == 0:
            return out
        alpha = dust.alpha if dust is not None else 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            kp = (a.kernel_reflectivity / math.pi) * took * np.exp(-2.0 * alpha * kr) / (kr * kr)
        kp = np.where(kr > 0.0, kp, 0.0)
        hp = hard_power(r0[ids], alpha, a.target_reflectivity, 0.0, 0.0) * left
        out[ids] = self._choose(row, kr, kp, r0[ids], hp, dust)
        return out

    def _choose(self, row: np.ndarray, kr: np.ndarray, kp: np.ndarray, r0: np.ndarray, hp: np.ndarray,
                dust: DustModel | None) -> np.ndarray:
        """Per beam with kernels (``row``: each kernel's beam, 0..B-1; ``r0``, ``hp`` (B,) its target's range and
        power): the reported range among its kernels, its target and the dust, strongest or last above the
        detection limit."""
        n = len(r0)
        seen = kp >= self.p_min
        best = np.full(n, -1.0)
        if self.last:                                                 # the farthest detected return
            far = np.full(n, -np.inf)
            np.maximum.at(far, row[seen], kr[seen])
            res = np.where(hp >= self.p_min, r0, np.where(np.isfinite(far), far, np.nan))
        else:                                                         # the strongest detected return
            res = np.full(n, np.nan)
            np.maximum.at(best, row[seen], kp[seen])
            pick = seen & (kp == best[row])
            res[row[pick]] = kr[pick]
            res = np.where((hp >= self.p_min) & (hp >= best), r0, res)
            best = np.maximum(best, np.where(hp >= self.p_min, hp, -1.0))
        if dust is not None:                                         # the dust's near return may still win
            reach = np.nan_to_num(np.fmin(res, r0), nan=dust.grid[-1])
            k = dust.cell(reach)
            s = dust.peak[k]
            wins = (s >= self.p_min) & ((s > best) if not self.last else ~np.isfinite(res))
            res = np.where(wins, dust.peak_at[k], res)
        return res.astype(np.float32)


def lidar_atmosphere(scenario: Scenario, directions: np.ndarray) -> LidarAtmosphere | None:
    """The run's :class:`LidarAtmosphere`, None when the air is clear and the stream solid (nothing to apply)."""
    if scenario.atmosphere.clear:
        return None
    return LidarAtmosphere(scenario, directions, dust_model(scenario, scenario.lidar.range_max_m))
