"""Scenario sections for the grain fill model, the offloading controller and the integrator.

Owned by dynamics_proc (issue 3). ``Controller.grid_cell_m`` and ``Controller.sections`` are shared with
perception_proc: the perceived height map is produced on that grid.
"""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import Fraction, Model, NonNegFloat, PosFloat

__all__ = ["Grain", "Controller", "Integrator"]


class Grain(Model):
    """Grain fill model: height map over the cart floor."""

    cell_m: PosFloat = 0.1
    initial_fill_m: NonNegFloat = 1.0
    deposit_radius_m: PosFloat = 0.25


class Controller(Model):
    """Offloading controller: operator inputs and the section grid."""

    target_fill_m: PosFloat = 1.9
    strategy: Literal["front_to_back", "back_to_front", "lowest_first"] = "front_to_back"
    sections: int = Field(default=9, ge=1, le=64)
    grid_cell_m: PosFloat = 0.1
    full_fraction: Fraction = 0.98
    estimator: Literal["paper", "fused"] = "paper"


class Integrator(Model):
    """Integration of the continuous vehicle states inside one sensor frame."""

    method: Literal["rk4", "exponential", "radau", "bdf"] = "exponential"
    rtol: PosFloat = 1e-8
    atol: PosFloat = 1e-10
