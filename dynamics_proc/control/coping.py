"""How the built-in controller copes with field conditions (``controller.coping``; docs/field.md): pure functions.

* **Lead on the full level** (:func:`rise_rate`, :func:`full_with_lead`): each section's estimated peak is
  differentiated and filtered (first-order, ``rise_tau_s``) into a rise rate r >= 0 (m/s); a section counts
  as full once ``peak + r * full_lead_s`` reaches the full level. The grain that still lands on a section after
  the controller decides it is full (while the nudges move the impact on, and during the auger's run-out after
  the last one) is about r times that time, so at a high flow the decision comes that much earlier.
* **Confidence of the dead-reckoned estimate** (:func:`section_sigma`): with the fused estimator
  (dynamics_proc.control.estimator) the controller keeps filling while perception does not see the target section,
  on the delivered volume placed at the impact predicted from Machine Sync's relative pose; the estimate's own
  variance says how far it can be trusted. The 1-sigma of the cell that sets the target section's peak is
  compared with
  ``fallback_sigma_m``; beyond it the controller switches the auger off and holds
  (:data:`dynamics_proc.control.protocol.HOLD_LOST`).
* **Modes** reported in ``dyn_state.control_mode``: :data:`MODE_MEASURED` (the target section was seen in the
  latest measurement), :data:`MODE_DEAD_RECKONING` (it was not; the estimate carries on), :data:`MODE_HOLD`
  (auger off, no nudges; ``dyn_state.hold_reason`` says why).

* **Safety ahead** (:func:`unexplained_shift`): a stop, a start or a latency makes the cart move under the spout
  faster than any nudge would (Machine Sync lags or overshoots); the impact is checked where that velocity puts it
  ``safety_lead_s`` on, and the auger pauses while the combine's speed changes fast (``pause_accel_mps2``).

Feed-forward of the auger target through turns is :mod:`dynamics_proc.control.feedforward` (it needs the vehicles'
geometry, so the frame step computes it and hands it to the controller in ``ControllerInput.feedforward_m``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dynamics_proc.control.protocol import HOLD_LOST, HOLD_NO_MEASUREMENT, HOLD_NONE

__all__ = ["MODE_MEASURED", "MODE_DEAD_RECKONING", "MODE_HOLD", "rise_rate", "peak_sigma", "SlowLimits", "slowed_section", "mode",
           "unexplained_shift"]

MODE_MEASURED, MODE_DEAD_RECKONING, MODE_HOLD = 0, 1, 2


def rise_rate(rate: np.ndarray, prev: np.ndarray, heights: np.ndarray, dt_s: float, tau_s: float) -> np.ndarray:
    """Filtered rise rate (N,) m/s of the section peaks: ``rate`` (N,) the previous filtered value, ``prev`` and
    ``heights`` (N,) m the peaks one step of ``dt_s`` apart (NaN unknown: the rate is kept). First-order filter
    with time constant ``tau_s`` (its gain dt / tau, at most 1) on the signed differences, so that noise on a
    perceived peak averages out (callers use the positive part)."""
    with np.errstate(invalid="ignore"):
        raw = (heights - prev) / dt_s
    gain = min(dt_s / tau_s, 1.0)
    return np.where(np.isfinite(raw), rate + gain * (raw - rate), rate)


def peak_sigma(blocks: np.ndarray, var: np.ndarray, rows: slice) -> float:
    """1-sigma (m) of a section's estimated peak: the standard deviation of the cell that sets it, the highest
    2 x 2 block minimum ``blocks`` (nx, ny) m (NaN outside the edge margin) over the grid rows ``rows``, from the
    estimate's variances ``var`` (nx, ny) m^2. Infinite when the section has no block."""
    sub = blocks[rows]
    if not np.isfinite(sub).any():
        return float("inf")
    i, j = np.unravel_index(int(np.nanargmax(sub)), sub.shape)
    return float(np.sqrt(var[(rows.start or 0) + i, j]))


