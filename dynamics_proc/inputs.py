"""Run-time inputs of the dynamics: scenario values a user may change between frames (``cosim.Simulation.set``).

A change is applied at the start of the next integrated frame (set after frame m, it acts over t_m -> t_{m+1})
and shows in that frame's ``dyn_state`` row (``setpoint_long_m``, ``setpoint_lat_m``, ``combine_speed_mps``,
``target_fill_m``), so the timeseries records it. Pure functions of (world, params) -> (world, params).

=====================================  ==========================================================================
 path                                   effect
=====================================  ==========================================================================
 ``machine_sync.longitudinal_offset_m``  Machine Sync setpoint along the combine, m (the controller's nudges
                                         go on from the new value)
 ``machine_sync.lateral_offset_m``       Machine Sync setpoint across the combine, m (cart to the left > 0)
 ``combine.speed_mps``                   combine speed, m/s (on an arc the yaw rate follows: speed / radius)
 ``controller.target_fill_m``            target grain height, m (and the "full" level, ``full_fraction`` of it)
=====================================  ==========================================================================
"""
from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Callable

from cosim.scenario.config import Scenario

if TYPE_CHECKING:
    from dynamics_proc.state import ModelParams, World

__all__ = ["INPUTS", "apply_input"]

def _longitudinal(w: "World", p: "ModelParams", s: Scenario, v: float):
    return replace(w, setpoint=(v, w.setpoint[1])), p


def _lateral(w: "World", p: "ModelParams", s: Scenario, v: float):
    return replace(w, setpoint=(w.setpoint[0], v)), p


def _combine_speed(w: "World", p: "ModelParams", s: Scenario, v: float):
    yaw_rate = v / s.combine.path_radius_m if s.combine.path == "arc" else 0.0
    return w, replace(p, vehicles=replace(p.vehicles, combine_speed_mps=v, combine_yaw_rate_radps=yaw_rate))


def _target_fill(w: "World", p: "ModelParams", s: Scenario, v: float):
    control = replace(p.control, target_m=v, full_level_m=s.controller.full_fraction * v)
    return w, replace(p, control=control)


#: settable scenario path -> ``fn(world, params, scenario, value) -> (world, params)``
INPUTS: dict[str, Callable] = {
    "machine_sync.longitudinal_offset_m": _longitudinal,
    "machine_sync.lateral_offset_m": _lateral,
    "combine.speed_mps": _combine_speed,
    "controller.target_fill_m": _target_fill,
}


def apply_input(w: "World", p: "ModelParams", s: Scenario, path: str, value: float) -> tuple["World", "ModelParams"]:
    """(world, params) with input ``path`` set to ``value`` (KeyError for a path that is not an input)."""
    try:
        fn = INPUTS[path]
    except KeyError:
        raise KeyError(f"{path!r} is not a run-time input; inputs: {', '.join(INPUTS)}") from None
    return fn(w, p, s, float(value))
