"""One resolver for every plug-in point: a scenario names a plug-in, this finds, imports and checks it.

A reference (``ref``) is one of

* a **short name**: a built-in (the table :data:`BUILTINS`, which mirrors the entry points this package declares
  in pyproject.toml, so that an uninstalled checkout works the same) or a name registered by an installed
  distribution under the group's entry point group (:data:`ENTRY_POINT_GROUPS`, e.g.
  ``[project.entry-points."graincosim.strategies"] middle_out = "mypkg.fill:middle_out"``);
* an **import path** ``package.module:name`` (dotted attributes allowed after the colon), imported from the
  scenario file's folder (``base_dir``, searched first) or sys.path.

Built-ins win over entry points of the same name (an installed package cannot replace a built-in silently).
Groups (plug-in points; the scenario key each one is named by):

========================  =========================  ==========================================
group                     scenario key               protocol
========================  =========================  ==========================================
``strategies``            controller.strategy        dynamics_proc.control.strategies (a function)
``controllers``           controller.model           dynamics_proc.control.protocol (a factory)
``perception``            perception.algorithm       perception_proc.protocol (a function)
``perception.rim``        perception.stages.rim      perception_proc.protocol
``perception.heightmap``  perception.stages.heightmap  perception_proc.protocol
``perception.impact``     perception.stages.impact   perception_proc.protocol
========================  =========================  ==========================================

Options: the scenario's ``<key>_options`` mapping beside a reference holds keyword arguments; :func:`load_plugin`
checks them against the plug-in's signature (after the protocol's positional arguments) and binds them
(``functools.partial``), so the caller calls the protocol as usual.

Trust: loading a plug-in runs its module's code. ``allow_external=False`` refuses anything that is not built in.
"""
from __future__ import annotations

import functools
import importlib
import importlib.metadata as metadata
import inspect
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

__all__ = ["BUILTINS", "ENTRY_POINT_GROUPS", "ARITY", "PluginError", "PluginOptionsError", "PluginInfo",
           "load_plugin", "resolve_plugin", "check_options", "is_import_path", "distribution_of", "external_module"]

#: plug-in group -> built-in short name -> import path (the same as the package's entry points)
BUILTINS: dict[str, dict[str, str]] = {
    "strategies": {
        "front_to_back": "dynamics_proc.control.strategies:front_to_back",
        "back_to_front": "dynamics_proc.control.strategies:back_to_front",
        "lowest_first": "dynamics_proc.control.strategies:lowest_first",
    },
    "controllers": {"section_fill": "dynamics_proc.control.controller:SectionFillController"},
    "perception": {"staged": "perception_proc.staged:staged"},
    "perception.rim": {"builtin": "perception_proc.staged:rim_stage"},
    "perception.heightmap": {"builtin": "perception_proc.staged:heightmap_stage"},
    "perception.impact": {"builtin": "perception_proc.staged:impact_stage"},
}

#: plug-in group -> entry point group
ENTRY_POINT_GROUPS: dict[str, str] = {g: "graincosim." + g for g in BUILTINS}

#: plug-in group -> positional arguments its callable must accept (the protocol's signature)
ARITY: dict[str, tuple[str, ...]] = {
    "strategies": ("full", "height", "current"),
    "controllers": ("params", "scenario"),
    "perception": ("ctx", "inp"),
    "perception.rim": ("ctx", "inp"),
    "perception.heightmap": ("ctx", "inp", "cart"),
    "perception.impact": ("ctx", "inp", "cart", "heightmap"),
}


class PluginError(ValueError):
    """A plug-in reference cannot be used: unknown name, import failure, missing attribute, not callable, wrong
    signature, or refused (``allow_external=False``). The message names the reference."""


class PluginOptionsError(PluginError):
    """A plug-in's ``*_options`` do not fit its signature; ``names``: the options it does not take."""

    def __init__(self, message: str, names: tuple[str, ...]):
        super().__init__(message)
        self.names = names


