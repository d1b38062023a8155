"""Build SectionFill.fmu (FMI 2.0 co-simulation) from SectionFill.py with pythonfmu, into this folder.

    python examples/fmu_controller/build.py            # then: python launch.py run examples/fmu_controller/scenario.yaml
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
    return Path(FmuBuilder.build_FMU(HERE / "SectionFill.py", dest=dest))


if __name__ == "__main__":
    print(build())
