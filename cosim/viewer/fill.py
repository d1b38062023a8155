"""The fullness bars' one rule: each section's label and its status (the bar's colour) from one function.

A section's fullness is the controller's estimated height over the target fill (``dyn_state.section<k>_fullness``,
1 = at the target). The label is the fullness in whole per cent (``"100 %"``), ``"?"`` when unknown (NaN); the
status is decided on that shown per cent against the band the run's outcome allows around the target
(``1 - underfill_tolerance_m / target_fill_m`` .. ``1 + overfill_tolerance_m / target_fill_m``): ``below``
under the band, ``at`` within it, ``over`` above it, ``unknown`` without a value. Deciding on the shown number
is what keeps label and colour together: a bar labelled "100 %" is never "below target", and one label always
has one colour. The page draws what :func:`bar_labels` says (colours and legend from :data:`STATUSES`).
"""
from __future__ import annotations

import math

__all__ = ["STATUSES", "section_status", "bar_labels"]

#: status -> (legend text, colour the page draws it in), in legend order
STATUSES = {"below": ("below target", "#60b0ff"), "at": ("at target", "#7fdc7f"),
            "over": ("over target", "#ff8060"), "unknown": ("unknown", "#555555")}
#: slack of the band comparison, per cent (a band edge computed as 97.0000000001 % still takes a 97 % label)
BAND_SLACK_PCT = 1e-6


def section_status(value: float | None, band: tuple[float, float]) -> tuple[str, str]:
    """(label, status) of one section's fullness ``value`` (a fraction of the target; None or NaN: unknown) in
    the band (lowest, highest fullness at the target; fractions)."""
    if value is None or not math.isfinite(value):
        return "?", "unknown"
    pct = math.floor(100.0 * value + 0.5)                       # half up, as the label is read
    if pct < 100.0 * band[0] - BAND_SLACK_PCT:
        status = "below"
    elif pct > 100.0 * band[1] + BAND_SLACK_PCT:
        status = "over"
    else:
        status = "at"
    return f"{pct} %", status


def bar_labels(values, band: tuple[float, float]) -> dict:
    """The bars of ``values`` (fullness per section, 1 = front): {labels, status, band (lowest, highest)}."""
    pairs = [section_status(v, band) for v in values]
    return {"labels": [p[0] for p in pairs], "status": [p[1] for p in pairs], "band": [band[0], band[1]]}
