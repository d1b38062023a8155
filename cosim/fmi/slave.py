"""One FMU instance in the loop: instantiate, set parameters and start values, initialise, step, close.

:class:`FmuSlave` wraps fmpy's ``FMU2Slave`` behind a small interface in *our* signal order: ``set_inputs``
takes the inputs as one flat list of floats (in the order given at construction), ``do_step`` advances
the FMU, ``outputs`` returns the outputs as floats. Value references are grouped by FMI type once, so each
call is one ``fmi2Set*``/``fmi2Get*`` per type. Any failure while stepping (a status other than OK, a NaN
or infinite output) raises :class:`FmuStepError` naming the FMU file, its role, the frame and the cause.
``close`` terminates and frees the instance and removes the extracted files; use it as a context manager.
"""
from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from typing import Mapping, Sequence

from cosim.errors import RunError

from .describe import FmuDescription, require_fmpy

__all__ = ["FmuStepError", "FmuSlave"]

#: the process every FMU runs in (the system model's)
PROCESS = "dynamics"


class FmuStepError(RunError):
    """An FMU failed during the run: the message names the file, the role, the frame and the cause."""


@dataclass(frozen=True)
class _Group:
    """Variables of one FMI type: their value references and their positions in our flat list."""

    type: str
    refs: tuple[int, ...]
    index: tuple[int, ...]


def _groups(desc: FmuDescription, names: Sequence[str]) -> tuple[_Group, ...]:
    by_type: dict[str, tuple[list[int], list[int]]] = {}
    for i, n in enumerate(names):
        v = desc.variables[n]
        t = "Integer" if v.type == "Enumeration" else v.type
        refs, idx = by_type.setdefault(t, ([], []))
        refs.append(v.value_reference)
        idx.append(i)
    return tuple(_Group(t, tuple(r), tuple(i)) for t, (r, i) in by_type.items())


class FmuSlave:
    """An instantiated, initialised FMU (FMI 2.0 co-simulation).

    ``inputs`` / ``outputs``: FMU variable names, in the order of the flat lists ``set_inputs`` takes and
    ``outputs`` returns; ``start``: FMU variable -> value set before initialisation (parameters and start
    values); ``label``: how messages name it (e.g. ``vehicles.tractor_cart.fmu``); ``start_time_s`` the
    experiment's start; ``nan_ok``: outputs that may be NaN (any other non-finite output is a fault).
    """

    def __init__(self, desc: FmuDescription, inputs: Sequence[str], outputs: Sequence[str],
                 start: Mapping[str, object], label: str, start_time_s: float = 0.0,
                 instance_name: str = "graincosim", nan_ok: Sequence[str] = ()):
        fmpy = require_fmpy()
        from fmpy.fmi2 import FMU2Slave

        self.desc, self.label = desc, label
        self.output_names = tuple(outputs)
        self._checked = tuple(i for i, n in enumerate(outputs) if n not in set(nan_ok))
        self._in = _groups(desc, inputs)
        self._out = _groups(desc, outputs)
        self._n_in = len(inputs)
        self._dir = fmpy.extract(str(desc.path))
        self._fmu = None
        try:
            fmu = FMU2Slave(guid=desc.guid, unzipDirectory=self._dir, modelIdentifier=desc.model_identifier,
                            instanceName=instance_name)
            fmu.instantiate()
            self._fmu = fmu
            fmu.setupExperiment(startTime=start_time_s)
            for name, value in start.items():
                self._set_one(name, value)
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
        except Exception as e:  # noqa: BLE001 - fmpy raises plain Exception subclasses for FMI statuses
            self.close()
            raise FmuStepError(f"FMU {desc.path} ({label}) failed to initialise: {e}", process=PROCESS,
                               frame=0) from e

    def _set_one(self, name: str, value: object) -> None:
        v = self.desc.variables[name]
        ref = [v.value_reference]
        if v.type == "Real":
            self._fmu.setReal(ref, [float(value)])
        elif v.type in ("Integer", "Enumeration"):
            self._fmu.setInteger(ref, [int(value)])
        elif v.type == "Boolean":
            self._fmu.setBoolean(ref, [bool(value)])
        else:
            self._fmu.setString(ref, [str(value)])

    def _fail(self, cause: str, frame: int, t_s: float) -> FmuStepError:
        return FmuStepError(f"FMU {self.desc.path} ({self.label}) failed at frame {frame} (t = {t_s:.3f} s): {cause}",
                            process=PROCESS, frame=frame)

    def step(self, inputs: Sequence[float], t_s: float, h_s: float, frame: int) -> list[float]:
        """Set ``inputs`` (our order), ``doStep(t_s, h_s)``, return the outputs (our order) as floats.
        :class:`FmuStepError` when a call fails or an output is not finite."""
        fmu = self._fmu
        try:
            for g in self._in:
                vals = [inputs[i] for i in g.index]
                if g.type == "Real":
                    fmu.setReal(g.refs, vals)
                elif g.type == "Integer":
                    fmu.setInteger(g.refs, [int(x) for x in vals])
                else:
                    fmu.setBoolean(g.refs, [bool(x) for x in vals])
            fmu.doStep(currentCommunicationPoint=t_s, communicationStepSize=h_s)
            out = [0.0] * len(self.output_names)
            for g in self._out:
                got = (fmu.getReal(g.refs) if g.type == "Real" else
                       fmu.getInteger(g.refs) if g.type == "Integer" else fmu.getBoolean(g.refs))
                for i, x in zip(g.index, got):
                    out[i] = float(x)
        except Exception as e:  # noqa: BLE001 - fmpy's FMICallException and ctypes errors
            raise self._fail(f"doStep: {e}", frame, t_s) from e
        for i in self._checked:
            if not math.isfinite(out[i]):
                raise self._fail(f"output {self.output_names[i]!r} is {out[i]}", frame, t_s)
        return out

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
