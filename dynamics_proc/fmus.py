"""FMUs standing in for the built-in models of the system model (docs/fmu.md): the tractor-and-cart
dynamics and the fill strategy.

:func:`open_fmus` instantiates the FMUs a scenario names (``vehicles.tractor_cart.fmu``, ``controller.fmu``
with ``strategy: fmu``) and :meth:`Fmus.params` puts them into the frame step's parameters; ``close`` frees
them. The participant opens them in ``start`` and closes them in ``close``; the pure closed loop does the same
around its frames.

Stepping (lockstep with the dynamics):

* vehicle, ``step: dynamics_step`` (default): per dynamics step of ``timing.dynamics_dt_s``, Machine Sync's
  command (speed m/s, steering rad) is computed from the current state (exactly as for the built-in model) and
  set, then one ``doStep`` from that step's start time; the outputs are the new tractor state. ``step: frame``:
  one command per frame, held over one ``doStep`` of ``timing.sensor_period_s``. The combine is advanced by
  :func:`~dynamics_proc.vehicles.combine_advance` (its exact path); the cart's position is derived from the
  tractor's rear axle and the cart heading through the scenario's hitch and tongue geometry, as for the
  built-in model.
* strategy: whenever the controller asks for a section (every frame from the first measurement on), the
  inputs are set and one ``doStep`` runs from the end of the previous one to the end of the current frame.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from cosim.fmi.describe import describe
from cosim.fmi.roles import STRATEGY, VEHICLE, expand, step_mode
from cosim.fmi.slave import FmuSlave, FmuStepError
from cosim.scenario.config import Fmu, Scenario

from .machine_sync import SyncGains, sync_command
from .vehicles import CX, CY, CYAW, DELTA, PYAW, TX, TY, TYAW, V, VehicleParams, combine_advance, initial_state

__all__ = ["FmuVehicle", "FmuStrategy", "Fmus", "open_fmus", "VEHICLE_LABEL", "STRATEGY_LABEL"]

VEHICLE_LABEL = "vehicles.tractor_cart.fmu"
STRATEGY_LABEL = "controller.fmu"
#: state index of each vehicle output, in the order of cosim.fmi.roles.VEHICLE.outputs
_STATE_INDEX = {"tractor_axle_x_m": TX, "tractor_axle_y_m": TY, "tractor_yaw_rad": TYAW, "tractor_speed_mps": V,
                "tractor_steer_rad": DELTA, "cart_yaw_rad": PYAW}


def _open(fmu: Fmu, role, sections: int, label: str, initial: dict[str, float]) -> FmuSlave:
    """The slave for ``fmu`` with inputs and outputs in the role's signal order (per-section ones expanded)."""
    desc = describe(fmu.path)
    names = {}
    for kind in ("inputs", "outputs"):
        names[kind] = [n for s in role.signals(kind) if s.name in getattr(fmu, kind)
                       for n in expand(s, getattr(fmu, kind)[s.name], sections)]
    start = dict(fmu.parameters)
    start.update({fmu.initial[ours]: value for ours, value in initial.items() if ours in fmu.initial})
    return FmuSlave(desc, names["inputs"], names["outputs"], start, label, 0.0, fmu.instance_name)


class FmuVehicle:
    """The tractor and cart from an FMU: :meth:`advance` maps the state (9,) over one frame, as
    ``model._advance_vehicles`` does for the built-in model (see the module docstring for the stepping)."""

    def __init__(self, slave: FmuSlave, per_frame: bool, p: VehicleParams, gains: SyncGains, dt_s: float,
                 steps: int):
        self.slave, self.p, self.gains = slave, p, gains
        self.n, self.h = (1, dt_s * steps) if per_frame else (steps, dt_s)
        self.frame_dt_s = dt_s * steps

    def advance(self, x: np.ndarray, setpoint: tuple[float, float], frame: int) -> np.ndarray:
        """State (9,) at the end of frame ``frame`` (>= 1) from the state ``x`` at its start."""
        xs = x.tolist()
        t0 = (frame - 1) * self.frame_dt_s
        for i in range(self.n):
            u = sync_command(xs, setpoint, self.p, self.gains)
            out = self.slave.step(u, t0 + i * self.h, self.h, frame)
            cx, cy, cyaw = combine_advance(xs[CX], xs[CY], xs[CYAW], self.p, self.h)
            xs = [cx, cy, cyaw, out[0], out[1], out[2], out[3], out[4], out[5]]
        return np.array(xs)


