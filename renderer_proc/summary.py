"""The renderer's part of summary.json: which exact ray cast a mock renderer ran (``ray_caster``).

A renderer that ray-casts (``renderer: mock``, or a beam-native CSV pattern under GL) records the caster it
runs in ``render_state.ray_caster``, the index of its name in :data:`cosim.world.fastcast.CASTERS`: ``numpy``,
``embree`` (the scene built every frame) or ``embree-static`` (the rigid bodies built once per run). A GL run
records nothing and gets no key.
"""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config.scenario import Scenario
from cosim.world.fastcast import CASTERS
from renderer_proc.blocks import STATE_BLOCK

__all__ = ["summarize"]

#: the timeseries column of the ray caster's code
COLUMN = f"{STATE_BLOCK}.ray_caster"


def summarize(scenario: Scenario, series: dict[str, np.ndarray], heightmap_truth: np.ndarray | None) -> dict:
    """``{"ray_caster": name}`` from the last recorded frame's code; ``{}`` when the renderer casts no rays."""
    codes = series.get(COLUMN)
    if codes is None or len(codes) == 0 or not math.isfinite(float(codes[-1])):
        return {}
    code = int(codes[-1])
    return {"ray_caster": CASTERS[code] if 0 <= code < len(CASTERS) else f"unknown ({code})"}