@dataclass(frozen=True)
class SlowLimits:
    """When the auger is slowed near full (:func:`slowed_section`): the lead ``lead_s`` (s; 0 switches slowing
    off), the rise over it that needs no slowing ``allowance_m`` (m), the "full" level ``full_level_m`` (m), the
    sections' centres along grid x ``centres_m`` (N,) m and a section's length ``section_m`` (m)."""

    lead_s: float
    allowance_m: float
    full_level_m: float
    centres_m: tuple[float, ...]
    section_m: float


def slowed_section(target: int, slowed: int, full: np.ndarray, heights: np.ndarray, rate: np.ndarray,
                   impact_x: float, limits: SlowLimits) -> int:
    """The section (0-based) the auger is slowed for, -1 none: the ``target`` once its level ``heights[target]``
    plus its rise over the lead, ``max(rate, 0) * lead_s``, reaches ``full_level_m`` while that rise exceeds
    ``allowance_m`` (a high flow; latched while it stays the target, ``slowed`` the last answer), and that
    section, once ``full``, until the predicted ``impact_x`` (grid x, m) is within half a section (``section_m``)
    of the next target's centre (at a high flow the grain dropped on the way lands on the full section).
    ``heights``, ``rate`` (N,) m, m/s; ``full`` (N,) bool; the other figures from ``limits``."""
    lead_s, allowance_m, full_level_m = limits.lead_s, limits.allowance_m, limits.full_level_m
    centres_m, section_m = limits.centres_m, limits.section_m
    if target < 0 or lead_s <= 0.0:
        return -1
    if slowed == target:
        return target
    rise = max(float(rate[target]), 0.0) * lead_s
    if rise > allowance_m and heights[target] + rise >= full_level_m:
        return target
    arrived = abs(impact_x - centres_m[target]) <= 0.5 * section_m
    return slowed if slowed >= 0 and full[slowed] and not arrived else -1


def mode(seen: bool, target: int, target_seen: bool, fused: bool, sigma_m: float,
         fallback_sigma_m: float) -> tuple[int, int]:
    """(mode, hold reason) of a decision: holding (:data:`~dynamics_proc.control.protocol.HOLD_NO_MEASUREMENT`) before any
    measurement; measured while there is no target or the latest map shows it (``target_seen``); else dead
    reckoning on the ``fused`` estimate while the target's 1-sigma ``sigma_m`` stays within ``fallback_sigma_m``
    (m), holding (:data:`~dynamics_proc.control.protocol.HOLD_LOST`) beyond. Without a fused estimate (the paper's
    estimator) there is nothing to reckon with: it goes on with the last heights (its stale-target rule)."""
    if not seen:
        return MODE_HOLD, HOLD_NO_MEASUREMENT
    if target < 0 or target_seen:
        return MODE_MEASURED, HOLD_NONE
    if fused and not (math.isfinite(sigma_m) and sigma_m <= fallback_sigma_m):
        return MODE_HOLD, HOLD_LOST
    return MODE_DEAD_RECKONING, HOLD_NONE


def unexplained_shift(spout_x: float, prev_x: float, dt_s: float, nudge_speed_mps: float, lead_s: float) -> float:
    """How far (m, along grid x) the spout will have moved over the cart in ``lead_s`` at its measured velocity
    (``spout_x`` now and ``prev_x`` one decision of ``dt_s`` ago, m) beyond what a nudge explains: only the part
    of the speed above ``nudge_speed_mps`` counts (a nudge moves the cart to a setpoint the controller vetted as
    safe). 0.0 before a previous position is known."""
    if not math.isfinite(prev_x) or lead_s <= 0.0:
        return 0.0
    v = (spout_x - prev_x) / dt_s
    excess = abs(v) - nudge_speed_mps
    return math.copysign(excess, v) * lead_s if excess > 0.0 else 0.0
