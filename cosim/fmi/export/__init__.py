"""graincosim's world exported as an FMU for a foreign master (``launch.py export-fmu``; docs/fmu.md, "Export").

* :mod:`.world`: the world inside the FMU (:class:`~.world.WorldHost`): the grain fill model, scene, sensors and
  perception of one scenario over the in-process transport, one frame per ``doStep``; its variables;
* :mod:`.build`: the scenario the FMU carries and the FMU built from it (pythonfmu for FMI 2.0, pythonfmu3 for
  FMI 3.0);
* ``fmu2.py`` / ``fmu3.py``: the FMU's model class (copied into the FMU, not imported here).
"""
from .build import export_fmu, export_scenario
from .world import StepRefused, WorldHost

__all__ = ["export_fmu", "export_scenario", "StepRefused", "WorldHost"]
