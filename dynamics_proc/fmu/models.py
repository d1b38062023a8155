"""FMUs standing in for the built-in models of the system model (docs/fmu.md): the tractor-and-cart
dynamics, the offloading controller, the fill strategy.

:func:`open_fmus` instantiates the FMUs a scenario names (``vehicles.tractor_cart.fmu``; ``controller.fmu``
with ``controller.model: fmu`` or ``controller.strategy: fmu``) and ``ModelParams.from_scenario(s, fmus)`` puts
them in place of the built-in models; ``close`` frees them. The participant opens them in ``start`` and closes
them in ``close``; the pure closed loop does the same around its frames.

Stepping (lockstep with the dynamics):

* vehicle, ``step: dynamics_step`` (default): per dynamics step of ``timing.dynamics_dt_s``, Machine Sync's
  command (speed m/s, steering rad) is computed from the current state (exactly as for the built-in model) and
  set, then one ``doStep`` from that step's start time; the outputs are the new tractor state. ``step: frame``:
  one command per frame, held over one ``doStep`` of ``timing.sensor_period_s``. The combine is advanced by
  :func:`~dynamics_proc.vehicles.motion.combine_advance` (its exact path); the cart's position is derived from the
  tractor's rear axle and the cart heading through the scenario's hitch and tongue geometry, as for the
  built-in model.
* controller (``controller.model: fmu``, dynamics_proc.control.protocol): once per frame, at the decision time
  t of frame m (the start of the interval the decision acts over): inputs set, one ``doStep(t, sensor_period_s)``,
  outputs read. Its per-section heights are the robust section peaks (``controller.section_heights``) of the
  measurement the latency rule gives that frame (NaN without one).
* strategy: whenever the controller asks for a section (every frame from the first measurement on), the
  inputs are set and one ``doStep`` runs from the end of the previous one to the end of the current frame.

An FMI 3.0 controller or strategy with an input clock (cosim.fmi.roles.frame_clock) is ticked at the decision
time, the start of the frame, and answers at the tick (cosim.fmi.slave); a clocked strategy is first stepped up
to that time with its inputs held.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cosim.fmi.describe import describe
from cosim.fmi.roles import CONTROLLER, STRATEGY, VEHICLE, expand, frame_clock, step_mode
from cosim.fmi.slave import PROCESS, FmuSlave, FmuStepError
from cosim.scenario.config import FMU_REF, Fmu, Scenario
from dynamics_proc.control.controller import ControllerParams, section_heights
from dynamics_proc.control.protocol import ControllerCommand, ControllerInput
from dynamics_proc.vehicles.machine_sync import SyncGains, sync_command
from dynamics_proc.vehicles.motion import (
    CX,
    CY,
    CYAW,
    DELTA,
    PYAW,
    TX,
    TY,
    TYAW,
    V,
    VehicleParams,
    combine_advance,
    initial_state,
)

__all__ = ["FmuVehicle", "FmuStrategy", "FmuController", "Fmus", "open_fmus", "VEHICLE_LABEL", "CONTROLLER_LABEL"]

VEHICLE_LABEL = "vehicles.tractor_cart.fmu"
CONTROLLER_LABEL = "controller.fmu"
#: state index of each vehicle output, in the order of cosim.fmi.roles.VEHICLE.outputs
_STATE_INDEX = {"tractor_axle_x_m": TX, "tractor_axle_y_m": TY, "tractor_yaw_rad": TYAW, "tractor_speed_mps": V,
                "tractor_steer_rad": DELTA, "cart_yaw_rad": PYAW}


def _open(fmu: Fmu, role, sections: int, label: str, initial: dict[str, float]) -> FmuSlave:
    """The slave for ``fmu`` with inputs and outputs in the role's signal order (per-section ones expanded;
    optional ones only where mapped)."""
    desc = describe(fmu.path)
    names = {}
    for kind in ("inputs", "outputs"):
        names[kind] = [n for s in role.signals(kind) if s.name in getattr(fmu, kind)
                       for n in expand(s, getattr(fmu, kind)[s.name], sections, fmu.index_base)]
    nan_ok = [n for s in role.outputs if s.nan_ok and s.name in fmu.outputs
              for n in expand(s, fmu.outputs[s.name], sections, fmu.index_base)]
    start = dict(fmu.parameters)
    start.update({fmu.initial[ours]: value for ours, value in initial.items() if ours in fmu.initial})
    clock = frame_clock(desc) if role.clocks else None
    return FmuSlave(desc, names["inputs"], names["outputs"], start, label, 0.0, fmu.instance_name, nan_ok,
                    None if clock is None else clock.name)


class FmuVehicle:
    """The tractor and cart from an FMU: :meth:`advance` maps the state (9,) over one frame, as
    ``model._advance_vehicles`` does for the built-in model (see the module docstring for the stepping)."""

    def __init__(self, slave: FmuSlave, per_frame: bool, dt_s: float, steps: int):
        self.slave = slave
        self.n, self.h = (1, dt_s * steps) if per_frame else (steps, dt_s)
        self.frame_dt_s = dt_s * steps

    def advance(self, x: np.ndarray, setpoint: tuple[float, float], frame: int, p: VehicleParams,
                gains: SyncGains) -> np.ndarray:
        """State (9,) at the end of frame ``frame`` (>= 1) from the state ``x`` at its start; ``p`` and ``gains``
        the frame's (run-time inputs such as the combine speed may change them between frames)."""
        xs = x.tolist()
        t0 = (frame - 1) * self.frame_dt_s
        for i in range(self.n):
            u = sync_command(xs, setpoint, p, gains)
            out = self.slave.step(u, t0 + i * self.h, self.h, frame)
            cx, cy, cyaw = combine_advance(xs[CX], xs[CY], xs[CYAW], p, self.h)
            xs = [cx, cy, cyaw, out[0], out[1], out[2], out[3], out[4], out[5]]
        return np.array(xs)


