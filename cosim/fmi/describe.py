"""What an FMU file is, read without running it: FMI version, kind, model, variables (through fmpy).

:func:`describe` opens the ``.fmu`` (a zip archive), reads ``modelDescription.xml`` with fmpy and refuses what
graincosim cannot step: not an FMU, model exchange only, an FMI version other than 2.0 or 3.0, no binary for this
platform. fmpy is optional (``pip install "graincosim[fmi]"``): :func:`require_fmpy` says so when it is missing.

FMI 2.0 and 3.0 name their types differently; :attr:`Variable.kind` puts both in one vocabulary (``Real``,
``Integer``, ``Boolean``, ``String``, ``Enumeration``) for the types graincosim maps, and is None for the others
(FMI 3.0 ``Float32``, ``Int8`` ... ``UInt64``, ``Binary``, ``Clock``), which a mapping refuses by name.
"""
from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Mapping
from xml.etree import ElementTree

from .archive import archive_problem

__all__ = ["FMI_VERSIONS", "KINDS", "KIND_NAMES", "FmiUnavailable", "FmuInvalid", "Clock", "Variable",
           "FmuDescription", "require_fmpy", "describe"]

#: FMI versions graincosim steps
FMI_VERSIONS = ("2.0", "3.0")
#: FMU variable type -> the kind graincosim maps it as (FMI 2.0 and FMI 3.0 names); a type not here is not mapped
KINDS = {"Real": "Real", "Float64": "Real", "Integer": "Integer", "Int32": "Integer", "Int64": "Integer",
         "Boolean": "Boolean", "String": "String", "Enumeration": "Enumeration"}
#: how each kind is written in an FMI version (messages speak the FMU's own vocabulary)
KIND_NAMES = {"2.0": {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean", "String": "String",
                      "Enumeration": "Enumeration"},
              "3.0": {"Real": "Float64", "Integer": "Int32 or Int64", "Boolean": "Boolean", "String": "String",
                      "Enumeration": "Enumeration"}}


class FmiUnavailable(ImportError):
    """fmpy is not installed; the message says how to install it."""


class FmuInvalid(ValueError):
    """The file is not an FMU graincosim can step; the message says why and what to export instead."""


@dataclass(frozen=True)
class Clock:
    """What an FMI 3.0 ``Clock`` variable declares: ``interval_variability`` (``triggered``, ``constant``,
    ``fixed``, ...) and, for a constant clock, its ``interval_s`` and ``shift_s`` (``intervalDecimal``,
    ``shiftDecimal``; None where not given)."""

    interval_variability: str
    interval_s: float | None = None
    shift_s: float | None = None


@dataclass(frozen=True)
class Variable:
    """One variable of an FMU: ``type`` as the FMU declares it (FMI 2.0 ``Real``, ``Integer``, ...; FMI 3.0
    ``Float64``, ``Int32``, ...; see :attr:`kind`); ``causality`` ``parameter``, ``input``, ``output``, ``local``,
    ...; ``start`` as text or None; ``shape`` () for a scalar, (n,) ... for an FMI 3.0 array; ``min`` / ``max`` the
    declared range as text (None: unbounded); ``clock`` what a Clock variable declares (None for other types)."""

    name: str
    value_reference: int
    type: str
    causality: str
    variability: str
    start: str | None
    shape: tuple[int, ...] = ()
    min: str | None = None
    max: str | None = None
    clock: Clock | None = None

    @property
    def kind(self) -> str | None:
        """``Real``, ``Integer``, ``Boolean``, ``String`` or ``Enumeration`` for the types graincosim maps, else
        None."""
        return KINDS.get(self.type)

    @property
    def size(self) -> int:
        """Number of values: 1 for a scalar, the product of the shape for an array."""
        n = 1
        for d in self.shape:
            n *= d
        return n


@dataclass(frozen=True)
class FmuDescription:
    """The parts of an FMU's model description the runtime and ``validate`` use."""

    path: Path
    fmi_version: str
    model_name: str
    model_identifier: str
    generation_tool: str
    guid: str
    platforms: tuple[str, ...]
    variables: Mapping[str, Variable]
    can_vary_step: bool
    has_event_mode: bool = False

    def input_clocks(self) -> list[Variable]:
        """The FMU's input clocks (FMI 3.0 ``Clock`` variables of causality ``input``)."""
        return [v for v in self.variables.values() if v.type == "Clock" and v.causality == "input"]

    def summary(self) -> str:
        """One line for ``validate``: file, FMI version, model, tool, GUID."""
        return (f"{self.path} (FMI {self.fmi_version} co-simulation, model {self.model_name!r}, "
                f"{self.generation_tool or 'unknown tool'}, guid {self.guid})")


