"""The lead on the full level at the flow that is about to run (``controller.coping``; docs/field.md).

The controller slows the auger for a section near full (dynamics_proc.control.coping.slowed_section) and keeps it slowed
while the impact travels on to the next target; there the flow comes back to nominal. Whether the next target must
be slowed as well is judged on its lead, its rise rate times ``full_lead_s`` (the grain in the air and the auger's
run-out that still land after the decision). But the rise measured during the travel is the rise at the *slowed*
flow: the grain that reaches a section grows with the flow, so at nominal flow the same section rises
``nominal / slowed`` times faster. A section that arrives nearly full (the heap spilt over from its neighbour)
then looks slow enough to take the full flow, and overshoots by the rise at nominal flow over the lead.

:func:`rise_at_nominal` scales the measured rise to the flow that runs once the slowing ends, by the ratio of the
nominal flow level (1) to the flow level the rise was measured at. That level is the commanded level filtered
exactly as the rise rate is (:func:`level_filter`, first order with ``rise_tau_s``), so the two carry the same lag
of the flow's changes. It is applied only while a release is pending (a section other than the target is still
slowed): then the next decision is whether the full flow may come back. While nothing is slowed the rise is
measured at the flow that runs, and the lead is as it was.
"""
from __future__ import annotations

import numpy as np

__all__ = ["level_filter", "rise_at_nominal", "commanded_level"]


def commanded_level(auger_on: bool, slowed: int, slow_flow: float) -> float:
    """The flow level (fraction of nominal) a decision commands: 0 off, ``slow_flow`` while a section is slowed
    (``slowed`` >= 0), else 1."""
    if not auger_on:
        return 0.0
    return slow_flow if slowed >= 0 else 1.0


def level_filter(level_f: float, level: float, dt_s: float, tau_s: float) -> float:
    """One step of the first-order filter (gain ``dt_s / tau_s``, at most 1) of the commanded flow ``level``: the
    flow level the filtered rise rate (dynamics_proc.control.coping.rise_rate, the same filter) was measured at."""
    return level_f + min(dt_s / tau_s, 1.0) * (level - level_f)


def rise_at_nominal(rate: np.ndarray, level_f: float, slowed: int, target: int, slow_flow: float) -> np.ndarray:
    """The rise rates (N,) m/s to judge the lead on: ``rate`` scaled to the nominal flow, ``rate / level``, while a
    release is pending (``slowed`` >= 0 and not the ``target``, a target left), the filtered ``level_f`` floored at ``slow_flow``
    (the lowest level a running auger is commanded: the noise of a rise measured with the auger off is not
    amplified beyond that); ``rate`` itself otherwise."""
    if target < 0 or slowed < 0 or slowed == target or slow_flow >= 1.0:
        return rate
    return rate / min(max(level_f, slow_flow), 1.0)
