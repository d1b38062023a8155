"""Scenario files: the packaged scenarios by name, and reading a file within the size limit."""
from __future__ import annotations

import difflib
import os
from pathlib import Path

import yaml

from cosim.errors import Problem, ScenarioError

__all__ = ["SCENARIO_DIR", "MAX_SCENARIO_BYTES", "packaged_scenarios", "resolve_scenario_arg", "describe_packaged",
           "read_scenario", "too_large"]

#: directory of the scenarios shipped with the package
SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"
#: largest scenario file (or text) read, bytes: a scenario is a few KiB; a larger one is refused before parsing
MAX_SCENARIO_BYTES = 1 << 20


def packaged_scenarios() -> dict[str, Path]:
    """Scenarios shipped with the package, name (file stem) -> path."""
    return {p.stem: p for p in sorted(SCENARIO_DIR.glob("*.yaml"))}


def _unknown(arg: str) -> str:
    packaged = packaged_scenarios()
    close = difflib.get_close_matches(arg, list(packaged), n=1, cutoff=0.6)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    return (f"no such scenario file or packaged scenario (packaged: {', '.join(packaged) or 'none'}; "
            f"`launch.py list` describes them){hint}")


def resolve_scenario_arg(arg: str | os.PathLike) -> Path:
    """A scenario argument as a file: an existing file path, or the name of a packaged scenario ("default")."""
    path = Path(arg)
    if path.is_file():
        return path
    packaged = packaged_scenarios()
    if str(arg) in packaged:
        return packaged[str(arg)]
    raise ScenarioError([Problem(str(arg), 0, 0, "", _unknown(str(arg)))])


def describe_packaged() -> dict[str, str]:
    """Packaged scenario name -> its ``description`` (first sentence, whitespace collapsed; "" when none)."""
    out = {}
    for name, path in packaged_scenarios().items():
        doc = yaml.safe_load(path.read_text()) or {}
        text = " ".join(str(doc.get("description") or "").split())
        out[name] = text.split(". ")[0].rstrip(".") + "." if text else ""
    return out


def too_large(filename: str, size: int) -> Problem:
    return Problem(filename, 1, 1, "", f"the scenario is {size / 2**20:.1f} MiB; scenarios are limited to "
                   f"{MAX_SCENARIO_BYTES / 2**20:g} MiB (put large tables in files, e.g. sensor.pattern.csv_file)")


def read_scenario(path: str | os.PathLike) -> str:
    """The text of scenario file ``path``; ScenarioError when it is unreadable, not UTF-8 or over the limit."""
    try:
        size = os.stat(path).st_size
        if size > MAX_SCENARIO_BYTES:
            raise ScenarioError([too_large(str(path), size)])
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError([Problem(str(path), 0, 0, "", f"cannot read scenario file: {e}")]) from None
