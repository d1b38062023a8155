"""What a scenario would load, checked when it is validated: every plug-in (and, through :data:`CHECKS`, every other
kind of external model, such as FMUs) it names.

A scenario that names a plug-in runs that code (in the launcher while validating, and in the run's processes).
:func:`inspect_scenario` imports and checks each one and returns the inventory ``validate`` prints; with
``allow_plugins=False`` anything not built in is refused instead (``--no-plugins``, for scenarios from
untrusted sources). Problems come back as :class:`Issue` (scenario key + message); the loader turns them into
``file:line:col: key: message`` errors.

Hook: :data:`CHECKS` is the tuple of check functions the loader runs after the plug-in checks, each
``check(scenario, *, allow_plugins: bool, versions: bool) -> (list[Loaded], list[Issue])`` (``versions``: also
find each item's distribution version, which can be slow; the loader passes False, ``validate`` True); another
kind of external model adds its function there.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from cosim.fmi import check as fmi_check

from .config import FMU_REF, Scenario
from .plugins import PluginError, PluginOptionsError, check_options, distribution_of, external_module, resolve_plugin
from .probe import probe_imports

__all__ = ["Loaded", "Issue", "Check", "PLUGIN_POINTS", "options_key", "plugin_points", "check_plugin_refs",
           "check_plugins", "check_fmus", "CHECKS", "inspect_scenario", "format_inventory"]


@dataclass(frozen=True)
class Loaded:
    """One thing a scenario would load: ``kind`` ('plug-in', 'fmu', ...), ``key`` the scenario key naming it,
    ``ref`` as named there, ``builtin`` whether it ships with graincosim, ``file`` the file that would be
    loaded, ``version`` of its distribution ('' unknown), ``target`` what the reference resolved to, ``options``
    the keyword options it is called with (``json``-like text, '' none)."""

    kind: str
    key: str
    ref: str
    builtin: bool
    file: str
    version: str
    target: str = ""
    options: str = ""


@dataclass(frozen=True)
class Issue:
    """A problem found at scenario key ``loc`` (a tuple of keys)."""

    loc: tuple[str, ...]
    message: str


Check = Callable[..., "tuple[list[Loaded], list[Issue]]"]


#: every plug-in point: (scenario key, plug-in group of cosim.scenario.plugins)
PLUGIN_POINTS: tuple[tuple[tuple[str, ...], str], ...] = (
    (("controller", "strategy"), "strategies"),
    (("controller", "model"), "controllers"),
    (("perception", "algorithm"), "perception"),
    (("perception", "stages", "rim"), "perception.rim"),
    (("perception", "stages", "heightmap"), "perception.heightmap"),
    (("perception", "stages", "impact"), "perception.impact"),
)


def options_key(loc: tuple[str, ...]) -> tuple[str, ...]:
    """The scenario key of the options beside the plug-in reference at ``loc`` (``controller.strategy_options``)."""
    return loc[:-1] + (loc[-1] + "_options",)


def plugin_points(s: Scenario) -> list[tuple[tuple[str, ...], str, str, dict]]:
    """(scenario key, plug-in group, reference, options) of every plug-in point of ``s``."""
    out = []
    for loc, group in PLUGIN_POINTS:
        node, options = s, s
        for part in loc:
            node = getattr(node, part)
        for part in options_key(loc):
            options = getattr(options, part)
        out.append((loc, group, node, dict(options)))
    return out


def check_plugin_refs(refs: list[tuple[tuple[str, ...], str, str, dict]], plugin_dir: str, *,
                      allow_plugins: bool = True, versions: bool = False) -> tuple[list[Loaded], list[Issue]]:
    """Import and signature-check each (scenario key, group, reference, options), looked for in ``plugin_dir``
    first ('' none); the options are checked against the plug-in's signature at their own key. Modules not yet
    imported are imported in a child process first (cosim.scenario.probe): one that ends, kills or hangs the
    interpreter is refused at its key instead of ending this process. The loader runs
    this on the raw values too, so that a bad plug-in is reported together with the scenario's other problems."""
    base = Path(plugin_dir) if plugin_dir else None
    loaded, issues = [], []
    modules = {} if not allow_plugins else {loc: external_module(group, ref) for loc, group, ref, _ in refs}
    path = ([str(base.resolve())] if base is not None else []) + sys.path
    refused = probe_imports([m for m in modules.values() if m], path)
    for loc, group, ref, options in refs:
        if modules.get(loc) in refused:
            issues.append(Issue(loc, f"plug-in {ref!r}: {refused[modules[loc]]}"))
            continue
        if ref == FMU_REF and loc[0] == "controller":
            if options:
                issues.append(Issue(options_key(loc), "options are for Python plug-ins; an FMU takes its "
                                                      "parameters in controller.fmu.parameters"))
            continue                        # names controller.fmu: check_fmus
        try:
            info = resolve_plugin(group, ref, base_dir=base, allow_external=allow_plugins)
            check_options(group, ref, info.obj, options)
        except PluginError as e:
            where = options_key(loc) + e.names[:1] if isinstance(e, PluginOptionsError) else loc
            issues.append(Issue(where, str(e)))
            continue
        dist, version = distribution_of(info) if versions else ("", "")
        loaded.append(Loaded("plug-in", ".".join(loc), ref, info.builtin, info.file,
                             f"{dist} {version}" if dist else "", info.target,
                             ", ".join(f"{k}={json.dumps(v)}" for k, v in options.items())))
    return loaded, issues


def check_plugins(s: Scenario, *, allow_plugins: bool = True,
                  versions: bool = False) -> tuple[list[Loaded], list[Issue]]:
    """Every plug-in ``s`` names, checked (:func:`check_plugin_refs`)."""
    return check_plugin_refs(plugin_points(s), s.plugin_dir, allow_plugins=allow_plugins, versions=versions)


def check_fmus(s: Scenario, *, allow_plugins: bool = True,
               versions: bool = False) -> tuple[list[Loaded], list[Issue]]:
    """Describe and check every FMU ``s`` names (cosim.fmi.check; refused with ``allow_plugins=False``); an FMU's
    version is its FMI version, model and GUID, read from the file either way."""
    rows, problems = fmi_check.check_fmus(s, allow_plugins=allow_plugins)
    return ([Loaded("fmu", key, ref, False, file, version, target) for key, ref, file, version, target in rows],
            [Issue(loc, message) for loc, message in problems])


#: the checks of other external model kinds (e.g. FMUs), run on every valid scenario after the plug-ins
CHECKS: tuple[Check, ...] = (check_fmus,)


def inspect_scenario(s: Scenario, *, allow_plugins: bool = True,
                     versions: bool = False) -> tuple[list[Loaded], list[Issue]]:
    """:func:`check_plugins` and every :data:`CHECKS` function on ``s``: (what it would load, the problems)."""
    loaded, issues = check_plugins(s, allow_plugins=allow_plugins, versions=versions)
    for check in CHECKS:
        got, bad = check(s, allow_plugins=allow_plugins, versions=versions)
        loaded += got
        issues += bad
    return loaded, issues


def format_inventory(loaded: list[Loaded]) -> str:
    """The inventory as text lines, one per item: kind, key, ref (with its options), built-in or external, file,
    version."""
    lines = []
    for item in loaded:
        origin = "built in" if item.builtin else "EXTERNAL (runs its code)"
        options = f" with {item.options}" if item.options else ""
        lines.append(f"  {item.kind} {item.key} = {item.ref}{options}: {origin}; file {item.file or '?'}; "
                     f"version {item.version or 'unknown'}")
    return "\n".join(lines)
