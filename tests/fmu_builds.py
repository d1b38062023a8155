"""Building the test FMUs once per test session.

``build_all(dest)`` builds into ``dest`` and returns name -> path:

* FMI 2.0, with pythonfmu (Python inside): the example FMUs (examples/fmu_vehicle, examples/fmu_controller) and the
  test-only ones (tests/fmus/*.py written against ``pythonfmu``);
* FMI 3.0, with pythonfmu3, where it is installed: the example's TractorCart3 and tests/fmus/FrontToBack3.py;
* FMI 3.0 in C, where a C compiler is found (``cc``, Linux x86-64): tests/fmus/Clocked/ (an input clock, which
  pythonfmu3 FMUs cannot have: its fmi3SetClock is not implemented), as ``Clocked`` (triggered clock) and
  ``ClockedPeriodic`` (constant clock of 0.1 s).

``variant(src, dest, edit)`` copies an FMU with its modelDescription.xml edited (wrong kind, wrong FMI version).
pythonfmu and fmpy are test dependencies; where either is missing, ``MISSING`` says which (the tests skip with that
reason). :func:`need` skips a test whose FMU could not be built here, naming what is missing.
"""
from __future__ import annotations

import importlib.util
import platform
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Callable

import pytest

ROOT = Path(__file__).resolve().parent.parent
FMUS = ROOT / "tests" / "fmus"
VEHICLE = ROOT / "examples" / "fmu_vehicle"
#: name -> (script, project files) built with pythonfmu (FMI 2.0)
SOURCES = {
    "TractorCart": (VEHICLE / "TractorCart.py", [VEHICLE / "tractor_cart_model.py"]),
    "SectionFill": (ROOT / "examples" / "fmu_controller" / "SectionFill.py", []),
    "FrontToBack": (FMUS / "FrontToBack.py", []),
    "FrontToBack0": (FMUS / "FrontToBack0.py", []),
    "Faulty": (FMUS / "Faulty.py", []),
}
#: name -> (script, project files) built with pythonfmu3 (FMI 3.0)
SOURCES3 = {
    "TractorCart3": (VEHICLE / "TractorCart3.py", [VEHICLE / "tractor_cart_model.py"]),
    "FrontToBack3": (FMUS / "FrontToBack3.py", []),
}
CLOCKED = FMUS / "Clocked"
#: FMU name -> the Clock attributes of its input clock ``tick``
CLOCK_VARIANTS = {"Clocked": 'intervalVariability="triggered"',
                  "ClockedPeriodic": 'intervalVariability="constant" intervalDecimal="0.1"'}
#: FMI functions Clocked.c implements; the others fmpy binds are stubs returning fmi3Error
CLOCKED_IMPLEMENTS = {
    "fmi3GetVersion", "fmi3SetDebugLogging", "fmi3InstantiateCoSimulation", "fmi3FreeInstance",
    "fmi3EnterInitializationMode", "fmi3ExitInitializationMode", "fmi3EnterEventMode", "fmi3EnterStepMode",
    "fmi3Terminate", "fmi3Reset", "fmi3SetClock", "fmi3GetClock", "fmi3UpdateDiscreteStates", "fmi3DoStep",
    "fmi3GetFloat64", "fmi3SetFloat64", "fmi3GetInt32", "fmi3GetBoolean", "fmi3SetBoolean",
}
#: fmi3Error, what a stub returns
FMI3_ERROR = 3

MISSING = [m for m in ("pythonfmu", "fmpy") if importlib.util.find_spec(m) is None]
#: why the FMI 3.0 Python FMUs cannot be built here ("" when they can)
MISSING3 = "" if importlib.util.find_spec("pythonfmu3") else "pythonfmu3 (pip install -e \".[test]\")"
#: why the C FMUs cannot be built here ("" when they can)
MISSING_C = ("" if shutil.which("cc") and sys.platform == "linux" and platform.machine() == "x86_64" else
             "a C compiler (cc) on Linux x86-64")


def _python_fmus(builder, sources: dict, dest: Path) -> dict[str, Path]:
    return {name: Path(builder.build_FMU(src, dest=dest, project_files=files)) for name, (src, files) in
            sources.items()}


def build_clocked(dest: Path) -> dict[str, Path]:
    """The C FMUs (tests/fmus/Clocked), one per clock variant: name -> path."""
    import fmpy
    from fmpy.fmi3 import FMU3Slave

    with tempfile.TemporaryDirectory() as tmp:
        stubs = Path(tmp) / "stubs.c"
        names = sorted(n for n in dir(FMU3Slave) if n.startswith("fmi3") and n not in CLOCKED_IMPLEMENTS)
        stubs.write_text("".join(f"int {n}(void) {{ return {FMI3_ERROR}; }}\n" for n in names))
        lib = Path(tmp) / "Clocked.so"
        include = Path(fmpy.__file__).parent / "c-code"
        subprocess.run(["cc", "-shared", "-fPIC", "-O1", "-I", str(include), str(CLOCKED / "Clocked.c"), str(stubs),
                        "-o", str(lib), "-lm"], check=True, capture_output=True)
        template = (CLOCKED / "modelDescription.xml").read_text()
        out = {}
        for name, clock in CLOCK_VARIANTS.items():
            path = dest / f"{name}.fmu"
            with zipfile.ZipFile(path, "w") as zf:
                zf.writestr("modelDescription.xml", template.replace("@CLOCK@", clock))
                zf.write(lib, "binaries/x86_64-linux/Clocked.so")
            out[name] = path
        return out


def build_all(dest: Path) -> dict[str, Path]:
    """Every test FMU that can be built here, built into ``dest``: name -> .fmu path."""
    import pythonfmu

    built = _python_fmus(pythonfmu.FmuBuilder, SOURCES, dest)
    if not MISSING3:
        import pythonfmu3

        built.update(_python_fmus(pythonfmu3.FmuBuilder, SOURCES3, dest))
    if not MISSING_C:
        built.update(build_clocked(dest))
    return built


def need(built: dict[str, Path], name: str) -> Path:
    """The built FMU ``name``; the test is skipped, naming what is missing, where it could not be built here."""
    if name not in built:
        why = MISSING_C if name in CLOCK_VARIANTS else MISSING3
        pytest.skip(f"the test FMU {name} needs {why}")
    return built[name]


def variant(src: Path, dest: Path, edit: Callable[[str], str]) -> Path:
    """A copy of FMU ``src`` at ``dest`` whose modelDescription.xml is ``edit(text)``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = edit(data.decode("utf-8")).encode("utf-8")
            zout.writestr(item, data)
    return dest
