"""The offloading controller plug-in point (``controller.model``): what a controller is given each frame and
what it must decide.

A controller is made once per run by its factory, ``factory(params, scenario) -> controller``
(a class whose ``__init__(self, params, scenario)`` qualifies), where ``params`` is the
:class:`dynamics_proc.control.controller.ControllerParams` of the scenario (section grid, target, margins, nudge size,
the resolved fill strategy ``params.strategy``) and ``scenario`` the whole validated
:class:`cosim.scenario.config.Scenario`. The controller object has two methods:

* ``initial_state() -> state``: its memory before the first frame (any object; ``None`` for a controller
  that keeps its memory in ``self``);
* ``step(state, inp: ControllerInput) -> (state, ControllerCommand)``: one decision, once per sensor frame.

The state is handed back on the next call, so a controller may be pure (the built-in ``section_fill`` is:
its state is the frozen :class:`~dynamics_proc.control.controller.ControllerState`) or keep its memory in ``self``.

Frames and units: every position is along the **cart grid** axes (m; x from the front inner wall, increasing
to the rear; y from the left inner wall), the height map is on the controller grid (``params.nx`` x
``params.ny`` cells of ``params.grid_cell_m``), times are s. The command moves the Machine Sync
longitudinal setpoint by ``nudge * params.nudge_m`` (one step at most per frame; the controller itself
keeps ``params.nudge_interval_s`` between nudges if it wants to) and switches the auger; the other
fields are reported in the run's outputs (``dyn_state``) and do not act on the plant.

Every command is checked (:func:`check_command`) before it acts: a wrong type, a nudge other than -1/0/+1, a
target outside -1..N-1 or a fullness of the wrong shape ends the run with a
:class:`cosim.errors.PluginFault` naming the plug-in, the frame and the cause.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from cosim.errors import PluginFault
from cosim.scenario.config.holds import HOLD_LOST, HOLD_NO_MEASUREMENT, HOLD_NONE, HOLD_REASONS

__all__ = ["ControllerInput", "ControllerCommand", "Delivery", "OffloadingController", "ControllerFactory",
           "check_command", "CONTROLLER_POINT", "HOLD_NONE", "HOLD_NO_MEASUREMENT", "HOLD_LOST", "HOLD_REASONS"]

#: the scenario key of this plug-in point (named in faults)
CONTROLLER_POINT = "controller.model"


@dataclass(frozen=True)
class Delivery:
    """What the machine knows of the grain it has delivered: the flow signal integrated since the start (m^3,
    with the scenario's ``controller.fusion.flow_meter_bias``), and the spout position and exit velocity in
    the cart grid frame (m, m/s), from which the impact is predicted; on tilted ground also gravity in that frame
    (the cart's tilt, as its inclination sensor knows it; None: level)."""

    delivered_m3: float
    spout: np.ndarray            # (3,) m, cart grid frame
    velocity: np.ndarray         # (3,) m/s, cart grid frame
    gravity: np.ndarray | None = None  # (3,) m/s^2, cart grid frame; None: -z


@dataclass(frozen=True)
class ControllerInput:
    """What a controller sees at one decision (state in).

    * ``t_s``: time of the decision, s; ``frame``: the frame the decision is made at (its result acts over
      frame -> frame + 1);
    * ``heights``: the measurement the latency rule gives this frame, (nx, ny) float64 m on the controller grid,
      NaN where no valid cell; ``None`` when there is none (before the first, a missing or stale one);
    * ``spout_x_m``: the actual auger (spout) location along grid x, m;
    * ``impacts``: predicted impact points (grid x, y m) at the target fill height and on the floor, from the
      known geometry: the stream lands between them;
    * ``drift_x_m``: predicted impact x minus spout x, m;
    * ``nudge_signal_m``: the spout grid x the current Machine Sync setpoint implies, m;
    * ``delivery``: the flow signal and spout kinematics (:class:`Delivery`);
    * ``target_fill_m``: the operator's target grain height above the cart floor, m (``controller.target_fill_m``;
      it may change during a run: ``cosim.Simulation.set``);
    * ``turn_shift_m``: (now, ahead) the steady-state shift of the spout along grid x, m, that the combine's yaw
      rate now and ``controller.coping.feedforward_lead_s`` ahead cause as the cart off-tracks in the turn
      (dynamics_proc.control.feedforward; (0, 0) on a straight path): the spout sits at ``nudge_signal_m`` plus it
      once the lateral correction below is applied;
    * ``lateral_correction_m``: the correction of Machine Sync's lateral setpoint that keeps the spout over the
      same line of the cart in the turn ``feedforward_lead_s`` ahead (the cart off-tracks sideways), m;
    * ``speed_change_mps2``: the largest rate at which the combine's speed changes within the next
      ``controller.coping.safety_lead_s`` (its speed profile, known to the combine), m/s^2.
    """

    t_s: float
    frame: int
    heights: np.ndarray | None
    spout_x_m: float
    impacts: tuple[tuple[float, float], ...]
    drift_x_m: float
    nudge_signal_m: float
    delivery: Delivery
    target_fill_m: float
    turn_shift_m: tuple[float, float] = (0.0, 0.0)
    lateral_correction_m: float = 0.0
    speed_change_mps2: float = 0.0


@dataclass(frozen=True)
class ControllerCommand:
    """What a controller decides (commands out).

    Acting on the plant:

    * ``nudge``: -1, 0 or +1, move the Machine Sync longitudinal setpoint by that many ``nudge_m`` along grid x;
    * ``auger_on``: run the auger (the flow ramps with the auger's time constant);
    * ``lateral_m``: move Machine Sync's lateral setpoint by this much from the operator's (cart to the left > 0),
      m (0: leave it);
    * ``flow``: the commanded flow while on, a fraction of the auger's nominal flow in (0, 1] (1: full flow; less
      slows the auger, as variable-speed unloading augers can).

    Reported only (``dyn_state``: desired_auger_x_m, control_effort_m, target_section, section_<k>_fullness,
    all_full, measurement_seen, control_bias_m):

    * ``desired_m``: desired auger location, grid x m;
    * ``effort_m``: control effort, grid x m (NaN: not reported);
    * ``target``: 0-based section being filled, -1 none;
    * ``fullness``: (N,) float, estimated height / target fill per section, NaN unknown (None: all unknown);
    * ``all_full``: the controller considers the cart full (a closed loop may stop early on it);
    * ``seen``: a measurement has been used; ``bias_m``: a learnt steady-state offset, m;
    * ``mode``: 0 measured, 1 dead reckoning, 2 holding (dynamics_proc.control.coping); ``hold_reason``: why it holds, a
      code of :data:`HOLD_REASONS` (0 not holding): the run's outcome names it, so a controller
      that stops on purpose should say why; ``sigma_m``: the stated 1-sigma of its estimate of the target
      section, m (NaN unknown); ``lead_m``: the lead added to the target section's level, m.
    """

    nudge: int
    auger_on: bool
    desired_m: float
    effort_m: float = math.nan
    target: int = -1
    fullness: np.ndarray | None = field(default=None, compare=False)
    all_full: bool = False
    seen: bool = True
    bias_m: float = 0.0
    mode: int = 0
    hold_reason: int = 0
    sigma_m: float = math.nan
    lead_m: float = 0.0
    flow: float = 1.0
    lateral_m: float = 0.0


@runtime_checkable
class OffloadingController(Protocol):
    """A controller object (see the module docstring)."""

    def initial_state(self) -> Any:
        """The controller's memory before the first frame."""

    def step(self, state: Any, inp: ControllerInput) -> tuple[Any, ControllerCommand]:
        """One decision: (next state, command)."""


#: ``factory(params: ControllerParams, scenario: Scenario) -> OffloadingController``
ControllerFactory = Callable[[Any, Any], OffloadingController]


def check_command(cmd: object, sections: int, ref: str) -> ControllerCommand:
    """``cmd`` when it is a valid :class:`ControllerCommand` for ``sections`` sections, with ``fullness`` (N,)
    float64 (NaN filled when None); else :class:`PluginFault` naming ``ref`` and the cause (frame unknown here)."""
    if not isinstance(cmd, ControllerCommand):
        raise PluginFault(ref, CONTROLLER_POINT, f"step returned {type(cmd).__name__} as its command, expected "
                          "ControllerCommand (return (state, ControllerCommand(...)))")
    if not isinstance(cmd.nudge, (int, np.integer)) or cmd.nudge not in (-1, 0, 1):
        raise PluginFault(ref, CONTROLLER_POINT, f"nudge must be -1, 0 or +1, got {cmd.nudge!r}")
    if not isinstance(cmd.auger_on, (bool, np.bool_)):
        raise PluginFault(ref, CONTROLLER_POINT, f"auger_on must be a bool, got {cmd.auger_on!r}")
    if not isinstance(cmd.target, (int, np.integer)) or not -1 <= cmd.target < sections:
        raise PluginFault(ref, CONTROLLER_POINT, f"target must be a section index in -1..{sections - 1}, "
                          f"got {cmd.target!r}")
    if not isinstance(cmd.desired_m, (float, int)) or not math.isfinite(cmd.desired_m):
        raise PluginFault(ref, CONTROLLER_POINT, f"desired_m must be a finite number (m), got {cmd.desired_m!r}")
    if not isinstance(cmd.flow, (float, int)) or isinstance(cmd.flow, bool) or not 0.0 < cmd.flow <= 1.0:
        raise PluginFault(ref, CONTROLLER_POINT, f"flow must be a fraction in (0, 1], got {cmd.flow!r}")
    if not isinstance(cmd.lateral_m, (float, int)) or isinstance(cmd.lateral_m, bool) or not math.isfinite(cmd.lateral_m):
        raise PluginFault(ref, CONTROLLER_POINT, f"lateral_m must be a finite number (m), got {cmd.lateral_m!r}")
    if not isinstance(cmd.hold_reason, (int, np.integer)) or isinstance(cmd.hold_reason, bool) or cmd.hold_reason < 0:
        raise PluginFault(ref, CONTROLLER_POINT, f"hold_reason must be a code >= 0, got {cmd.hold_reason!r}")
    if cmd.fullness is None:
        return _with_fullness(cmd, np.full(sections, np.nan))
    f = cmd.fullness
    if not isinstance(f, np.ndarray) or f.shape != (sections,) or f.dtype != np.float64:
        what = f"{f.shape} {f.dtype}" if isinstance(f, np.ndarray) else type(f).__name__
        raise PluginFault(ref, CONTROLLER_POINT, f"fullness must be a ({sections},) float64 array, got {what}")
    return cmd


def _with_fullness(cmd: ControllerCommand, fullness: np.ndarray) -> ControllerCommand:
    return replace(cmd, fullness=fullness)
