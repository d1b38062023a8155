"""``launch.py export-fmu``: write an FMU holding one scenario's world, sensors and perception (docs/fmu.md).

:func:`export_scenario` turns a scenario into the one the FMU carries: perception feedback (so the ring holds the
renderer and perception), the renderer asked for (mock by default), perception not overlapping the next frame
(each ``doStep`` reads the perception of the frame it ran), no vehicle or controller FMU or plug-in (the master
holds those), every file the scenario names copied beside it (``files/``) and named relative to it. A perception
plug-in given by import path is refused: the FMU carries the scenario's files, not its Python modules.
:func:`export_fmu` writes that scenario and the model class (:mod:`.fmu2` with pythonfmu, :mod:`.fmu3` with
pythonfmu3) into a folder and builds the FMU from it, after checking the scenario loads there as the FMU will
load it.
"""
from __future__ import annotations

import importlib
import importlib.util
import keyword
import re
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import yaml

from cosim.errors import OutputError
from cosim.scenario.config import Scenario
from cosim.scenario.loader import load_scenario, path_fields
from cosim.scenario.plugins import is_import_path
from cosim.scenario.trust import plugin_points
from cosim.scenario.yamlmarks import Dumper
from cosim.world.terrain import terrain_of

from .contract import TERRAIN_REFUSED
from .destination import DestinationError, fmu_destination, shown, write_atomically
from .world import SCENARIO_FILE


class BuilderMissing(ImportError):
    """The FMU builder for the FMI version asked for is not installed; the message says what to install."""

__all__ = ["FMI_BUILDERS", "FILES_DIR", "BuilderMissing", "DestinationError", "model_identifier", "export_scenario", "export_fmu",
           "export_command"]

HERE = Path(__file__).resolve().parent
#: FMI version -> (builder module, model class file)
FMI_BUILDERS = {"2": ("pythonfmu", HERE / "fmu2.py"), "3": ("pythonfmu3", HERE / "fmu3.py")}
#: folder of the scenario's files inside the FMU's resources
FILES_DIR = "files"
#: the model class's name in the model class files, replaced by the FMU's model identifier
TEMPLATE_CLASS = "GrainWorld"
#: the renderers an exported world can use (perception needs images)
RENDERERS = ("mock", "gl")


def _taken(ident: str) -> bool:
    """Whether ``ident`` names a module Python could import instead of the FMU's own (pythonfmu imports the model
    class from a module of that name: ``gc`` or ``json`` would be the standard library's)."""
    if ident in sys.stdlib_module_names or ident in sys.builtin_module_names or ident in sys.modules:
        return True
    try:
        return importlib.util.find_spec(ident) is not None
    except (ImportError, ValueError):
        return True


def model_identifier(out: Path) -> str:
    """The FMU's model identifier (a C identifier, also its binary's and its Python module's name) from the output
    file's stem; ``_fmu`` is appended while it names a module Python would import instead (``gc.fmu`` ->
    ``gc_fmu``)."""
    ident = re.sub(r"\W", "_", out.stem)
    if not ident or ident[0].isdigit() or keyword.iskeyword(ident):
        ident = "M" + ident
    while _taken(ident):
        ident += "_fmu"
    return ident


def _perception_plugins(s: Scenario) -> list[str]:
    """The perception plug-ins ``s`` names by import path (the FMU cannot carry them)."""
    return [f"{'.'.join(loc)} = {ref!r}" for loc, group, ref, _ in plugin_points(s)
            if group.startswith("perception") and is_import_path(ref)]


def export_scenario(s: Scenario, folder: Path, renderer: str = "mock") -> Path:
    """Write the scenario the FMU carries (and the files it names) into ``folder``; return its path."""
    if renderer not in RENDERERS:
        raise ValueError(f"renderer {renderer!r}: the exported world renders with {' or '.join(RENDERERS)}")
    if terrain_of(s) is not None:
        raise ValueError(TERRAIN_REFUSED)
    refused = _perception_plugins(s)
    if refused:
        raise ValueError(f"{', '.join(refused)}: an exported FMU carries the scenario's files but not its Python "
                         "modules; install the plug-in as a package (an entry point) or use a built-in")
    d = s.model_dump(mode="json")
    d.update(feedback="perception", renderer=renderer)
    d["timing"]["schedule"] = "sequential"
    # the master drives the vehicles: no Machine Sync pose of the world's own to gate the found cart against
    d["perception"]["pose_gate_m"] = 0.0
    d["vehicles"]["tractor_cart"]["fmu"] = None
    d["controller"].update(fmu=None, model="section_fill", model_options={}, strategy="front_to_back",
                           strategy_options={})
    d.pop("plugin_dir", None)
    files = folder / FILES_DIR
    for loc in path_fields():
        node = d
        for part in loc[:-1]:
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, dict) or not node.get(loc[-1]):
            continue
        src = Path(node[loc[-1]])
        files.mkdir(parents=True, exist_ok=True)
        dest = files / f"{len(list(files.iterdir()))}_{src.name}"
        shutil.copy2(src, dest)
        node[loc[-1]] = f"{FILES_DIR}/{dest.name}"
    path = folder / SCENARIO_FILE
    path.write_text(f"# the scenario of the exported world '{s.name}' (launch.py export-fmu)\n" +
                    yaml.dump(d, Dumper=Dumper, sort_keys=False, allow_unicode=True, width=120))
    return path


