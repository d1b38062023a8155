"""One FMU instance in the loop: instantiate, set parameters and start values, initialise, step, close.

:class:`FmuSlave` wraps fmpy's ``FMU2Slave`` (FMI 2.0) or ``FMU3Slave`` (FMI 3.0) behind a small interface in
*our* signal order: ``step`` takes the inputs as one flat list of floats (in the order of the variables given at
construction, an FMI 3.0 array variable taking as many places as it has elements), calls ``doStep`` and returns
the outputs as one flat list of floats. Value references are grouped by FMI type once, so each call is one
``fmi2Set*``/``fmi3Get*`` per type. Any failure while stepping (a status other than OK, a NaN or infinite output)
raises :class:`FmuStepError` naming the FMU file, its role, the frame and the cause. ``close`` terminates and frees
the instance and removes the extracted files; use it as a context manager.

An FMI 3.0 FMU with an input clock (``clock``) is instantiated with Event Mode and ticked once per ``step``: at the
step's start time it enters Event Mode, activates the clock, sets the inputs, updates its discrete states (until it
needs no more), reads the outputs, returns to Step Mode and steps.
"""
from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from typing import Mapping, Sequence

from cosim.errors import RunError

from .describe import FmuDescription, require_fmpy
from .pythonfmu_exit import release_at_exit

__all__ = ["FmuStepError", "FmuSlave"]

#: the process every FMU runs in (the system model's)
PROCESS = "dynamics"
#: Event Mode updates an FMU may ask for at one tick before it counts as not settling
MAX_EVENT_ITERATIONS = 100
#: (FMI version, type) -> fmpy's setter and getter name suffix and the Python type of a value
_ACCESS = {("2.0", "Real"): ("Real", float), ("2.0", "Integer"): ("Integer", int),
           ("2.0", "Enumeration"): ("Integer", int), ("2.0", "Boolean"): ("Boolean", bool),
           ("2.0", "String"): ("String", str),
           ("3.0", "Float64"): ("Float64", float), ("3.0", "Int32"): ("Int32", int), ("3.0", "Int64"): ("Int64", int),
           ("3.0", "Enumeration"): ("Int64", int), ("3.0", "Boolean"): ("Boolean", bool),
           ("3.0", "String"): ("String", str)}


class FmuStepError(RunError):
    """An FMU failed during the run: the message names the file, the role, the frame and the cause."""


@dataclass(frozen=True)
class _Group:
    """Variables of one access type: their value references, their places in our flat list (one per element) and
    fmpy's setter / getter suffix and value type."""

    access: str
    cast: type
    refs: tuple[int, ...]
    index: tuple[int, ...]


def _groups(desc: FmuDescription, names: Sequence[str]) -> tuple[tuple[_Group, ...], tuple[tuple[int, int], ...]]:
    """The access groups of ``names`` and each name's (first place, number of places) in the flat list."""
    by_access: dict[tuple[str, type], tuple[list[int], list[int]]] = {}
    slots, at = [], 0
    for n in names:
        v = desc.variables[n]
        access, cast = _ACCESS[(desc.fmi_version, v.type)]
        refs, idx = by_access.setdefault((access, cast), ([], []))
        refs.append(v.value_reference)
        idx.extend(range(at, at + v.size))
        slots.append((at, v.size))
        at += v.size
    groups = tuple(_Group(a, c, tuple(r), tuple(i)) for (a, c), (r, i) in by_access.items())
    return groups, tuple(slots)


