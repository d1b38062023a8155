"""The controller's hold reasons: the codes a controller writes into ``dyn_state.hold_reason`` when it holds the
auger on purpose, and what each means in words. A contract between the controller (``controller.model``,
re-exported by dynamics_proc.control.protocol) and the run's outcome (cosim.runtime.outcome), kept here so that
neither imports the other.
"""
from __future__ import annotations

__all__ = ["HOLD_NONE", "HOLD_NO_MEASUREMENT", "HOLD_LOST", "HOLD_REASONS"]

#: hold reason codes (``dyn_state.hold_reason``): 0 the controller is not holding
HOLD_NONE = 0
#: no usable height map has arrived yet, so the auger has not been started
HOLD_NO_MEASUREMENT = 1
#: perception lost the cart or the fill and the dead-reckoned estimate is no longer confident enough
HOLD_LOST = 2
#: code -> what the controller is doing, in words
HOLD_REASONS: dict[int, str] = {
    HOLD_NO_MEASUREMENT: "no usable height map yet: the auger is not started",
    HOLD_LOST: "perception lost the cart or the fill and dead reckoning is not confident enough: auger off, holding",
}
