"""Building the test FMUs with pythonfmu (FMI 2.0 co-simulation, Python inside), once per test session.

``build_all(dest)`` builds the example FMUs (examples/fmu_vehicle, examples/fmu_controller) and the test-only ones
(tests/fmus) into ``dest`` and returns name -> path; ``variant(src, dest, edit)`` copies an FMU with its
modelDescription.xml edited (wrong kind, wrong FMI version). pythonfmu and fmpy are test dependencies; where
either is missing, ``MISSING`` says which (the tests skip with that reason).
"""
from __future__ import annotations

import importlib.util
import zipfile
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parent.parent
SOURCES = {
    "TractorCart": ROOT / "examples" / "fmu_vehicle" / "TractorCart.py",
    "SectionFill": ROOT / "examples" / "fmu_controller" / "SectionFill.py",
    "FrontToBack": ROOT / "tests" / "fmus" / "FrontToBack.py",
    "Faulty": ROOT / "tests" / "fmus" / "Faulty.py",
}
MISSING = [m for m in ("pythonfmu", "fmpy") if importlib.util.find_spec(m) is None]


def build_all(dest: Path) -> dict[str, Path]:
    """Every test FMU built into ``dest``: name -> .fmu path."""
    from pythonfmu import FmuBuilder

    return {name: Path(FmuBuilder.build_FMU(src, dest=dest)) for name, src in SOURCES.items()}


def variant(src: Path, dest: Path, edit: Callable[[str], str]) -> Path:
    """A copy of FMU ``src`` at ``dest`` whose modelDescription.xml is ``edit(text)``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = edit(data.decode("utf-8")).encode("utf-8")
            zout.writestr(item, data)
    return dest
