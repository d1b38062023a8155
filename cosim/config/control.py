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
    """Grain fill model: height map over the cart floor.

    ``cell_m`` must divide the cart interior length and width. ``deposit_radius_m`` is the radius of the flat
    top of the heap the stream builds around its impact point.
    """

    cell_m: PosFloat = 0.1
    initial_fill_m: NonNegFloat = 1.0
    deposit_radius_m: PosFloat = 0.25


class Controller(Model):
    """Offloading controller: operator inputs and the section grid.

    A section is full when its estimated peak height reaches ``full_fraction * target_fill_m`` (latched). The
    auger only runs while the predicted impact lies at least ``safe_margin_m`` inside every inner wall (it stops
    when it comes closer than ``safe_margin_m - safety_hysteresis_m``). A target section that gives no valid
    measurement for ``stale_timeout_s`` while it is being filled is treated as full (so nothing overfills
    blind). Cells whose centre lies within ``edge_margin_m`` of an inner wall are left out of the estimate (the
    heap's peak is never there; wall and rim returns are); a section's estimate is updated only from a map with
    at least ``min_section_cells`` valid cells in it. ``estimator``: ``paper`` takes the per-section robust
    peak (highest 2 x 2 block minimum) of the map; ``fused`` first fills holes with each cell's last valid value.
    Strategies: dynamics_proc.strategies.
    """

    target_fill_m: PosFloat = 1.9
    strategy: Literal["front_to_back", "back_to_front", "lowest_first"] = "front_to_back"
    sections: int = Field(default=9, ge=1, le=64)
    grid_cell_m: PosFloat = 0.1
    full_fraction: Fraction = 0.995
    estimator: Literal["paper", "fused"] = "paper"
    safe_margin_m: NonNegFloat = 0.3
    safety_hysteresis_m: NonNegFloat = 0.1
    stale_timeout_s: PosFloat = 10.0
    edge_margin_m: NonNegFloat = 0.2
    min_section_cells: int = Field(default=4, ge=1)


class Integrator(Model):
    """Integration of the continuous vehicle states inside one sensor frame.

    ``rk4``: classic fixed-step RK4; ``exponential``: the lags solved exactly (rate limits included) and the
    kinematics by RK4 on them; ``radau`` / ``bdf``: scipy ``solve_ivp`` with ``rtol`` / ``atol`` (reference).
    """

    method: Literal["rk4", "exponential", "radau", "bdf"] = "exponential"
    rtol: PosFloat = 1e-8
    atol: PosFloat = 1e-10
