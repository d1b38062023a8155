"""Whether a run did its job: summary.json's ``outcome`` (docs/architecture.md, docs/field.md).

A run can complete as a simulation and still not fill the cart. :func:`judge` reads what the run left (the
summary's fill, spill and perception parts, the recorded series and the run's error) and says one of

* ``filled``: every section's true peak is within ``outcome.underfill_tolerance_m`` of the target, no spill
  beyond ``outcome.spill_tolerance_kg``, no overfill beyond ``outcome.overfill_tolerance_m``;
* ``stopped_safe``: not filled, but nothing spilled or overfilled and the auger is off at the end because the
  controller stopped on purpose and said why (``dyn_state.hold_reason``), or perception never found the cart
  so the auger never started;
* ``unfinished``: not filled, nothing spilled or overfilled, the auger started and the controller still at work
  (no hold, the cart not declared full) when the run reached its duration (``duration_s``, ``--duration``): the
  run ended before the job could be done, which is no failure of the job; the reason gives the progress made
  (``fill.fill_fraction``, the sections at target);
* ``job_failed``: everything else: spill, overfill, a run that did not complete, a controller that declared
  the cart full while a section is short of the target, a run that ended unfilled with the auger never started
  and no reason given, or with the controller holding but the grain still flowing,

with a ``reason`` in words and numbers ("perception never found the cart: 0 of 1201 frames", "spill 120 kg",
"overfill 15 cm in section 9", "the run ended at its duration, 10.0 s, before the job was done: 12.3 % filled").
Pure: no I/O.

The controller's hold reasons (:data:`HOLD_REASONS`, cosim.scenario.config.holds) are the contract between the
controller (which writes the code into ``dyn_state.hold_reason``, dynamics_proc.control.coping) and this judge.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from cosim.scenario.config import Scenario
from cosim.scenario.config.holds import HOLD_LOST, HOLD_NO_MEASUREMENT, HOLD_NONE, HOLD_REASONS

__all__ = ["FILLED", "STOPPED_SAFE", "UNFINISHED", "JOB_FAILED", "STATUSES", "HOLD_NONE", "HOLD_NO_MEASUREMENT", "HOLD_LOST",
           "HOLD_REASONS", "judge", "outcome_line"]

FILLED, STOPPED_SAFE, UNFINISHED, JOB_FAILED = "filled", "stopped_safe", "unfinished", "job_failed"
#: every status, from the job done to the job failed
STATUSES = (FILLED, STOPPED_SAFE, UNFINISHED, JOB_FAILED)

#: a flow level below this counts as stopped (the auger's run-out ends exactly at 0)
FLOW_STOPPED = 1e-9
_CM_PER_M = 100.0


def _col(series: Mapping[str, np.ndarray], name: str) -> np.ndarray:
    a = series.get(name)
    return np.asarray(a, np.float64) if a is not None else np.zeros(0)


def _sections_short(peaks: list, target: float, tol: float) -> list[tuple[int, float]]:
    """(section 1..N, peak m) of every section whose true peak is more than ``tol`` under ``target``."""
    return [(k + 1, float(p)) for k, p in enumerate(peaks)
            if p is None or not math.isfinite(p) or p < target - tol]


def _worst_overfill(peaks: list, target: float) -> tuple[int, float]:
    """(section 1..N, overfill m) of the highest section."""
    vals = [p if p is not None and math.isfinite(p) else -math.inf for p in peaks]
    k = int(np.argmax(vals)) if vals else 0
    return k + 1, (vals[k] - target) if vals else math.nan


def _cart_frames(series: Mapping[str, np.ndarray]) -> tuple[int, int] | None:
    """(frames perception found the cart in, frames it ran) or None when perception did not run."""
    valid = _col(series, "perc_state.cart_valid")
    if valid.size == 0:
        return None
    return int(np.count_nonzero(valid > 0.5)), int(valid.size)


def _hold_text(series: Mapping[str, np.ndarray], code: int) -> str:
    """The controller's final hold reason with the numbers it left in the series."""
    text = HOLD_REASONS.get(code, f"hold reason {code}")
    if code == HOLD_LOST:
        t = _col(series, "dyn_state.t_s")
        mode = _col(series, "dyn_state.hold_reason")
        sigma = _col(series, "dyn_state.estimate_sigma_m")
        held = np.flatnonzero(mode == HOLD_LOST)
        start = held[0] if held.size else len(t) - 1
        # the start of the last uninterrupted hold
        gaps = np.flatnonzero(np.diff(held) > 1)
        if gaps.size:
            start = held[gaps[-1] + 1]
        s = sigma[start] if sigma.size > start else math.nan
        text = (f"perception lost the cart or the fill; the dead-reckoned estimate's 1-sigma reached "
                f"{s * _CM_PER_M:.1f} cm at {t[start]:.1f} s: auger off, holding")
    return text


