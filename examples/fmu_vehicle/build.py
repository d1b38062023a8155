"""Build TractorCart.fmu (FMI 2.0 co-simulation) from TractorCart.py with pythonfmu, into this folder.

    python examples/fmu_vehicle/build.py            # then: python launch.py run examples/fmu_vehicle/scenario.yaml
"""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def build(dest: Path = HERE) -> Path:
    """Build the FMU into ``dest`` and return its path."""
    try:
        from pythonfmu import FmuBuilder
    except ImportError:
        sys.exit("building the example FMU needs pythonfmu: pip install pythonfmu")
    return Path(FmuBuilder.build_FMU(HERE / "TractorCart.py", dest=dest))


if __name__ == "__main__":
    print(build())
