"""Dust between the LiDAR and its targets: extinction, backscatter, the return the sensor reports.

The model of Hahner et al. 2021 ("Fog Simulation on Real LiDAR Point Clouds") with dust's constants. For a
homogeneous medium of extinction alpha (1/m) and backscatter beta = alpha / S (1/(m sr), S the lidar ratio), a
pulse P0 sin^2(pi t / (2 tau)) (0 <= t <= 2 tau, half-power width tau) and a receiver whose field of view meets the
beam as xi(r) (0 before r1, linear to 1 at r2), the received power, in units of C_A P0 2 / c (common to every
return, so it drops out of every comparison), is

* from a hard (Lambertian, reflectivity rho) target at range R0, at its peak:
  ``h(R0) = (rho / pi) xi(R0) exp(-2 alpha R0) / R0^2`` (the overlap is applied to the medium's return, where
  it shapes the near clutter; a hard target inside it is the sensor's ``range_min_m``'s business, so that clear
  air passes every range unchanged);
* from the medium itself, at range R:
  ``s(R) = beta * integral_{max(R - c tau, 0)}^{R} sin^2(pi (R - r) / (c tau)) xi(r) exp(-2 alpha r) / r^2 dr``
  (the pulse convolved with the backscatter along the beam), which far from the sensor (R >> c tau) tends to
  ``beta (c tau / 2) exp(-2 alpha R) / R^2``.

The sensor reports one return per beam (``atmosphere.return_mode``): the strongest of the hard return and the
medium's peak in front of it, or the last of them above its detection limit (a target of
``detection_reflectivity`` at ``sensor.range_max_m`` in clear air); a medium's peak stronger than the hard return
is a false early return at the medium's range, a hard return below the limit is lost. Clear air (alpha = 0) has
no medium return and no attenuation: every range passes unchanged. :class:`DustModel` tabulates s(R) once per
scenario (the medium is the same along every beam) and answers per beam by lookup.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from cosim.scenario.config import Atmosphere, Scenario

__all__ = ["C_MPS", "overlap", "hard_power", "soft_power", "DustModel", "dust_model", "dust_blows"]

#: speed of light, m/s
C_MPS = 299_792_458.0
#: s(R) is tabulated every this, m
TABLE_STEP_M = 0.01
#: samples of each s(R) integral over the pulse length
PULSE_SAMPLES = 400
_NS = 1e-9


def overlap(r, r1: float, r2: float) -> np.ndarray:
    """The receiver's overlap xi(r): 0 before ``r1``, 1 after ``r2``, linear between (m)."""
    r = np.asarray(r, np.float64)
    if r2 <= r1:
        return (r >= r1).astype(np.float64)
    return np.clip((r - r1) / (r2 - r1), 0.0, 1.0)


def hard_power(r0, alpha: float, reflectivity: float, r1: float, r2: float) -> np.ndarray:
    """Peak return of Lambertian targets at ranges ``r0`` (m; NaN or inf: none, 0), in units of C_A P0 2 / c."""
    r0 = np.asarray(r0, np.float64)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        h = (reflectivity / math.pi) * overlap(r0, r1, r2) * np.exp(-2.0 * alpha * r0) / (r0 * r0)
    return np.where(np.isfinite(r0) & (r0 > 0.0), h, 0.0)


def soft_power(r, alpha: float, beta: float, tau_s: float, r1: float, r2: float,
               samples: int = PULSE_SAMPLES) -> np.ndarray:
    """The medium's return s(R) at ranges ``r`` (m), in units of C_A P0 2 / c: the pulse convolved with the
    backscatter (the module docstring), by the midpoint rule over ``samples`` points of the pulse's length."""
    r = np.atleast_1d(np.asarray(r, np.float64))
    length = C_MPS * tau_s
    u = (np.arange(samples) + 0.5) / samples                       # fraction of the pulse length
    rr = r[:, None] - u[None, :] * length                           # the range each part of the pulse is at
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        f = np.sin(math.pi * u) ** 2 * overlap(rr, r1, r2) * np.exp(-2.0 * alpha * rr) / (rr * rr)
    f = np.where(rr > 0.0, f, 0.0)
    return beta * length * f.mean(axis=1)


