"""What the exported world reads of the dynamics role driven from outside (its contract:
cosim.fmi.export.contract): the inputs' start values and the per-section figures of a height map.
"""
from __future__ import annotations

from dataclasses import fields

import numpy as np

from cosim.scenario.config import Scenario
from dynamics_proc.control.controller import ControllerParams
from dynamics_proc.control.sections import section_heights
from dynamics_proc.fmu.external import ExternalDynamicsParticipant, initial_inputs
from dynamics_proc.grain.fill import resample
from dynamics_proc.summary import section_stats

__all__ = ["input_starts", "SectionReadout"]


def input_starts(s: Scenario) -> dict[str, float | bool]:
    """{input name: start value} at the scenario's initial state, in :class:`~dynamics_proc.fmu.external.WorldInputs`'
    field order."""
    u = initial_inputs(s)
    return {f.name: getattr(u, f.name) for f in fields(u)}


def _no_strategy(*_args) -> int:
    """The controller parameters' strategy slot: the exported world has no controller."""
    return -1


class SectionReadout:
    """The built-in controller's section estimates of scenario ``s`` (cosim.fmi.export.contract.SectionReadout)."""

    def __init__(self, s: Scenario):
        self.scenario = s
        self.control = ControllerParams.from_scenario(s, strategy=_no_strategy)
        self.target_m = self.control.target_m
        self.sections = self.control.sections

    def truth_peaks(self, dynamics: ExternalDynamicsParticipant) -> np.ndarray:
        c, g = self.control, dynamics.params.grid
        return section_heights(resample(dynamics.world.heights, g.cell_m, c.grid_cell_m, g.length_m, g.width_m), c)

    def true_means(self, dynamics: ExternalDynamicsParticipant) -> np.ndarray:
        return section_stats(dynamics.world.heights, self.scenario)[1]

    def perceived_peaks(self, heightmap: np.ndarray) -> np.ndarray:
        return section_heights(np.array(heightmap, dtype=np.float64), self.control)
