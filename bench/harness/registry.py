"""The named cases: what each measures (one line), its options with their full and quick values, and the function
that takes one sample.

A case module in ``bench/cases/`` registers its cases with :func:`case`::

    @case("ring_latency", "the lockstep ring's round trip over semaphores", options={"frames": 5000},
          quick={"frames": 300})
    def ring_latency(ctx: Context) -> Sample: ...

The function gets a :class:`Context` (the source tree it measures, the scenario settings of its arm, its options)
and returns one sample (``harness.rounds``). It runs in a fresh process with the tree's code first on
``sys.path`` (``harness.arms``) unless it is told to run in the harness's process.
"""
from __future__ import annotations

import importlib
import pkgutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

__all__ = ["CASES", "Case", "Context", "OptionError", "case", "get", "load_cases", "parse_value"]

#: every registered case by name, in registration order
CASES: dict[str, "Case"] = {}


class OptionError(ValueError):
    """An unknown case, option or value given on the command line."""


@dataclass(frozen=True)
class Context:
    """What one sample of a case is measured with.

    ``tree``: the source tree measured (its ``launch.py`` and packages); ``settings``: ``--set PATH=VALUE`` strings
    for the scenario (the arm's and the command line's); ``opts``: the case's options; ``quick``: a check of the
    case, not a figure; ``round``: the round's index; ``arm``: the arm's label; ``cwd``: where the command was
    given (relative paths among the options are relative to it, :meth:`path`)."""

    tree: Path
    settings: tuple[str, ...] = ()
    opts: Mapping[str, Any] = field(default_factory=dict)
    quick: bool = False
    round: int = 0
    arm: str = "this"
    cwd: Path = field(default_factory=Path.cwd)

    def __getitem__(self, key: str):
        return self.opts[key]

    def path(self, value: str) -> Path:
        """An option's path, relative to where the command was given."""
        return (self.cwd / Path(value).expanduser()).resolve()

    def scenario(self, name: str = "default", extra: Mapping | None = None, settings: Sequence[str] = ()):
        """The packaged (or file) scenario ``name`` with ``extra`` (a nested mapping), then the arm's settings and
        ``settings`` applied, as ``launch.py run NAME --set ...`` would."""
        from cosim.scenario.loader import load_scenario, resolve_scenario_arg

        return load_scenario(resolve_scenario_arg(name), [*settings, *self.settings], extra=dict(extra or {}))

    def launch_args(self) -> list[str]:
        """The arm's settings as ``launch.py`` arguments (``--set PATH=VALUE`` each)."""
        return [x for s in self.settings for x in ("--set", s)]


@dataclass(frozen=True)
class Case:
    """A named measurement. ``options``: name -> full value (the figures); ``quick``: the values ``--quick``
    replaces (a check in seconds); ``rounds``: default interleaved rounds; ``settings``: whether the case runs a
    scenario that ``--set`` / ``--variant`` change; ``compare``: columns whose paired ratios an A/B reports (all
    numeric columns where empty); ``in_process``: the sample needs the harness's process (never a worker)."""

    name: str
    summary: str
    measure: Callable[[Context], dict]
    options: Mapping[str, Any] = field(default_factory=dict)
    quick: Mapping[str, Any] = field(default_factory=dict)
    rounds: int = 1
    settings: bool = False
    compare: tuple[str, ...] = ()
    notes: str = ""

    def resolve(self, quick: bool = False, given: Mapping[str, Any] | None = None) -> dict:
        """The options of a run: full values, the quick ones over them, then ``given`` (unknown names refused)."""
        given = dict(given or {})
        unknown = set(given) - set(self.options)
        if unknown:
            known = ", ".join(f"{k}={v!r}" for k, v in self.options.items()) or "none"
            raise OptionError(f"case {self.name}: unknown option(s) {sorted(unknown)}; its options: {known}")
        return {**self.options, **(self.quick if quick else {}), **given}


def case(name: str, summary: str, *, options: Mapping[str, Any] | None = None, quick: Mapping[str, Any] | None = None,
         rounds: int = 1, settings: bool = False, compare: Sequence[str] = (), notes: str = ""):
    """Register the decorated function as case ``name`` (see :class:`Case`)."""
    if quick and set(quick) - set(options or {}):
        raise ValueError(f"case {name}: quick values for options it does not have: {set(quick) - set(options or {})}")

    def register(fn: Callable[[Context], dict]) -> Callable[[Context], dict]:
        if name in CASES and CASES[name].measure.__module__ != fn.__module__:
            raise ValueError(f"case {name} registered twice ({CASES[name].measure.__module__}, {fn.__module__})")
        CASES[name] = Case(name, summary, fn, dict(options or {}), dict(quick or {}), rounds, settings,
                           tuple(compare), notes or (fn.__doc__ or "").strip())
        return fn
    return register


def load_cases() -> dict[str, Case]:
    """Import every module of ``bench/cases`` (each registers its cases) and return :data:`CASES`."""
    import cases

    for mod in pkgutil.iter_modules(cases.__path__):
        importlib.import_module(f"cases.{mod.name}")
    return CASES


def get(name: str) -> Case:
    if name not in CASES:                        # a script may have imported one case module before
        load_cases()
    if name not in CASES:
        raise OptionError(f"no case named {name!r}; `python bench/run.py --list` lists them")
    return CASES[name]


def parse_value(text: str):
    """A command-line option value: an int, a float, true/false/none, or the string itself."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    if low in ("none", "null"):
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text

