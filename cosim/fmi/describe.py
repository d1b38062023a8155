"""What an FMU file is, read without running it: FMI version, kind, model, variables (through fmpy).

:func:`describe` opens the ``.fmu`` (a zip archive), reads ``modelDescription.xml`` with fmpy and refuses what
graincosim cannot step: not an FMU, model exchange only, an FMI version other than 2.0, no binary for this
platform. fmpy is optional (``pip install "graincosim[fmi]"``): :func:`require_fmpy` says so when it is missing.
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

__all__ = ["FMI_VERSIONS", "FmiUnavailable", "FmuInvalid", "Variable", "FmuDescription", "require_fmpy",
           "describe"]

#: FMI versions graincosim steps (FMI 3.0: fmpy reads it, but no tool here builds a test FMU; see docs/fmu.md)
FMI_VERSIONS = ("2.0",)


class FmiUnavailable(ImportError):
    """fmpy is not installed; the message says how to install it."""


class FmuInvalid(ValueError):
    """The file is not an FMU graincosim can step; the message says why and what to export instead."""


@dataclass(frozen=True)
class Variable:
    """One scalar variable of an FMU: ``type`` is ``Real``, ``Integer``, ``Boolean``, ``String`` or
    ``Enumeration``; ``causality`` ``parameter``, ``input``, ``output``, ``local``, ...; ``start`` as text or None."""

    name: str
    value_reference: int
    type: str
    causality: str
    variability: str
    start: str | None


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


def _fmi_version(path: str) -> str:
    """The ``fmiVersion`` attribute of the FMU's model description, read without fmpy's full parse."""
    if not zipfile.is_zipfile(path):
        raise FmuInvalid("is not an FMU (not a zip archive); export the model as an FMU (FMI 2.0 co-simulation)")
    with zipfile.ZipFile(path) as zf:
        if "modelDescription.xml" not in zf.namelist():
            raise FmuInvalid("is not an FMU: the archive has no modelDescription.xml")
        try:
            root = ElementTree.fromstring(zf.read("modelDescription.xml"))
        except ElementTree.ParseError as e:
            raise FmuInvalid(f"has a model description that is not XML: {e}") from None
    return root.get("fmiVersion", "?")


@lru_cache(maxsize=16)
def _describe(path: str, size: int, mtime_ns: int) -> FmuDescription:
    fmpy = require_fmpy()
    from fmpy.model_description import read_model_description

    version = _fmi_version(path)
    if version not in FMI_VERSIONS:
        hint = ("FMI 3.0 FMUs are not supported yet" if version.startswith("3") else
                f"FMI {version} is not supported")
        raise FmuInvalid(f"is an FMI {version} FMU: {hint}; export it as FMI 2.0 co-simulation")
    try:
        md = read_model_description(path, validate=False)
    except Exception as e:  # noqa: BLE001 - fmpy raises plain Exception / lxml errors for a broken description
        raise FmuInvalid(f"has a model description fmpy cannot read: {e}") from None
    if md.coSimulation is None:
        raise FmuInvalid("is a model-exchange FMU; graincosim steps co-simulation FMUs only (export it as FMI 2.0 "
                         "co-simulation, with the solver inside the FMU)")
    platforms = tuple(fmpy.supported_platforms(path))
    if fmpy.platform not in platforms:
        raise FmuInvalid(f"has no binary for this platform ({fmpy.platform}); it has "
                         f"{', '.join(platforms) or 'none'}: export it on or for {fmpy.platform}")
    variables = {v.name: Variable(v.name, int(v.valueReference), v.type, v.causality or "local",
                                  v.variability or "continuous", None if v.start is None else str(v.start))
                 for v in md.modelVariables}
    return FmuDescription(Path(path), md.fmiVersion, md.modelName or "", md.coSimulation.modelIdentifier,
                          md.generationTool or "", md.guid or "", platforms, MappingProxyType(variables),
                          bool(md.coSimulation.canHandleVariableCommunicationStepSize))
