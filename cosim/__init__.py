"""graincosim: perception-in-the-loop grain offloading co-simulation (README.md).

``from cosim import Simulation, run`` is the Python API (cosim.api, docs/api.md). It is imported on first use
(PEP 562 ``__getattr__``) so that ``import cosim.<module>`` in a run's child processes does not import the API
and what it pulls in (pydantic validation of inputs, the recorder, the report): children start faster.
"""
from __future__ import annotations

__all__ = ["Simulation", "SimulationResult", "run"]


def __getattr__(name: str):
    if name in __all__:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'cosim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
