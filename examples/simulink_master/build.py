"""Export scenario.yaml's world, sensors and perception as GrainWorld.fmu (FMI 2.0 co-simulation) into this folder,
as ``python launch.py export-fmu examples/simulink_master/scenario.yaml --out examples/simulink_master/GrainWorld.fmu``
does.

    python examples/simulink_master/build.py        # then: python examples/simulink_master/master.py
"""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def build(dest: Path = HERE) -> Path:
    """Export the FMU into ``dest`` and return its path."""
    from cosim.cli import main

    out = dest / "GrainWorld.fmu"
    code = main(["export-fmu", str(HERE / "scenario.yaml"), "--out", str(out), "--overwrite"])
    if code:
        sys.exit(code)
    return out


if __name__ == "__main__":
    build()
