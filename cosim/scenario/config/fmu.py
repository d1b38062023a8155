"""Scenario records for FMUs (FMI co-simulation units) standing in for a built-in model (docs/fmu.md).

An :class:`Fmu` names the file and maps *our* names (the signals of the role it plays, listed in
``cosim.fmi.roles``) to the FMU's variable names; ``parameters`` sets the FMU's own parameters by their names.
Where it is used:

* ``vehicles.tractor_cart.fmu``: the tractor-and-cart dynamics, driven by Machine Sync's commands;
* ``controller.fmu`` with ``controller.model: fmu``: the offloading controller; with ``controller.strategy:
  fmu``: the fill strategy.

Whether the file is an FMI 2.0 or 3.0 co-simulation FMU and whether every mapped variable exists with the right
causality is checked when the scenario is loaded (``cosim.fmi.check``), each problem at its YAML line.
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal, Union

from pydantic import Field

from .base import Model

__all__ = ["FMU_REF", "Fmu", "TractorCart", "Vehicles", "FmuStep", "ParameterValue"]

#: the plug-in reference (``controller.strategy`` / ``controller.model``) that names ``controller.fmu``
FMU_REF = "fmu"

#: what one ``doStep`` covers: one dynamics step (``timing.dynamics_dt_s``) or one sensor frame
FmuStep = Literal["dynamics_step", "frame"]
#: a parameter value: Real (float or int), Integer (int), Boolean (bool) or String (str), by the variable's type
ParameterValue = Union[bool, int, float, str]

_NAME = r"^\S(.*\S)?$"


class Fmu(Model):
    """One FMU in the loop.

    * ``path``: the ``.fmu`` file, relative to the scenario file;
    * ``inputs`` / ``outputs``: our signal name -> FMU variable name (causality ``input`` / ``output``); for
      per-section signals the FMU name holds ``{k}``, replaced by the section number (1..N; 0..N-1 with
      ``index_base: 0``), or, in an FMI 3.0 FMU, names an array of N elements;
    * ``index_base``: how the FMU numbers sections, in its per-section names and in its section values (the
      strategy's ``section`` and ``current_section``, the controller's ``target_section``): 1 (1..N, 0 for none)
      or 0 (0..N-1, -1 for none, as the Python strategy protocol does);
    * ``initial``: our initial value -> FMU variable (causality ``parameter`` or ``input``) set before the
      FMU is initialised, so that it starts where the built-in model starts;
    * ``parameters``: FMU variable (causality ``parameter``) -> value, set before initialisation;
    * ``step``: ``dynamics_step`` (one ``doStep`` of ``timing.dynamics_dt_s`` per dynamics step, inputs
      updated before each) or ``frame`` (one ``doStep`` of ``timing.sensor_period_s`` per frame, inputs held);
      unset: the role's own (the vehicle ``dynamics_step``; a controller or strategy only per ``frame``).
    """

    path: Path
    """The .fmu file (FMI 2.0 or 3.0 co-simulation), relative to the scenario file."""
    inputs: dict[str, str] = {}
    """Our signal name -> the FMU's input variable; for per-section signals the FMU name holds {k} (section
    1..N)."""
    outputs: dict[str, str] = {}
    """Our signal name -> the FMU's output variable; for per-section signals the FMU name holds {k}."""
    initial: dict[str, str] = {}
    """Our initial value -> FMU variable (parameter or input) set before initialisation."""
    parameters: dict[str, ParameterValue] = {}
    """FMU parameter variable -> value (Real, Integer, Boolean or String), set before initialisation."""
    step: FmuStep | None = None
    """dynamics_step (one doStep per dynamics step) or frame (one per sensor frame); unset: the role's own."""
    instance_name: str = Field(default="graincosim", pattern=_NAME, max_length=64)
    """Instance name given to the FMU (1-64 characters, no surrounding whitespace)."""
    index_base: Literal[0, 1] = 1
    """How the FMU numbers sections: 1 (1..N, 0 for none) or 0 (0..N-1, -1 for none)."""

    def __hash__(self) -> int:
        # frozen records are hashable (the scenario is a cache key); the mappings hash as their items
        return hash((self.path, *(tuple(getattr(self, k).items()) for k in ("inputs", "outputs", "initial",
                                                                              "parameters")),
                     self.step, self.instance_name, self.index_base))


class TractorCart(Model):
    """The tractor towing the cart: the built-in model (``dynamics_proc.vehicles.motion``) unless ``fmu`` is given."""

    fmu: Fmu | None = None
    """An FMU that replaces the built-in tractor-and-cart dynamics (docs/fmu.md)."""


class Vehicles(Model):
    """Replaceable vehicle dynamics. The combine always follows its path (``combine``)."""

    tractor_cart: TractorCart = TractorCart()
    """The tractor towing the cart: the built-in model unless an FMU is given."""