@dataclass(frozen=True)
class PluginInfo:
    """A resolved plug-in: ``obj`` the loaded object; ``builtin`` whether it ships with graincosim; ``target``
    the import path it was loaded from; ``file`` its module's file ('' unknown). Which distribution provides it:
    :func:`distribution_of` (a scan of the installed packages, so only on demand)."""

    group: str
    ref: str
    target: str
    builtin: bool
    file: str
    obj: object


def is_import_path(ref: str) -> bool:
    """Whether ``ref`` is an import path ``module:name`` rather than a short name."""
    return ":" in ref


def _entry_point(group: str, name: str):
    eps = metadata.entry_points(group=ENTRY_POINT_GROUPS[group])
    found = [ep for ep in eps if ep.name == name]
    return found[0] if found else None


def external_module(group: str, ref: str) -> str | None:
    """The module plug-in ``ref`` of ``group`` would import when it is not built in (its import path's module,
    or its entry point's), None for a built-in or a name that resolves to nothing; nothing is imported."""
    if group not in BUILTINS or ref in BUILTINS[group]:
        return None
    if is_import_path(ref):
        return ref.partition(":")[0] or None
    ep = _entry_point(group, ref)
    return ep.value.partition(":")[0] if ep is not None else None


def _import(target: str, ref: str, base_dir: Path | None):
    module_name, _, attr = target.partition(":")
    if not module_name or not attr:
        raise PluginError(f"plug-in {ref!r}: an import path is 'package.module:name'")
    if base_dir is not None:
        folder = str(Path(base_dir).resolve())
        if folder not in sys.path:
            sys.path.insert(0, folder)      # the scenario's folder, searched first (and by the plug-in's imports)
    try:
        obj = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        if e.name is not None and module_name.startswith(e.name):
            where = f" (looked in {str(base_dir)!r} and on sys.path)" if base_dir is not None else " (on sys.path)"
            raise PluginError(f"plug-in {ref!r}: no module named {e.name!r}{where}") from None
        raise PluginError(f"plug-in {ref!r}: importing {module_name!r} failed: {type(e).__name__}: {e}") from None
    except Exception as e:  # noqa: BLE001 - any error in the user's module is a problem of this reference
        raise PluginError(f"plug-in {ref!r}: importing {module_name!r} failed: {type(e).__name__}: {e}") from None
    except SystemExit as e:  # the child-process probe (cosim.scenario.probe) normally finds it first
        raise PluginError(f"plug-in {ref!r}: importing {module_name!r} ends the interpreter (sys.exit({e.code!r}) "
                          "at import time)") from None
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise PluginError(f"plug-in {ref!r}: module {module_name!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    return obj


def _check_signature(group: str, ref: str, obj: object) -> None:
    if not callable(obj):
        raise PluginError(f"plug-in {ref!r} is not callable (a {type(obj).__name__!r} object); the {group} protocol takes "
                          f"({', '.join(ARITY[group])})")
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return                          # a builtin or extension callable without a signature: trust it
    try:
        sig.bind(*ARITY[group])
    except TypeError as e:
        raise PluginError(f"plug-in {ref!r} has signature {sig}, which cannot be called as "
                          f"({', '.join(ARITY[group])}): {e}") from None


def check_options(group: str, ref: str, obj: object, options: Mapping[str, object]) -> None:
    """:class:`PluginError` unless ``obj`` can be called with the protocol's arguments and ``options`` as keywords."""
    if not options:
        return
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return                          # no signature to check against: trust it
    try:
        sig.bind(*ARITY[group], **options)
    except TypeError as e:
        params = sig.parameters
        takes_any = any(p.kind is p.VAR_KEYWORD for p in params.values())
        named = [p for p in list(params)[len(ARITY[group]):]
                 if params[p].kind in (params[p].POSITIONAL_OR_KEYWORD, params[p].KEYWORD_ONLY)]
        bad = tuple(k for k in options if not takes_any and k not in named) or tuple(options)
        raise PluginOptionsError(f"plug-in {ref!r} takes no option {', '.join(repr(k) for k in bad)}: its "
                                 f"signature is {sig} ({e}); options: "
                                 f"{', '.join(named) if named else 'none'}", bad) from None


def _module_file(obj: object) -> str:
    module = sys.modules.get(getattr(obj, "__module__", "") or "")
    return str(getattr(module, "__file__", "") or "")


#: this project's distribution and the top-level packages it installs (its built-in plug-ins live there)
OWN_DISTRIBUTION = "graincosim"
OWN_PACKAGES = ("cosim", "dynamics_proc", "perception_proc", "renderer_proc", "shm_schema")


@functools.lru_cache(maxsize=4)
def _packages_distributions(path: tuple[str, ...]) -> Mapping[str, list[str]]:
    """Top-level package -> distributions installed on ``path`` (``sys.path``), read once per path: the scan
    parses every installed package's metadata (0.3 s quiet, seconds on a busy machine), and validate asks it once
    per plug-in."""
    return metadata.packages_distributions()


def distribution_of(info: PluginInfo) -> tuple[str, str]:
    """(name, version) of the installed distribution providing the plug-in's top-level package, ('', '') when
    none does (a loose module, an uninstalled checkout). This project's own packages are named without a scan;
    another's scans the installed packages once per process."""
    top = (getattr(info.obj, "__module__", "") or info.target).split(".")[0].split(":")[0]
    candidates = [OWN_DISTRIBUTION] if top in OWN_PACKAGES else _packages_distributions(tuple(sys.path)).get(top, [])
    for dist in candidates:
        try:
            return dist, metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    return "", ""


def resolve_plugin(group: str, ref: str, *, base_dir: Path | None = None, allow_external: bool = True,
                   check: bool = True) -> PluginInfo:
    """Find, import and (``check``) signature-check plug-in ``ref`` of ``group``; :class:`PluginError` otherwise."""
    if group not in BUILTINS:
        raise ValueError(f"unknown plug-in group {group!r}; groups: {', '.join(BUILTINS)}")
    builtin = BUILTINS[group].get(ref)
    if builtin is not None:
        target = builtin
    elif is_import_path(ref):
        target = ref
    else:
        ep = _entry_point(group, ref)
        if ep is None:
            names = sorted(set(BUILTINS[group]) | {e.name for e in metadata.entry_points(
                group=ENTRY_POINT_GROUPS[group])})
            raise PluginError(f"unknown {group} plug-in {ref!r}: not built in, not registered under entry point "
                              f"group {ENTRY_POINT_GROUPS[group]!r} (known: {', '.join(names)}), and not an "
                              "import path 'package.module:name'")
        target = ep.value
    if builtin is None and not allow_external:
        raise PluginError(f"plug-in {ref!r} is not built in and plug-ins are disabled (--no-plugins / "
                          "allow_plugins=False): a scenario that names a plug-in runs its code")
    obj = _import(target, ref, base_dir if builtin is None else None)
    if check:
        _check_signature(group, ref, obj)
    return PluginInfo(group, ref, target, builtin is not None, _module_file(obj), obj)


def load_plugin(group: str, ref: str, *, base_dir: Path | None = None, allow_external: bool = True,
                options: Mapping[str, object] | None = None) -> object:
    """The object plug-in ``ref`` of ``group`` names, imported and signature-checked (see the module docstring),
    with ``options`` (the scenario's ``*_options``) bound as keyword arguments; :class:`PluginError` naming
    ``ref`` otherwise."""
    obj = resolve_plugin(group, ref, base_dir=base_dir, allow_external=allow_external).obj
    if not options:
        return obj
    check_options(group, ref, obj, options)
    return functools.partial(obj, **options)
