"""Build the example tractor-cart FMUs into this folder: TractorCart.fmu (FMI 2.0 co-simulation, from TractorCart.py
with pythonfmu) and, where pythonfmu3 is installed, TractorCart3.fmu (FMI 3.0, from TractorCart3.py). Both wrap
the equations of tractor_cart_model.py, which each FMU carries as a project file.

    python examples/fmu_vehicle/build.py            # then: python launch.py run examples/fmu_vehicle/scenario.yaml
"""
import importlib.util
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
MODEL = HERE / "tractor_cart_model.py"


def build(dest: Path = HERE) -> Path:
    """Build TractorCart.fmu (FMI 2.0) into ``dest`` and return its path."""
    try:
        from pythonfmu import FmuBuilder
    except ImportError:
        sys.exit("building the example FMU needs pythonfmu: pip install pythonfmu")
    return Path(FmuBuilder.build_FMU(HERE / "TractorCart.py", dest=dest, project_files=[MODEL]))


def build3(dest: Path = HERE) -> Path:
    """Build TractorCart3.fmu (FMI 3.0) into ``dest`` and return its path."""
    from pythonfmu3 import FmuBuilder

    return Path(FmuBuilder.build_FMU(HERE / "TractorCart3.py", dest=dest, project_files=[MODEL]))


if __name__ == "__main__":
    print(build())
    if importlib.util.find_spec("pythonfmu3") is not None:
        print(build3())
    else:
        print("TractorCart3.fmu not built: FMI 3.0 needs pythonfmu3 (pip install pythonfmu3)")