def judge(scenario: Scenario, summary: Mapping, series: Mapping[str, np.ndarray]) -> dict:
    """``{"status", "reason", ...}`` of a run from its summary (``fill``, ``spill``, ``completed``, ``error``) and
    its series (``"<block>.<field>"`` -> (frames,) float64). The extra keys give the numbers the reason rests
    on: ``sections_at_target`` of ``sections``, ``fill_fraction`` (the summary's, None without it), ``auger_on_s``,
    ``cart_found_frames`` / ``perception_frames``
    (None without perception), ``hold_reason`` (the controller's last code)."""
    tol = scenario.outcome
    target = scenario.controller.target_fill_m
    fill = summary.get("fill") or {}
    peaks = list(fill.get("section_peak_height_m") or [])
    n = scenario.controller.sections
    spill_kg = float((summary.get("spill") or {}).get("mass_kg") or 0.0)
    on = _col(series, "dyn_state.auger_on")
    flow = _col(series, "dyn_state.flow_level")
    t = _col(series, "dyn_state.t_s")
    hold = _col(series, "dyn_state.hold_reason")
    all_full = _col(series, "dyn_state.all_full")
    auger_on_s = float(np.count_nonzero(on > 0.5)) * scenario.timing.sensor_period_s
    cart = _cart_frames(series)
    code = int(hold[-1]) if hold.size else HOLD_NONE
    short = _sections_short(peaks, target, tol.underfill_tolerance_m) if peaks else [(k + 1, math.nan)
                                                                                       for k in range(n)]
    progress = fill.get("fill_fraction")
    facts = {"sections_at_target": n - len(short), "sections": n, "auger_on_s": auger_on_s,
             "fill_fraction": float(progress) if isinstance(progress, (int, float)) else None,
             "cart_found_frames": cart[0] if cart else None, "perception_frames": cart[1] if cart else None,
             "hold_reason": code}
    failed: list[str] = []
    if spill_kg > tol.spill_tolerance_kg:
        failed.append(f"spill {spill_kg:.0f} kg")
    if peaks:
        k, over = _worst_overfill(peaks, target)
        if over > tol.overfill_tolerance_m:
            failed.append(f"overfill {over * _CM_PER_M:.0f} cm in section {k}")
    if not summary.get("completed"):
        err = summary.get("error") or {}
        what = err.get("message") or summary.get("status") or "it stopped early"
        failed.append(f"the run did not complete ({summary.get('status', 'failed')} after "
                      f"{float(summary.get('sim_time_s') or 0.0):.1f} s): {what}")
    if failed:
        return {"status": JOB_FAILED, "reason": "; ".join(failed), **facts}
    if not short:
        return {"status": FILLED, "reason": f"every section within {tol.underfill_tolerance_m * _CM_PER_M:.0f} cm "
                f"of the {target:.2f} m target, no spill, overfill at most {tol.overfill_tolerance_m * _CM_PER_M:.0f}"
                " cm", **facts}
    worst = min(short, key=lambda kp: kp[1] if math.isfinite(kp[1]) else -math.inf)
    shortfall = (f"{n - len(short)} of {n} sections at target (section {worst[0]} peaks "
                 f"{worst[1]:.2f} m of {target:.2f} m)")
    stopped = flow.size == 0 or flow[-1] <= FLOW_STOPPED
    if all_full.size and all_full[-1] > 0.5:
        return {"status": JOB_FAILED, "reason": f"the controller declared the cart full but only {shortfall}",
                **facts}
    if cart is not None and cart[0] == 0 and stopped:
        started = "the auger never started" if auger_on_s == 0.0 else f"the auger ran {auger_on_s:.1f} s"
        return {"status": STOPPED_SAFE, "reason": f"perception never found the cart: 0 of {cart[1]} frames; "
                f"{started}; {shortfall}", **facts}
    if code != HOLD_NONE and stopped:
        why = _unfit(summary) if code == HOLD_NO_MEASUREMENT else None
        return {"status": STOPPED_SAFE, "reason": f"{why or _hold_text(series, code)}; {shortfall}", **facts}
    end = float(t[-1]) if t.size else 0.0
    if auger_on_s == 0.0:
        return {"status": JOB_FAILED, "reason": f"the auger never started and the controller gave no reason; "
                f"{shortfall}", **facts}
    if code != HOLD_NONE:           # holding, the grain not yet stopped when the run ended
        return {"status": JOB_FAILED, "reason": f"not filled when the run ended at {end:.1f} s, the controller "
                f"holding ({HOLD_REASONS.get(code, code)}) with the grain still flowing: {shortfall}", **facts}
    done = f"{facts['fill_fraction'] * 100.0:.1f} % filled, " if facts["fill_fraction"] is not None else ""
    return {"status": UNFINISHED, "reason": f"the run ended at its duration, {end:.1f} s, before the job was done: "
            f"{done}{shortfall}", **facts}


def _unfit(summary: Mapping) -> str | None:
    """Why perception withheld every height map (its cameras' expected error at the cart exceeds what the target
    allows: ``perception.fitness.reason``, perception_proc's summary), or None."""
    fitness = (summary.get("perception") or {}).get("fitness") or {}
    return fitness.get("reason") if isinstance(fitness, Mapping) else None


def outcome_line(outcome: Mapping | None) -> str:
    """The one line the console and log.txt print: ``outcome: <status>: <reason>``."""
    if not outcome:
        return "outcome: unknown (no frames were recorded)"
    return f"outcome: {outcome.get('status')}: {outcome.get('reason')}"