def export_fmu(s: Scenario, out: str | Path, fmi: str = "2", renderer: str = "mock", *, overwrite: bool = False,
               parents: bool = False) -> Path:
    """Build the FMU of scenario ``s`` at ``out`` (FMI ``fmi`` "2" or "3", rendering with ``renderer``); return
    the path of the file written. ``out`` is checked first and written atomically (cosim.fmi.export.destination:
    an existing folder takes ``<scenario name>.fmu``; ``overwrite`` replaces an earlier FMU, ``parents`` makes
    missing folders). :class:`cosim.errors.ScenarioError` when the exported scenario does not load, ValueError for
    what an export cannot carry or a destination it cannot use (:class:`DestinationError`),
    :class:`BuilderMissing` when the builder for that FMI version is not installed, OSError when the file cannot
    be written."""
    out = fmu_destination(out, s.name, overwrite=overwrite, parents=parents)
    if fmi not in FMI_BUILDERS:
        raise ValueError(f"FMI {fmi!r}: export writes FMI {' or '.join(FMI_BUILDERS)}")
    module, template = FMI_BUILDERS[fmi]
    try:
        builder = importlib.import_module(module).FmuBuilder
    except ImportError as e:
        raise BuilderMissing(f"exporting FMI {fmi}.0 needs {module}: pip install {module} [{e}]") from None
    ident = model_identifier(out)
    with tempfile.TemporaryDirectory(prefix="graincosim-export-") as tmp:
        folder = Path(tmp) / "resources"
        folder.mkdir()
        load_scenario(export_scenario(s, folder, renderer))       # as the FMU will load it
        script = Path(tmp) / f"{ident}.py"
        script.write_text(template.read_text().replace(f"class {TEMPLATE_CLASS}(", f"class {ident}(", 1))
        built = Path(builder.build_FMU(script, dest=Path(tmp) / "built", project_files=list(folder.iterdir()),
                                       canHandleVariableCommunicationStepSize=False))
        _model_structure(built, fmi)
        write_atomically(built, out)
    return out


def _model_structure(fmu: Path, fmi: str) -> None:
    """Complete the model structure pythonfmu / pythonfmu3 write: the outputs have no direct feedthrough (an
    output after ``doStep(t, h)`` depends on the inputs held over the step, not on inputs set at t + h), so each
    ``Output`` / ``Unknown`` gets ``dependencies=""`` and a master sees no algebraic loop through the world; FMI
    2.0 also lists every output among the ``InitialUnknowns`` (calculated at initialisation, frame 0), which
    pythonfmu leaves out."""
    with zipfile.ZipFile(fmu) as zf:
        items = [(i, zf.read(i.filename)) for i in zf.infolist()]
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as zf:
        for item, data in items:
            if item.filename == "modelDescription.xml":
                data = _edit_structure(data, fmi)
            zf.writestr(item, data)


def _edit_structure(xml: bytes, fmi: str) -> bytes:
    root = ElementTree.fromstring(xml)
    structure = root.find("ModelStructure")
    if fmi == "3":
        for out in structure.iterfind("Output"):
            out.set("dependencies", "")
    else:
        outputs = structure.find("Outputs")
        if outputs is not None:
            unknowns = ElementTree.Element("InitialUnknowns")
            for u in outputs.iterfind("Unknown"):
                ElementTree.SubElement(unknowns, "Unknown", index=u.get("index"))
                u.set("dependencies", "")
            structure.insert(list(structure).index(outputs) + 1, unknowns)
    return ElementTree.tostring(root, encoding="UTF-8", xml_declaration=True)


def export_command(args, s: Scenario) -> int:
    """``launch.py export-fmu``: build the FMU (``--out``, ``--fmi``, ``--overwrite``, ``--parents``; the renderer
    ``--renderer``, mock unless given), print the file written; exit 2 with the reason for what cannot be exported
    or a destination that cannot take it, 1 when writing it fails (nothing truncated is left)."""
    try:
        path = export_fmu(s, args.out, args.fmi, args.renderer or "mock", overwrite=args.overwrite,
                          parents=args.parents)
    except (ValueError, BuilderMissing) as e:
        sys.stderr.write(f"export-fmu: {e}\n")
        return 2
    except (OSError, OutputError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else e
        sys.stderr.write(f"export-fmu: --out {shown(args.out)}: cannot write the FMU: {why}; nothing was written\n")
        return 1
    sys.stdout.write(f"wrote {shown(path)}: FMI {args.fmi}.0 co-simulation, one doStep per "
                     f"{s.timing.sensor_period_s:g} s sensor frame, {s.controller.sections} sections (docs/fmu.md)\n")
    return 0
