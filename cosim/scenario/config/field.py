"""Scenario records of the field conditions the machines meet (docs/field.md): random processes and profiles.

Used by the machine sections (cosim.scenario.config.machines): Machine Sync's GNSS error, the tractor's wheel slip,
the yield-driven variation of the flow, the combine's speed and turn profile. Owned by dynamics_proc. Every
default is "none": a scenario that sets nothing here runs as on an ideal field, to the bit.
"""
from __future__ import annotations

from pydantic import Field

from .base import Model, NonNegFloat, PosFloat

__all__ = ["GaussMarkov", "Slip", "ProfilePoint", "increasing_times"]


class GaussMarkov(Model):
    """A stationary first-order Gauss-Markov process (dynamics_proc.vehicles.fieldnoise): zero mean, standard deviation
    ``sigma``, autocorrelation ``sigma^2 exp(-|dt| / correlation_time_s)``; seeded from the scenario's seed, one
    stream per process. ``sigma`` 0: off."""

    sigma: NonNegFloat = 0.0
    """Standard deviation of the process (0: off), in the unit of what it varies."""
    correlation_time_s: PosFloat = 10.0
    """Time over which its autocorrelation falls to 1/e, s."""


class Slip(Model):
    """Longitudinal wheel slip of the tractor: its ground speed is its wheel speed times (1 - slip), slip =
    ``mean`` plus a Gauss-Markov variation (``sigma``, ``correlation_time_s``), clipped to [0, 0.5]."""

    mean: float = Field(default=0.0, ge=0.0, le=0.5, allow_inf_nan=False)
    """Mean slip, a fraction of the wheel speed."""
    sigma: NonNegFloat = Field(default=0.0, le=0.2)
    """Standard deviation of the slip's Gauss-Markov variation about its mean."""
    correlation_time_s: PosFloat = 5.0
    """Correlation time of that variation, s."""


class ProfilePoint(Model):
    """A point of the combine's speed and turn profile: at ``t_s`` it drives at ``speed_mps`` on a path of
    curvature ``curvature_1pm`` (1/m, > 0 turning left; 0 straight; yaw rate = speed x curvature). Between points
    both change linearly in time; before the first and after the last they hold."""

    t_s: NonNegFloat
    """Time of the point, s."""
    speed_mps: NonNegFloat
    """Combine speed at that time, m/s."""
    curvature_1pm: float = Field(default=0.0, ge=-0.2, le=0.2, allow_inf_nan=False)
    """Path curvature at that time, 1/m (> 0 turning left, 0 straight)."""


def increasing_times(points: tuple[ProfilePoint, ...]) -> tuple[ProfilePoint, ...]:
    """Check that a profile's times increase strictly (ValueError naming the first that does not)."""
    for a, b in zip(points, points[1:]):
        if b.t_s <= a.t_s:
            raise ValueError(f"profile times must increase: {b.t_s:g} s follows {a.t_s:g} s")
    return points

