"""docs/paper.md names only what exists: every dotted name of a first-party package in it imports (the longest
importable module, then attributes by getattr), and every ``tests/<file>.py::<test>`` names a test function of
that file; each equation 1-7 has a row."""
from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "paper.md"
PACKAGES = ("cosim", "shm_schema", "dynamics_proc", "renderer_proc", "perception_proc")
DOTTED = re.compile(r"`((?:" + "|".join(PACKAGES) + r")(?:\.\w+)*)`")
TEST_REF = re.compile(r"`(tests/\w+\.py)::(\w+)`")


def resolve(dotted: str):
    """The object a dotted name denotes: the longest importable module prefix, then attributes."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError as e:
            if e.name is not None and not ".".join(parts[:k]).startswith(e.name):
                raise                                            # a dependency missing, not the name
            continue
        for attr in parts[k:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(dotted)


def test_every_dotted_name_resolves():
    names = sorted(set(DOTTED.findall(PAGE.read_text(encoding="utf-8"))))
    assert len(names) >= 30
    bad = []
    for name in names:
        try:
            resolve(name)
        except (ImportError, AttributeError) as e:
            bad.append(f"{name}: {type(e).__name__}: {e}")
    assert not bad, "docs/paper.md names what does not exist:\n" + "\n".join(bad)


def test_every_test_it_names_exists():
    refs = sorted(set(TEST_REF.findall(PAGE.read_text(encoding="utf-8"))))
    assert len(refs) >= 20
    missing = []
    for file, name in refs:
        path = ROOT / file
        defined = ({n.name for n in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
                    if isinstance(n, ast.FunctionDef)} if path.exists() else set())
        if name not in defined:
            missing.append(f"{file}::{name}")
    assert not missing, "docs/paper.md names tests that do not exist:\n" + "\n".join(missing)


@pytest.mark.parametrize("eq", ["Eqs 1-2", "Eq 3", "Eqs 4-5", "Eq 6", "Eq 7"])
def test_each_equation_has_a_row(eq):
    assert re.search(rf"^\| {eq}\b", PAGE.read_text(encoding="utf-8"), re.M)


def test_resolve_fails_on_a_missing_name():
    with pytest.raises(AttributeError):
        resolve("perception_proc.lidar.codec.no_such_function")
    with pytest.raises(ModuleNotFoundError):
        resolve("perception_proc_missing.codec")
