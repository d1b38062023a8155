"""The system model's value types: :class:`ModelParams` (everything the frame step needs, derived once from the
scenario) and :class:`World` (the whole ground truth after a frame), apart from the code that steps them
(dynamics_proc.model) and records them (dynamics_proc.record).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import dynamics_proc.grain.auger as ag
from cosim.errors import PluginFault
from cosim.scenario.config import FMU_REF, Scenario
from cosim.scenario.plugins import load_plugin
from cosim.world.geometry import cart_grid_from_body
from dynamics_proc.control.controller import ControllerParams, plugin_dir
from dynamics_proc.control.protocol import CONTROLLER_POINT, ControllerCommand, OffloadingController
from dynamics_proc.fmu.models import Fmus
from dynamics_proc.grain.fill import GrainGrid
from dynamics_proc.vehicles.fieldsync import FieldParams, FieldState
from dynamics_proc.vehicles.ground import Stance, stance_of
from dynamics_proc.vehicles.machine_sync import SyncGains
from dynamics_proc.vehicles.motion import VehicleParams

__all__ = ["ModelParams", "World", "SpoutGeometry"]

#: (spout world (3,) m, exit velocity world (3,) m/s, spout grid (3,) m, grid_from_world (4, 4)), see spout_grid
SpoutGeometry = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


@dataclass(frozen=True)
class ModelParams:
    """Everything the frame step needs, derived once from the scenario."""

    vehicles: VehicleParams
    gains: SyncGains
    auger: ag.AugerParams
    grid: GrainGrid
    control: ControllerParams
    cap: np.ndarray
    grid_from_cart_body: np.ndarray
    method: str
    rtol: float
    atol: float
    dt_s: float
    steps: int
    frame_dt_s: float
    lateral_offset_m: float
    signal_offset_m: float           # nudge signal = setpoint long + this (spout grid x at the setpoint)
    density_kgpm3: float
    flow_meter_bias: float           # relative error of the flow signal the fused estimator is given
    controller: OffloadingController  # controller.model, made by its factory
    controller_ref: str              # controller.model as the scenario names it
    fmus: Fmus | None = None         # FMUs in place of built-in models (dynamics_proc.fmu.models)
    feedforward_lead_s: float = 0.0  # controller.coping.feedforward_lead_s: the turn anticipated this far ahead, s
    stance: Stance | None = None     # the machines on the terrain (dynamics_proc.vehicles.ground), None on flat ground
    field: FieldParams | None = None  # Machine Sync and flow in a field (dynamics_proc.vehicles.fieldsync), None: ideal

    @classmethod
    def from_scenario(cls, s: Scenario, fmus: Fmus | None = None) -> "ModelParams":
        """The parameters of ``s``; ``fmus``: the run's open FMUs (:func:`dynamics_proc.fmu.models.open_fmus`) where the
        scenario names any (without them, a scenario that does builds parameters that fail when first used)."""
        a = ag.AugerParams.from_scenario(s)
        spout_x = a.pivot[0] + a.arm[0]
        fmus = fmus or Fmus()
        control = ControllerParams.from_scenario(s, fmus.strategy_for(s))
        if s.controller.model == FMU_REF:
            controller = fmus.controller_for(s)
        else:
            factory = load_plugin("controllers", s.controller.model, base_dir=plugin_dir(s),
                                  options=s.controller.model_options)
            controller = _make_controller(factory, control, s)
        return cls(VehicleParams.from_scenario(s), SyncGains.from_scenario(s), a, GrainGrid.from_scenario(s),
                   control, GrainGrid.from_scenario(s).cap(), cart_grid_from_body(s.cart),
                   s.integrator.method, s.integrator.rtol, s.integrator.atol, s.timing.dynamics_dt_s,
                   s.timing.steps_per_frame, s.timing.sensor_period_s, s.machine_sync.lateral_offset_m,
                   s.cart.interior_length_m / 2.0 - spout_x, s.crop.density, s.controller.fusion.flow_meter_bias,
                   controller, s.controller.model, fmus if fmus.vehicle or fmus.strategy else None,
                   s.controller.coping.feedforward_lead_s,
                   stance_of(s, s.tractor.rear_axle_x_m - s.tractor.hitch_offset_m), FieldParams.from_scenario(s))


def _make_controller(factory, control: ControllerParams, s: Scenario) -> OffloadingController:
    """``factory(control, s)``, checked to have the protocol's methods (PluginFault naming the plug-in)."""
    ref = s.controller.model
    try:
        c = factory(control, s)
    except PluginFault:
        raise
    except Exception as e:  # noqa: BLE001 - a plug-in's failure is reported with its name
        raise PluginFault(ref, CONTROLLER_POINT, f"making the controller raised {type(e).__name__}: {e}") from e
    missing = [m for m in ("initial_state", "step") if not callable(getattr(c, m, None))]
    if missing:
        raise PluginFault(ref, CONTROLLER_POINT, f"the controller made by the factory has no method "
                          f"{' or '.join(missing)} (dynamics_proc.control.protocol)")
    return c


@dataclass(frozen=True)
class World:
    """Ground truth after frame ``frame`` (time ``t_s``)."""

    frame: int
    t_s: float
    x: np.ndarray                    # (9,) vehicle state, see dynamics_proc.vehicles.motion
    flow_level: float                # 0..1
    heights: np.ndarray              # (nx, ny) float64 m, grain grid
    initial_m3: float
    delivered_m3: float
    spilled_m3: float
    spilled_outside_m3: float         # part of the spill that never reached the interior
    setpoint: tuple[float, float]    # Machine Sync cart offset (long, lat), m
    ctrl: object                     # the controller's state (ControllerState for the built-in)
    out: ControllerCommand           # its last command (fullness always (N,))
    impact: ag.Impact
    stream: np.ndarray               # (64, 4) float32 world rows [x, y, z, radius]
    stream_points: int
    spout: SpoutGeometry             # spout_grid(x), derived from x once per frame (the next frame starts from it)
    nudges: int = 0                  # nudges made so far
    field: FieldState | None = None  # the field conditions' memory (dynamics_proc.vehicles.fieldsync), None: ideal