class FmuSlave:
    """An instantiated, initialised FMU (FMI 2.0 or 3.0 co-simulation).

    ``inputs`` / ``outputs``: FMU variable names, in the order of the flat lists ``step`` takes and returns;
    ``start``: FMU variable -> value set before initialisation (parameters and start values); ``label``: how
    messages name it (e.g. ``vehicles.tractor_cart.fmu``); ``start_time_s`` the experiment's start; ``nan_ok``:
    outputs that may be NaN (any other non-finite output is a fault); ``clock``: the FMI 3.0 input clock ticked at
    each step (None: none).
    """

    def __init__(self, desc: FmuDescription, inputs: Sequence[str], outputs: Sequence[str],
                 start: Mapping[str, object], label: str, start_time_s: float = 0.0,
                 instance_name: str = "graincosim", nan_ok: Sequence[str] = (), clock: str | None = None):
        fmpy = require_fmpy()
        self.desc, self.label = desc, label
        self.output_names = tuple(outputs)
        self._in, _ = _groups(desc, inputs)
        self._out, out_slots = _groups(desc, outputs)
        self.n_outputs = sum(size for _, size in out_slots)
        skip = set(nan_ok)
        self._checked = tuple((n, i) for n, (at, size) in zip(outputs, out_slots) if n not in skip
                              for i in range(at, at + size))
        self._clock = None if clock is None else desc.variables[clock].value_reference
        self._v3 = desc.fmi_version == "3.0"
        self._dir = fmpy.extract(str(desc.path))
        self._fmu = None
        try:
            self._fmu = self._instantiate(instance_name)
            self._initialise(start, start_time_s)
        except Exception as e:  # noqa: BLE001 - fmpy raises plain Exception subclasses for FMI statuses
            self.close()
            raise FmuStepError(f"FMU {desc.path} ({label}) failed to initialise: {e}", process=PROCESS,
                               frame=0) from e

    @property
    def clocked(self) -> bool:
        """Whether the FMU has an input clock, ticked at each :meth:`step`."""
        return self._clock is not None

    def _instantiate(self, instance_name: str):
        desc = self.desc
        if self._v3:
            from fmpy.fmi3 import FMU3Slave

            fmu = FMU3Slave(guid=desc.guid, unzipDirectory=self._dir, modelIdentifier=desc.model_identifier,
                            instanceName=instance_name)
            fmu.instantiate(eventModeUsed=self._clock is not None)
        else:
            from fmpy.fmi2 import FMU2Slave

            fmu = FMU2Slave(guid=desc.guid, unzipDirectory=self._dir, modelIdentifier=desc.model_identifier,
                            instanceName=instance_name)
            fmu.instantiate()
        release_at_exit(fmu.dll._name)          # a pythonfmu wrapper's exit order (cosim.fmi.pythonfmu_exit)
        return fmu

    def _initialise(self, start: Mapping[str, object], t0: float) -> None:
        fmu = self._fmu
        if not self._v3:
            fmu.setupExperiment(startTime=t0)
        for name, value in start.items():
            self._set_one(name, value)
        if self._v3:
            fmu.enterInitializationMode(startTime=t0)
        else:
            fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        if self._clock is not None:          # Event Mode follows initialisation when it is used
            self._settle()
            fmu.enterStepMode()

    def _set_one(self, name: str, value: object) -> None:
        v = self.desc.variables[name]
        access, cast = _ACCESS[(self.desc.fmi_version, v.type)]
        getattr(self._fmu, "set" + access)([v.value_reference], [cast(value)])

    def _settle(self) -> None:
        """Update the discrete states until the FMU needs no more (Event Mode)."""
        for _ in range(MAX_EVENT_ITERATIONS):
            if not self._fmu.updateDiscreteStates()[0]:
                return
        raise RuntimeError(f"fmi3UpdateDiscreteStates still asks for updates after {MAX_EVENT_ITERATIONS} calls")

    def _set_inputs(self, inputs: Sequence[float]) -> None:
        for g in self._in:
            getattr(self._fmu, "set" + g.access)(g.refs, [g.cast(inputs[i]) for i in g.index])

    def _get_outputs(self) -> list[float]:
        out = [0.0] * self.n_outputs
        for g in self._out:
            get = getattr(self._fmu, "get" + g.access)
            got = get(g.refs, len(g.index)) if self._v3 else get(g.refs)
            for i, x in zip(g.index, got):
                out[i] = float(x)
        return out

    def _fail(self, cause: str, frame: int, t_s: float) -> FmuStepError:
        return FmuStepError(f"FMU {self.desc.path} ({self.label}) failed at frame {frame} (t = {t_s:.3f} s): {cause}",
                            process=PROCESS, frame=frame)

    def step(self, inputs: Sequence[float], t_s: float, h_s: float, frame: int) -> list[float]:
        """Set ``inputs`` (our flat order), ``doStep(t_s, h_s)``, return the outputs (our flat order) as floats; an
        FMU with a clock is ticked at ``t_s`` first and its outputs are those of the tick. :class:`FmuStepError`
        when a call fails or an output is not finite."""
        fmu = self._fmu
        try:
            if self._clock is None:
                self._set_inputs(inputs)
                self._do_step(t_s, h_s)
                out = self._get_outputs()
            else:
                fmu.enterEventMode()
                fmu.setClock([self._clock], [True])
                self._set_inputs(inputs)
                self._settle()
                out = self._get_outputs()
                fmu.enterStepMode()
                self._do_step(t_s, h_s)
        except Exception as e:  # noqa: BLE001 - fmpy's FMICallException and ctypes errors
            raise self._fail(f"doStep: {e}", frame, t_s) from e
        for name, i in self._checked:
            if not math.isfinite(out[i]):
                raise self._fail(f"output {name!r} is {out[i]}", frame, t_s)
        return out

    def advance(self, t_s: float, h_s: float, frame: int) -> None:
        """``doStep(t_s, h_s)`` with the inputs held (no tick): brings the FMU's time forward to a decision."""
        try:
            self._do_step(t_s, h_s)
        except Exception as e:  # noqa: BLE001 - fmpy's FMICallException and ctypes errors
            raise self._fail(f"doStep: {e}", frame, t_s) from e

    def _do_step(self, t_s: float, h_s: float) -> None:
        if self._v3:
            terminate = self._fmu.doStep(t_s, h_s)[1]
            if terminate:
                raise RuntimeError("fmi3DoStep asked to terminate the simulation")
        else:
            self._fmu.doStep(currentCommunicationPoint=t_s, communicationStepSize=h_s)

    def close(self) -> None:
        """Terminate and free the instance, remove the extracted files. Safe to call twice."""
        fmu, self._fmu = self._fmu, None
        if fmu is not None:
            try:
                fmu.terminate()
            except Exception:  # noqa: BLE001 - a failed FMU may refuse to terminate; it is still freed
                pass
            fmu.freeInstance()
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    def __enter__(self) -> "FmuSlave":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
