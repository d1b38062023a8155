"""Arms of an A/B: source trees (``--tree NAME=PATH``) and settings (``--variant NAME=PATH=VALUE``), and one sample
of a case for one arm, taken in a fresh process that imports the arm's tree.

The measuring code is always the harness's (``bench/cases`` of the checkout that runs ``bench/run.py``); what it
measures is the arm's tree: the worker process runs with the tree as its working directory and first on
``PYTHONPATH``, so ``import cosim`` (and ``launch.py``) come from the tree. Every arm is measured the same way, in
a worker of its own, so that no arm inherits another's imports, GL context or heap. Like a run's processes, the
worker starts with numpy's BLAS, OpenMP, MKL and OpenCV pools single-threaded unless the caller's environment sizes
them (``cosim.runtime.threadpools``): an idle pool thread spins after each small product, and its CPU would be
counted in a figure that a run does not pay."""
from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from .registry import Case, Context, OptionError, get

__all__ = ["ROOT", "Arm", "SampleFailed", "parse_arms", "sample", "shown_path", "worker_env", "worker_main"]

#: the checkout whose bench/ is running
ROOT = Path(__file__).resolve().parents[2]
#: the worker's result line on its standard output
_MARK = "BENCH-SAMPLE "


class SampleFailed(RuntimeError):
    """A worker that ended without a sample (its traceback went to standard error)."""


def shown_path(path: Path | str) -> str:
    """``path`` as results show it, without the machine's absolute paths: relative to this checkout (``.`` for the
    checkout itself) or to the working directory where it lies in either, else its last folder's name."""
    path = Path(path).resolve()
    for base in (ROOT, Path.cwd().resolve()):
        if path == base or base in path.parents:
            return str(path.relative_to(base)) or "."
    return path.name


@dataclass(frozen=True)
class Arm:
    """One side of an A/B: ``label``, the source ``tree`` and the scenario ``settings`` (``PATH=VALUE``)."""

    label: str
    tree: Path = ROOT
    settings: tuple[str, ...] = ()


def parse_arms(trees: Sequence[str] = (), variants: Sequence[str] = ()) -> list[Arm]:
    """Arms from ``NAME=PATH`` trees and ``NAME=PATH=VALUE`` variants (this tree with one more setting; a name
    given again adds its setting to that arm); this tree alone (``this``) when neither is given."""
    arms: list[Arm] = []
    for t in trees:
        label, sep, path = t.partition("=")
        if not sep or not label or not path:
            raise OptionError(f"--tree {t!r}: expected NAME=PATH")
        tree = Path(path).expanduser().resolve()
        if not (tree / "launch.py").exists():
            raise OptionError(f"--tree {t!r}: {tree} is not a source tree of this project (no launch.py)")
        arms.append(Arm(label, tree))
    settings: dict[str, list[str]] = {}
    for v in variants:
        label, sep, setting = v.partition("=")
        if not sep or "=" not in setting:
            raise OptionError(f"--variant {v!r}: expected NAME=PATH=VALUE")
        settings.setdefault(label, []).append(setting)
    arms += [Arm(label, ROOT, tuple(s)) for label, s in settings.items()]
    labels = [a.label for a in arms]
    if len(set(labels)) != len(labels):
        raise OptionError(f"arm names given twice: {labels}")
    return arms or [Arm("this")]


def _context(case: Case, arm: Arm, opts: dict, quick: bool, round_index: int, settings: Sequence[str]) -> Context:
    return Context(arm.tree, (*settings, *arm.settings), opts, quick, round_index, arm.label, Path.cwd())


def worker_env(tree: Path, environ: dict | None = None) -> dict:
    """The environment of a worker measuring ``tree``: ``environ`` (default this process's) with the tree first on
    ``PYTHONPATH`` and every unset numerical pool single-threaded (the module docstring)."""
    from cosim.runtime.threadpools import POOL_VARIABLES  # this checkout's, on sys.path from run.py's main

    env = dict(os.environ if environ is None else environ, PYTHONPATH=str(tree))
    for name in POOL_VARIABLES:
        env.setdefault(name, "1")
    return env


def sample(case: Case, arm: Arm, opts: dict, quick: bool, round_index: int, settings: Sequence[str] = (),
           in_process: bool = False) -> dict:
    """One sample of ``case`` for ``arm``: in this process where ``in_process`` (tests, debugging), else in a
    worker process of the arm's tree."""
    if (arm.settings or settings) and not case.settings:
        raise OptionError(f"case {case.name} runs no scenario: --set and --variant do not apply to it")
    if in_process:
        return case.measure(_context(case, arm, opts, quick, round_index, settings))
    payload = json.dumps({"case": case.name, "tree": str(arm.tree), "settings": [*settings, *arm.settings],
                          "opts": opts, "quick": quick, "round": round_index, "arm": arm.label,
                          "cwd": str(Path.cwd())})
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "run.py"), "--worker", payload], cwd=arm.tree,
                          env=worker_env(arm.tree), stdout=subprocess.PIPE, text=True)
    lines = [line for line in proc.stdout.splitlines() if line.startswith(_MARK)]
    if proc.returncode != 0 or not lines:
        raise SampleFailed(f"case {case.name}, arm {arm.label} ({arm.tree}), round {round_index + 1}: the worker "
                           f"failed (exit {proc.returncode}; its traceback is above)")
    return json.loads(lines[-1][len(_MARK):])


def worker_main(payload: str) -> int:
    """The worker's side of :func:`sample`: measure and print the sample as one JSON line (what the case prints
    goes to standard error)."""
    p = json.loads(payload)
    case = get(p["case"])
    ctx = Context(Path(p["tree"]), tuple(p["settings"]), p["opts"], p["quick"], p["round"], p["arm"], Path(p["cwd"]))
    with contextlib.redirect_stdout(sys.stderr):
        res = case.measure(ctx)
    sys.stdout.write(_MARK + json.dumps(res) + "\n")
    sys.stdout.flush()
    return 0
