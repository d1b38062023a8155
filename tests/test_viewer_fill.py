"""The fullness bars' one rule: label and colour (status) from one function, at the band's edges and beyond."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.scenario.config import Scenario
from cosim.viewer.fill import STATUSES, bar_labels, section_status
from cosim.viewer.server import fill_band_of, state_json
from cosim.viewer.snapshot import History, Snapshot
from cosim.viewer.viewinfo import ViewInfo, default_fill

#: the default scenario's band: 1.9 m target, 5 cm under and over allowed: 97.37 % .. 102.63 %
BAND = ViewInfo.of(Scenario(format_version=1)).fill_band


def test_the_band_is_the_outcomes_tolerance_around_the_target():
    lo, hi = BAND
    assert lo == pytest.approx(1 - 0.05 / 1.9) and hi == pytest.approx(1 + 0.05 / 1.9)
    assert default_fill() == BAND
    sc = Scenario.model_validate({"format_version": 1, "controller": {"target_fill_m": 1.5},
                                  "outcome": {"underfill_tolerance_m": 0.15, "overfill_tolerance_m": 0.0}})
    assert ViewInfo.of(sc).fill_band == pytest.approx((0.9, 1.0))


@pytest.mark.parametrize("value, label, status", [
    (0.5, "50 %", "below"),
    (0.9736, "97 %", "below"),        # below the band's 97.37 %
    (0.9749, "97 %", "below"),        # shows 97 %: below, whatever the digits after
    (0.975, "98 %", "at"),            # shows 98 %: within
    (0.995, "100 %", "at"),           # the controller's full_fraction
    (0.9951, "100 %", "at"),          # a bar labelled 100 % is never "below target"
    (1.0, "100 %", "at"),
    (1.0249, "102 %", "at"),
    (1.0251, "103 %", "over"),        # above the band's 102.63 %
    (1.2, "120 %", "over"),
    (-0.01, "-1 %", "below"),
    (float("nan"), "?", "unknown"),
    (None, "?", "unknown"),
])
def test_boundaries(value, label, status):
    assert section_status(value, BAND) == (label, status)


def test_with_no_tolerance_only_a_100_percent_label_is_at_target():
    band = (1.0, 1.0)
    assert section_status(0.9949, band) == ("99 %", "below")
    assert section_status(0.995, band) == ("100 %", "at")
    assert section_status(1.0049, band) == ("100 %", "at")
    assert section_status(1.0051, band) == ("101 %", "over")
    # an edge that float arithmetic puts a hair above a whole per cent still takes that label
    assert section_status(0.97, (1 - 0.03 / 1.0000000000001, 1.0))[1] == "at"


def test_one_label_one_colour():
    """Across every fullness from empty to overfull, each label has exactly one status."""
    seen: dict[str, set[str]] = {}
    for v in np.linspace(-0.05, 1.4, 290_001):
        label, status = section_status(float(v), BAND)
        seen.setdefault(label, set()).add(status)
    assert all(len(s) == 1 for s in seen.values()), {k: s for k, s in seen.items() if len(s) > 1}
    assert {s for v in seen.values() for s in v} == {"below", "at", "over"}
    assert math.isclose(len(seen), 146)                        # -5 % .. 140 %


def test_the_state_carries_labels_status_and_band():
    class Source:
        name, frames_planned, view = "x", 10, None
        history = History()

        def snapshot(self):
            return Snapshot(frame=1, structs={"dyn_state": {"section1_fullness": 0.9961, "section2_fullness": 0.4,
                                                            "section3_fullness": float("nan")}},
                            frames={"dyn_state": 1})

    doc = state_json(Source())["fullness"]
    assert doc["labels"] == ["100 %", "40 %", "?"] and doc["status"] == ["at", "below", "unknown"]
    assert doc["values"][2] is None and doc["band"] == list(default_fill())
    assert fill_band_of(Source()) == default_fill()
    assert bar_labels([], BAND) == {"labels": [], "status": [], "band": list(BAND)}
    assert list(STATUSES) == ["below", "at", "over", "unknown"]