@dataclass(frozen=True)
class DustModel:
    """The dust of a scenario for one LiDAR: extinction ``alpha`` 1/m, backscatter ``beta`` 1/(m sr), the
    reflectivity of its targets, its detection limit ``p_min`` (same units as the powers), the return mode; the
    medium's return tabulated: ``grid`` (K,) m, running maximum of s over [0, grid] ``peak`` (K,) and where it
    lies ``peak_at`` (K,) m."""

    alpha: float
    beta: float
    reflectivity: float
    r1: float
    r2: float
    p_min: float
    last: bool
    grid: np.ndarray
    peak: np.ndarray
    peak_at: np.ndarray

    def cell(self, reach: np.ndarray) -> np.ndarray:
        """Index (N,) int64 of the last ``grid`` point at or before each of ``reach`` (N,) m, clipped to the grid
        (as ``np.searchsorted(grid, reach, side="right") - 1``, the grid's even step used for a first guess that
        one comparison either side corrects; NaN: the last point)."""
        n = len(self.grid)
        if n < 2:
            return np.zeros(np.shape(reach), np.int64)
        with np.errstate(invalid="ignore"):
            guess = np.floor(np.asarray(reach, np.float64) / TABLE_STEP_M)
        k = np.clip(np.nan_to_num(guess, nan=n - 1.0), 0, n - 2).astype(np.int64)
        k -= (np.take(self.grid, k) > reach) & (k > 0)                 # one step back where the guess overshot
        k += np.take(self.grid, k + 1) <= reach                         # or one forward where it fell short
        return np.where(np.isnan(reach), n - 1, k)

    @cached_property
    def peak_at32(self) -> np.ndarray:
        """``peak_at`` (K,) as float32 m (what :meth:`returns` reports), made once."""
        return self.peak_at.astype(np.float32)

    def returns(self, ranges: np.ndarray) -> np.ndarray:
        """:meth:`returns_reference` (same argument, the same bits) in fewer passes, for float32 ``ranges`` and a
        positive detection limit (otherwise the reference answers): the overlap of a hard target (1 at every
        positive range) left out of its power, the table's cells found without the non-finite cases (the beams
        that met nothing look up the table's end), the return chosen in one test and taken straight from the
        ranges and a float32 copy of the table (the reference's round trip through float64 is exact)."""
        r = np.asarray(ranges)
        if r.dtype != np.float32 or not self.p_min > 0.0 or len(self.grid) < 2:
            return self.returns_reference(ranges)
        r0 = r.astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            h = (self.reflectivity / math.pi) * np.exp(-2.0 * self.alpha * r0) / (r0 * r0)
        hard_ok = (h >= self.p_min) & (r0 > 0.0)                      # NaN, inf and r <= 0: no hard return
        k = self._cell_finite(np.where(np.isfinite(r0), r0, self.grid[-1]))
        s = self.peak.take(k)
        soft_ok = s >= self.p_min
        use_hard = hard_ok if self.last else hard_ok & ((h >= s) | ~soft_ok)
        return np.where(use_hard, r, np.where(soft_ok, self.peak_at32.take(k), np.float32(np.nan)))

    def _cell_finite(self, reach: np.ndarray) -> np.ndarray:
        """:meth:`cell` for finite ``reach`` (N,) m and a grid of two points or more (its NaN cases left out)."""
        n = len(self.grid)
        k = np.clip(np.floor(reach / TABLE_STEP_M), 0, n - 2).astype(np.int64)
        k -= (self.grid.take(k) > reach) & (k > 0)
        k += self.grid.take(k + 1) <= reach
        return k

    def returns_reference(self, ranges: np.ndarray) -> np.ndarray:
        """The ranges (N,) float32 m the sensor reports for hard returns ``ranges`` (N,) float32 m (NaN: the beam
        met nothing): attenuated, replaced by the medium's peak where that is stronger (strongest) or the hard
        return is lost (last), NaN where nothing is detected. New array."""
        r0 = np.asarray(ranges, np.float64)
        h = hard_power(r0, self.alpha, self.reflectivity, 0.0, 0.0)
        k = self.cell(np.where(np.isfinite(r0), r0, self.grid[-1]))
        s, at = self.peak[k], self.peak_at[k]
        hard_ok, soft_ok = h >= self.p_min, s >= self.p_min
        if self.last:
            out = np.where(hard_ok, r0, np.where(soft_ok, at, np.nan))
        else:
            out = np.where(hard_ok & (h >= s), r0, np.where(soft_ok, at, np.where(hard_ok, r0, np.nan)))
        return out.astype(np.float32)


@lru_cache(maxsize=8)
def _table(alpha: float, beta: float, tau_s: float, r1: float, r2: float, r_max: float):
    grid = np.arange(0.0, r_max + TABLE_STEP_M, TABLE_STEP_M)
    s = soft_power(grid, alpha, beta, tau_s, r1, r2)
    peak = np.maximum.accumulate(s)
    idx = np.maximum.accumulate(np.where(s >= peak, np.arange(len(s)), 0))
    for a in (grid, peak):
        a.setflags(write=False)
    at = grid[idx]
    at.setflags(write=False)
    return grid, peak, at


def dust_model(s: Scenario, range_max_m: float | None = None) -> DustModel | None:
    """The scenario's :class:`DustModel` for a sensor reaching ``range_max_m`` m (None: ``sensor.range_max_m``),
    None in dust-free air (nothing to apply)."""
    a, sensor = s.atmosphere, s.sensor
    alpha = a.extinction_per_m
    if alpha == 0.0:
        return None
    r_max = sensor.range_max_m if range_max_m is None else float(range_max_m)
    beta = alpha / a.lidar_ratio_sr
    r1, r2 = a.overlap_m
    p_min = float(hard_power(r_max, 0.0, a.detection_reflectivity, 0.0, 0.0))
    grid, peak, at = _table(alpha, beta, a.pulse_half_power_ns * _NS, r1, r2, r_max)
    return DustModel(alpha, beta, a.target_reflectivity, r1, r2, p_min, a.return_mode == "last", grid, peak, at)


def dust_blows(atmosphere: Atmosphere, t_s: float) -> bool:
    """Whether the dust of ``atmosphere`` is in the air at run time ``t_s`` s: always, or inside its
    ``dust_window_s`` [start, end) (a gust). Every sensor asks this, so the LiDAR and the cameras share the gust."""
    window = atmosphere.dust_window_s
    return window is None or window[0] <= float(t_s) < window[1]
