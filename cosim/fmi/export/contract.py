"""The external dynamics' contract: what the exported world (:mod:`cosim.fmi.export.world`, :mod:`.build`) asks of
the dynamics role driven from outside, named by import path and resolved when used, so that ``cosim`` imports no
participant (docs/CONTRACTS.md, "Layers").

* :data:`CREATE` / :data:`BLOCKS`: the participant (a ring member whose ``set_inputs(**values)`` holds the
  inputs over the next frame) and its shared-memory blocks;
* :data:`INPUT_STARTS`: ``scenario -> {input name: start value}``, the FMU's inputs in their order at the
  scenario's initial state (auger off, no flow);
* :data:`READOUT`: ``scenario -> SectionReadout``, the per-section figures the FMU's outputs give
  (:class:`SectionReadout`);
* :data:`TERRAIN_REFUSED`: why a scenario with terrain cannot be driven from outside.
"""
from __future__ import annotations

from typing import Any, Protocol

import numpy as np

__all__ = ["CREATE", "BLOCKS", "INPUT_STARTS", "READOUT", "TERRAIN_REFUSED", "SectionReadout"]

#: the externally driven dynamics participant's factory
CREATE = "dynamics_proc.fmu.external:create"
#: its blocks (the same as the built-in dynamics')
BLOCKS = "dynamics_proc.blocks:declare_blocks"
#: scenario -> {input name: start value}
INPUT_STARTS = "dynamics_proc.fmu.export:input_starts"
#: scenario -> SectionReadout
READOUT = "dynamics_proc.fmu.export:SectionReadout"
#: why a scenario with terrain cannot be driven from outside
TERRAIN_REFUSED = ("the world driven from outside stands on flat ground: its inputs are planar poses, which do not "
                   "say how the machines stand on the scenario's terrain; export a scenario without terrain")


class SectionReadout(Protocol):
    """The controller's view of a height map, section by section (N = ``controller.sections``, section 1 first):
    ``target_m`` (``controller.target_fill_m``, m) and ``sections`` (N)."""

    target_m: float
    sections: int

    def truth_peaks(self, dynamics: Any) -> np.ndarray:
        """(N,) float64 robust peak height above the floor of each section of the participant's true fill, m."""

    def true_means(self, dynamics: Any) -> np.ndarray:
        """(N,) float64 mean grain height above the floor of each section of the true fill, m."""

    def perceived_peaks(self, heightmap: np.ndarray) -> np.ndarray:
        """(N,) float64 robust peak of each section of a perceived height map on the controller's grid, m (NaN:
        too few valid cells)."""
