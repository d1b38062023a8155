"""A scenario from what a Python caller gives (``cosim.Simulation``): a name, a path or a loaded Scenario, plus the
command line's options (``--renderer``, ``--feedback``, ``--seed``, ``--duration``, ``--set``) as arguments."""
from __future__ import annotations

import os
from typing import Any, Mapping, Sequence

from .config import Scenario
from .loader import dump_resolved, load_scenario, load_scenario_text, resolve_scenario_arg

__all__ = ["load_with_options"]


def load_with_options(scenario: str | os.PathLike | Scenario, *, renderer: str | None = None,
                      feedback: str | None = None, seed: int | None = None, duration: float | None = None,
                      overrides: Mapping[str, Any] | None = None, set_: Sequence[str] = (),
                      allow_plugins: bool = True) -> Scenario:
    """The validated scenario: ``scenario`` (packaged name, YAML path or Scenario) with the options applied as
    ``python launch.py run`` applies them. ``overrides`` maps dotted paths to values; ``set_`` holds ``--set``
    strings ("path=value"). Raises :class:`ScenarioError` (``file:line:col: path: message``)."""
    if isinstance(set_, str):
        set_ = [set_]
    extra = {"renderer": renderer, "feedback": feedback, "seed": seed, "duration_s": duration,
             **dict(overrides or {})}
    extra = {k: v for k, v in extra.items() if v is not None}
    if isinstance(scenario, Scenario):
        if not extra and not set_ and allow_plugins:
            return scenario
        return load_scenario_text(dump_resolved(scenario), f"<scenario {scenario.name}>", list(set_), extra=extra,
                                  allow_plugins=allow_plugins)
    return load_scenario(resolve_scenario_arg(scenario), list(set_), extra=extra, allow_plugins=allow_plugins)