def _fault(slave: FmuSlave, frame: int, cause: str) -> FmuStepError:
    return FmuStepError(f"FMU {slave.desc.path} ({slave.label}) failed at frame {frame}: {cause}", process=PROCESS,
                        frame=frame)


def _section(slave: FmuSlave, value: float, sections: int, name: str, frame: int, base: int) -> int:
    """An FMU's section output (base .. base + N - 1, base - 1 none) as a 0-based index (-1 none); FmuStepError when
    out of range."""
    if value != math.floor(value) or not base - 1 <= value <= sections - 1 + base:
        raise _fault(slave, frame, f"output {name!r} is {value:g}, not a section {base}..{sections - 1 + base} or "
                                   f"{base - 1} (none)")
    return int(value) - base


class FmuStrategy:
    """A fill strategy from an FMU, with the strategy signature ``(full (N,) bool, height (N,) m, current
    0-based or -1) -> 0-based section or -1``; the FMU sees sections numbered from its ``index_base`` (1: 1..N,
    0 none; 0: 0..N-1, -1 none)."""

    def __init__(self, slave: FmuSlave, fmu: Fmu, sections: int, frame_dt_s: float):
        self.slave, self.sections, self.frame_dt_s = slave, sections, frame_dt_s
        self.base = fmu.index_base
        self._height = "height_m" in fmu.inputs
        self._current = "current_section" in fmu.inputs
        self.clocked = slave.clocked
        self.frame, self._t_end = 0, 0.0

    def begin_frame(self, frame: int) -> None:
        """The frame (>= 1) whose decision the next call makes: the next doStep ends at its end."""
        self.frame = frame

    def __call__(self, full: np.ndarray, height: np.ndarray, current: int) -> int:
        u = [1.0 if f else 0.0 for f in full.tolist()]
        if self._height:
            u += height.tolist()
        if self._current:
            u.append(float(current + self.base))
        t_end = self.frame * self.frame_dt_s
        if self.clocked:                    # the tick is the decision, at the frame's start
            t = t_end - self.frame_dt_s
            if t > self._t_end:
                self.slave.advance(self._t_end, t - self._t_end, self.frame)
            out = self.slave.step(u, t, self.frame_dt_s, self.frame)
        else:
            out = self.slave.step(u, self._t_end, t_end - self._t_end, self.frame)
        self._t_end = t_end
        return _section(self.slave, out[0], self.sections, "section", self.frame, self.base)


#: ControllerInput -> value of each optional scalar controller input, in CONTROLLER.inputs order
_CONTROLLER_INPUTS = {
    "spout_x_m": lambda i: i.spout_x_m, "drift_x_m": lambda i: i.drift_x_m,
    "nudge_signal_m": lambda i: i.nudge_signal_m,
    "impact_top_x_m": lambda i: i.impacts[0][0], "impact_top_y_m": lambda i: i.impacts[0][1],
    "impact_floor_x_m": lambda i: i.impacts[-1][0], "impact_floor_y_m": lambda i: i.impacts[-1][1],
    "delivered_m3": lambda i: i.delivery.delivered_m3,
}