class FmuStrategy:
    """A fill strategy from an FMU, with the strategy signature ``(full (N,) bool, height (N,) m, current
    0-based or -1) -> 0-based section or -1``; the FMU sees sections numbered 1..N (0: none)."""

    def __init__(self, slave: FmuSlave, fmu: Fmu, sections: int, frame_dt_s: float):
        self.slave, self.sections, self.frame_dt_s = slave, sections, frame_dt_s
        self._height = "height_m" in fmu.inputs
        self._current = "current_section" in fmu.inputs
        self.frame, self._t_end = 0, 0.0

    def begin_frame(self, frame: int) -> None:
        """The frame whose decision the next call makes (>= 1): its end is the end of the next doStep."""
        self.frame = frame

    def __call__(self, full: np.ndarray, height: np.ndarray, current: int) -> int:
        u = [1.0 if f else 0.0 for f in full.tolist()]
        if self._height:
            u += height.tolist()
        if self._current:
            u.append(float(current + 1))
        t_end = self.frame * self.frame_dt_s
        out = self.slave.step(u, self._t_end, t_end - self._t_end, self.frame)
        self._t_end = t_end
        k = out[0]
        if k != math.floor(k) or not 0 <= k <= self.sections:
            raise FmuStepError(f"FMU {self.slave.desc.path} ({self.slave.label}) failed at frame {self.frame}: output "
                               f"'section' is {k:g}, not a section 1..{self.sections} or 0 (all full)",
                               process="dynamics", frame=self.frame)
        return int(k) - 1


@dataclass
class Fmus:
    """The FMUs of one run (None where the built-in model runs)."""

    vehicle: FmuVehicle | None = None
    strategy: FmuStrategy | None = None

    def params(self, p):
        """``p`` (model.ModelParams) with these FMUs in place of the built-in models."""
        control = dataclasses.replace(p.control, strategy_fn=self.strategy) if self.strategy else p.control
        return dataclasses.replace(p, control=control, fmus=self)

    def begin_frame(self, frame: int) -> None:
        """Tell the stateful FMUs which frame (>= 1) is being computed (their step times and messages)."""
        if self.strategy is not None:
            self.strategy.begin_frame(frame)

    def close(self) -> None:
        """Free every FMU (safe to call twice)."""
        for m in (self.vehicle, self.strategy):
            if m is not None:
                m.slave.close()


def open_fmus(s: Scenario) -> Fmus | None:
    """Instantiate and initialise the FMUs scenario ``s`` names; None when it names none."""
    vf, sf = s.vehicles.tractor_cart.fmu, s.controller.fmu
    if vf is None and sf is None:
        return None
    fmus = Fmus()
    try:
        if vf is not None:
            vp = VehicleParams.from_scenario(s)
            x0 = initial_state(s, vp)
            initial = {name: float(x0[i]) for name, i in _STATE_INDEX.items()}
            slave = _open(vf, VEHICLE, s.controller.sections, VEHICLE_LABEL, initial)
            fmus.vehicle = FmuVehicle(slave, step_mode(vf, VEHICLE) == "frame", vp, SyncGains.from_scenario(s),
                                      s.timing.dynamics_dt_s, s.timing.steps_per_frame)
        if sf is not None and s.controller.strategy == "fmu":
            slave = _open(sf, STRATEGY, s.controller.sections, STRATEGY_LABEL, {})
            fmus.strategy = FmuStrategy(slave, sf, s.controller.sections, s.timing.sensor_period_s)
    except BaseException:
        fmus.close()
        raise
    return fmus