def require_fmpy() -> ModuleType:
    """The fmpy module; :class:`FmiUnavailable` naming the extra to install when it is missing."""
    try:
        import fmpy
    except ImportError as e:
        raise FmiUnavailable("FMUs need fmpy, which is not installed: pip install \"graincosim[fmi]\" "
                             f"(or pip install fmpy) [{e}]") from None
    return fmpy


def describe(path: str | os.PathLike) -> FmuDescription:
    """The description of the FMU at ``path``; :class:`FmuInvalid` when it cannot be stepped here, OSError when
    it cannot be read. Cached per (path, size, modification time)."""
    p = Path(path).resolve()
    st = p.stat()
    return _describe(str(p), st.st_size, st.st_mtime_ns)


def _read_root(path: str) -> ElementTree.Element:
    """The root element of the FMU's model description, read without fmpy's full parse."""
    if not zipfile.is_zipfile(path):
        raise FmuInvalid("is not an FMU (not a zip archive); export the model as an FMU (FMI 2.0 or 3.0 co-simulation)")
    try:
        unsafe = archive_problem(path)
    except zipfile.BadZipFile as e:
        raise FmuInvalid(f"is not a readable zip archive: {e}") from None
    if unsafe is not None:
        raise FmuInvalid(unsafe)
    with zipfile.ZipFile(path) as zf:
        if "modelDescription.xml" not in zf.namelist():
            raise FmuInvalid("is not an FMU: the archive has no modelDescription.xml")
        try:
            root = ElementTree.fromstring(zf.read("modelDescription.xml"))
        except ElementTree.ParseError as e:
            raise FmuInvalid(f"has a model description that is not XML: {e}") from None
    return root


def _clocks(root: ElementTree.Element) -> dict[str, Clock]:
    """name -> Clock of every FMI 3.0 ``Clock`` variable (fmpy does not read the interval)."""
    def num(text):
        return None if text is None else float(text)

    return {e.get("name"): Clock(e.get("intervalVariability", ""), num(e.get("intervalDecimal")),
                                 num(e.get("shiftDecimal")))
            for e in root.iterfind("ModelVariables/Clock")}


@lru_cache(maxsize=16)
def _describe(path: str, size: int, mtime_ns: int) -> FmuDescription:
    fmpy = require_fmpy()
    from fmpy.model_description import read_model_description

    root = _read_root(path)
    version = root.get("fmiVersion", "?")
    if version not in FMI_VERSIONS:
        raise FmuInvalid(f"is an FMI {version} FMU: FMI {version} is not supported; export it as FMI 2.0 or 3.0 "
                         "co-simulation")
    try:
        md = read_model_description(path, validate=False)
    except Exception as e:  # noqa: BLE001 - fmpy raises plain Exception / lxml errors for a broken description
        raise FmuInvalid(f"has a model description fmpy cannot read: {e}") from None
    if md.coSimulation is None:
        raise FmuInvalid(f"is a model-exchange FMU; graincosim steps co-simulation FMUs only (export it as FMI "
                         f"{version} co-simulation, with the solver inside the FMU)")
    platforms = tuple(fmpy.supported_platforms(path))
    if fmpy.platform not in platforms:
        raise FmuInvalid(f"has no binary for this platform ({fmpy.platform}); it has "
                         f"{', '.join(platforms) or 'none'}: export it on or for {fmpy.platform}")
    clocks = _clocks(root)
    variables = {v.name: Variable(v.name, int(v.valueReference), v.type, v.causality or "local",
                                  v.variability or "continuous", None if v.start is None else str(v.start),
                                  tuple(v.shape or ()), v.min, v.max, clocks.get(v.name))
                 for v in md.modelVariables}
    return FmuDescription(Path(path), md.fmiVersion, md.modelName or "", md.coSimulation.modelIdentifier,
                          md.generationTool or "", md.guid or "", platforms, MappingProxyType(variables),
                          bool(md.coSimulation.canHandleVariableCommunicationStepSize),
                          bool(md.coSimulation.hasEventMode))