class FmuController:
    """The offloading controller from an FMU (dynamics_proc.control.protocol; memory inside the FMU, so its
    state is None). Stepped once per frame at the decision time (see the module docstring)."""

    def __init__(self, slave: FmuSlave, fmu: Fmu, params: ControllerParams):
        self.slave, self.params, self.base = slave, params, fmu.index_base
        self._inputs = [(n, f) for n, f in _CONTROLLER_INPUTS.items() if n in fmu.inputs]
        self._outputs = [s.name for s in CONTROLLER.outputs if s.name in fmu.outputs]
        self._seen = False

    def initial_state(self) -> None:
        """No memory outside the FMU."""
        return None

    def step(self, state: None, inp: ControllerInput) -> tuple[None, ControllerCommand]:
        """Set the inputs, one doStep of a frame at ``inp.t_s``, the outputs as a command."""
        p, frame = self.params, inp.frame + 1
        n = p.sections
        h = section_heights(inp.heights, p) if inp.heights is not None else np.full(n, np.nan)
        self._seen = self._seen or bool(np.isfinite(h).any())
        out = self.slave.step(h.tolist() + [f(inp) for _, f in self._inputs], inp.t_s, p.frame_dt_s, frame)
        got = dict(zip(self._outputs, out))
        nudge = got["nudge"]
        if nudge not in (-1.0, 0.0, 1.0):
            raise _fault(self.slave, frame, f"output 'nudge' is {nudge:g}, not -1, 0 or +1")
        target = _section(self.slave, got.get("target_section", self.base - 1.0), n, "target_section", frame,
                          self.base)
        fullness = np.array(out[-n:]) if "fullness" in got else np.full(n, np.nan)
        return None, ControllerCommand(int(nudge), got["auger_on"] != 0.0, got.get("desired_x_m", inp.spout_x_m),
                                       got.get("effort_m", math.nan), target, fullness,
                                       got.get("all_full", 0.0) != 0.0, self._seen, got.get("bias_m", 0.0))


def _not_opened(*_args):
    raise RuntimeError("this scenario names an FMU, which is opened with the run: build the model parameters with "
                       "ModelParams.from_scenario(s, dynamics_proc.fmu.models.open_fmus(s))")


class _NotOpenedController:
    initial_state = step = staticmethod(_not_opened)


@dataclass
class Fmus:
    """The FMUs of one run (None where the built-in model runs)."""

    vehicle: FmuVehicle | None = None
    strategy: FmuStrategy | None = None
    controller: FmuController | None = None

    def strategy_for(self, s: Scenario):
        """The fill strategy to use in place of loading ``s.controller.strategy`` by name, or None."""
        if s.controller.strategy != FMU_REF:
            return None
        return self.strategy or _not_opened

    def controller_for(self, s: Scenario):
        """The controller for ``controller.model: fmu``."""
        return self.controller or _NotOpenedController()

    def begin_frame(self, frame: int) -> None:
        """Tell the stateful FMUs which frame (>= 1) is being computed (their step times and messages)."""
        if self.strategy is not None:
            self.strategy.begin_frame(frame)

    def close(self) -> None:
        """Free every FMU (safe to call twice)."""
        for m in (self.vehicle, self.strategy, self.controller):
            if m is not None:
                m.slave.close()


def open_fmus(s: Scenario) -> Fmus | None:
    """Instantiate and initialise the FMUs scenario ``s`` names; None when it names none."""
    vf, cf = s.vehicles.tractor_cart.fmu, s.controller.fmu
    if vf is None and cf is None:
        return None
    fmus = Fmus()
    n = s.controller.sections
    try:
        if vf is not None:
            vp = VehicleParams.from_scenario(s)
            x0 = initial_state(s, vp)
            initial = {name: float(x0[i]) for name, i in _STATE_INDEX.items()}
            slave = _open(vf, VEHICLE, n, VEHICLE_LABEL, initial)
            fmus.vehicle = FmuVehicle(slave, step_mode(vf, VEHICLE) == "frame", s.timing.dynamics_dt_s,
                                      s.timing.steps_per_frame)
        if cf is not None and s.controller.strategy == FMU_REF:
            slave = _open(cf, STRATEGY, n, CONTROLLER_LABEL, {})
            fmus.strategy = FmuStrategy(slave, cf, n, s.timing.sensor_period_s)
        if cf is not None and s.controller.model == FMU_REF:
            slave = _open(cf, CONTROLLER, n, CONTROLLER_LABEL, {})
            fmus.controller = FmuController(slave, cf, ControllerParams.from_scenario(s, _not_opened))
    except BaseException:
        fmus.close()
        raise
    return fmus
