"""Scenario-time checks and listing of the FMUs a scenario names (for the loader and ``validate``).

:data:`SITES` lists where an FMU may appear and the role it plays there. :func:`fmu_problems` checks every FMU
in a loaded document (the file is an FMU graincosim can step, the mapping fits the role) and returns the
problems with their locations, for the loader to mark with file:line:col; it runs on the plain YAML data, so
an FMU is checked even when unrelated parts of the scenario are invalid. :func:`list_fmus` describes the FMUs a
validated scenario would load.
"""
from __future__ import annotations

import json
from pathlib import Path

from pydantic import ValidationError

from cosim.scenario.config import Controller, Fmu, Scenario

from .describe import FmiUnavailable, FmuDescription, FmuInvalid, describe
from .roles import STRATEGY, VEHICLE, Role, mapping_problems

__all__ = ["SITES", "fmu_problems", "list_fmus"]

#: (location of the FMU record in the scenario, the role it plays there)
SITES: tuple[tuple[tuple[str, ...], Role], ...] = (
    (("vehicles", "tractor_cart", "fmu"), VEHICLE),
    (("controller", "fmu"), STRATEGY),
)


def _get(data, loc: tuple[str, ...]):
    for part in loc:
        if not isinstance(data, dict) or part not in data:
            return None
        data = data[part]
    return data


def _sections(data) -> int:
    n = _get(data, ("controller", "sections"))
    ok = isinstance(n, int) and not isinstance(n, bool) and n >= 1
    return n if ok else Controller.model_fields["sections"].default


def fmu_problems(data) -> list[tuple[tuple, str, bool]]:
    """Problems of every FMU in the scenario data (paths already resolved): (location, message, whether to
    report it at the key). A record that does not validate, or whose file is missing, is left to the
    loader's other checks."""
    out: list[tuple[tuple, str, bool]] = []
    for site, role in SITES:
        raw = _get(data, site)
        if not isinstance(raw, dict):
            continue
        try:
            fmu = Fmu.model_validate_json(json.dumps(raw))
        except ValidationError:
            continue
        if not Path(fmu.path).is_file():
            continue
        try:
            desc = describe(fmu.path)
        except (FmiUnavailable, FmuInvalid, OSError) as e:
            what = str(e) if isinstance(e, FmiUnavailable) else f"{fmu.path} {e}"
            out.append((site + ("path",), what, False))
            continue
        out += [(site + loc, msg, at_key) for loc, msg, at_key in mapping_problems(fmu, desc, role, _sections(data))]
    return out


def list_fmus(scenario: Scenario) -> list[tuple[str, FmuDescription]]:
    """The FMUs ``scenario`` would load, as (dotted location, description); for ``validate``."""
    out = []
    for site, _role in SITES:
        fmu = scenario
        for part in site:
            fmu = getattr(fmu, part)
        if fmu is not None:
            out.append((".".join(site), describe(fmu.path)))
    return out
