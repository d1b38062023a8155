"""The layer rules of docs/CONTRACTS.md ("Layers"), held by a scan of every import statement in the first-party
packages (at any depth: module level, inside functions, under ``TYPE_CHECKING``):

* ``cosim`` imports no participant package outside ``cosim/testing/``;
* a participant imports of ``cosim.runtime`` only ``cosim.runtime.participant``;
* participants never import each other;
* the configuration layer (``cosim.scenario.config``) is a leaf: it imports no other first-party module;
* no import cycle among the modules;
* at most :data:`TOP_MODULES_MAX` modules at the top of each participant package;
* every import of a first-party name (in the packages, tests, bench and examples) names a module that exists, or a
  name its package binds (an installed copy of an older tree would otherwise answer a stale name silently).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("cosim", "shm_schema", "dynamics_proc", "renderer_proc", "perception_proc")
PARTICIPANTS = ("dynamics_proc", "renderer_proc", "perception_proc")
#: what cosim may import of a participant: only its test kits
COSIM_TESTING = "cosim.testing"
#: the one module of the runtime a participant imports
RUNTIME, RUNTIME_CONTRACT = "cosim.runtime", "cosim.runtime.participant"
#: the configuration layer, a leaf
CONFIG = "cosim.scenario.config"
#: modules (``*.py``) at the top of a participant package, at most
TOP_MODULES_MAX = 12


def module_name(path: Path, root: Path = ROOT) -> str:
    """Dotted name of the module at ``path`` (a package's ``__init__.py`` is the package)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def first_party_modules(root: Path = ROOT) -> dict[str, Path]:
    """{dotted name: file} of every module of :data:`PACKAGES` under ``root``."""
    return {module_name(p, root): p for pkg in PACKAGES for p in sorted((root / pkg).rglob("*.py"))}


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The first-party module ``name`` is or lies in (``a.b.attr`` -> ``a.b``), None outside them."""
    while name and name not in modules:
        if "." not in name:
            return None
        name = name.rsplit(".", 1)[0]
    return name


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> list[tuple[str, int]]:
    """(first-party module imported, line) for every import statement of module ``name``, at any depth;
    ``from pkg import mod`` counts as importing ``pkg.mod`` where that is a module."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else []))
            for a in node.names:
                full = f"{base}.{a.name}"
                found.append((full if full in modules else base, node.lineno))
    return [(m, line) for target, line in found if (m := _resolve(target, modules)) is not None]


def import_graph(root: Path = ROOT) -> dict[str, list[tuple[str, int]]]:
    """{module: [(module it imports, line)]} over the first-party modules under ``root``."""
    modules = first_party_modules(root)
    return {n: imports_of(n, p, modules) for n, p in modules.items()}


def _package(module: str) -> str:
    return module.split(".")[0]


def layer_violations(graph: dict[str, list[tuple[str, int]]]) -> list[str]:
    """Every import that breaks a layer rule, as ``module:line -> imported (rule)``."""
    bad = []
    for mod, deps in graph.items():
        for dep, line in deps:
            src, dst = _package(mod), _package(dep)
            if src == "cosim" and dst in PARTICIPANTS and not (mod + ".").startswith(COSIM_TESTING + "."):
                bad.append(f"{mod}:{line} -> {dep} (cosim imports no participant outside {COSIM_TESTING})")
            if src in PARTICIPANTS and (dep + ".").startswith(RUNTIME + ".") and dep not in (RUNTIME_CONTRACT,):
                bad.append(f"{mod}:{line} -> {dep} (a participant imports only {RUNTIME_CONTRACT} of the runtime)")
            if src in PARTICIPANTS and dst in PARTICIPANTS and src != dst:
                bad.append(f"{mod}:{line} -> {dep} (participants never import each other)")
            if (mod + ".").startswith(CONFIG + ".") and not (dep + ".").startswith(CONFIG + "."):
                bad.append(f"{mod}:{line} -> {dep} (the configuration layer {CONFIG} imports nothing outside it)")
    return bad


def import_cycles(graph: dict[str, list[tuple[str, int]]]) -> list[list[str]]:
    """The import cycles: every strongly connected set of more than one module (Tarjan, iterative), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(graph[start]))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            v, it = work[-1]
            for w, _ in it:
                if w == v:
                    continue
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(graph[w])))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        cycles.append(sorted(comp))
    return sorted(cycles)


@pytest.fixture(scope="module")
def graph():
    return import_graph()


def test_layers_hold(graph):
    bad = layer_violations(graph)
    assert not bad, "imports that break the layer rules (docs/CONTRACTS.md, Layers):\n" + "\n".join(bad)


def test_no_import_cycle(graph):
    cycles = import_cycles(graph)
    assert not cycles, "import cycles (late and TYPE_CHECKING imports count):\n" + "\n".join(
        " <-> ".join(c) for c in cycles)


@pytest.mark.parametrize("package", PARTICIPANTS)
def test_participant_packages_show_their_blocks(package):
    top = sorted(p.name for p in (ROOT / package).glob("*.py"))
    assert len(top) <= TOP_MODULES_MAX, f"{package} has {len(top)} modules at its top: {top}"


def _bound_names(init: Path) -> set[str]:
    """Names a package's ``__init__.py`` binds at module level (assignments, imports, definitions, ``__all__``)."""
    names: set[str] = set()
    for node in ast.parse(init.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {n.id for tg in targets for n in ast.walk(tg) if isinstance(n, ast.Name)}
            if any(isinstance(tg, ast.Name) and tg.id == "__all__" for tg in targets):
                names |= {e.value for e in ast.walk(node.value) if isinstance(e, ast.Constant)}
    return names


def stale_imports(root: Path = ROOT) -> list[str]:
    """Imports of first-party names that exist neither as a module nor as a name bound by their package."""
    modules = first_party_modules(root)
    packages = {n: p for n, p in modules.items() if p.name == "__init__.py"}
    files = [p for d in ("tests", "bench", "examples", *PACKAGES) for p in sorted((root / d).rglob("*.py"))
             if "build" not in p.relative_to(root).parts]
    bad = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.Import):
                wanted = [(a.name, None) for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                wanted = [(node.module, a.name) for a in node.names]
            else:
                continue
            for mod, name in wanted:
                if mod.split(".")[0] not in PACKAGES:
                    continue
                if mod not in modules:
                    bad.append(f"{path.relative_to(root)}:{node.lineno}: no module {mod}")
                elif (name not in (None, "*") and mod in packages and f"{mod}.{name}" not in modules
                      and name not in _bound_names(packages[mod])):
                    bad.append(f"{path.relative_to(root)}:{node.lineno}: {mod} has no module or name {name}")
    return bad


def test_first_party_imports_name_what_exists():
    bad = stale_imports()
    assert not bad, "imports of names that do not exist in this tree:\n" + "\n".join(bad)


def _tree(tmp_path: Path, files: dict[str, str]) -> dict[str, list[tuple[str, int]]]:
    for rel, text in files.items():
        p = tmp_path / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    for pkg in PACKAGES:
        (tmp_path / pkg).mkdir(exist_ok=True)
        (tmp_path / pkg / "__init__.py").touch()
    return import_graph(tmp_path)


def test_the_scan_finds_late_relative_and_type_checking_imports(tmp_path):
    g = _tree(tmp_path, {
        "cosim/runtime/__init__.py": "", "cosim/runtime/participant.py": "", "cosim/runtime/outcome.py": "",
        "cosim/testing/__init__.py": "import dynamics_proc.model\n",
        "cosim/api.py": "def f():\n    from dynamics_proc.model import step\n",
        "dynamics_proc/model.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .record import R\n"
                                  "from cosim.runtime import participant\nfrom cosim.runtime.outcome import X\n",
        "dynamics_proc/record.py": "def g():\n    from . import model\n",
        "renderer_proc/draw.py": "import perception_proc\n",
        "cosim/scenario/__init__.py": "", "cosim/scenario/profiles.py": "",
        "cosim/scenario/config/__init__.py": "from . import base\nfrom ..profiles import load\n",
        "cosim/scenario/config/base.py": "",
    })
    bad = layer_violations(g)
    assert any(b.startswith("cosim.api:2 -> dynamics_proc.model") for b in bad)
    assert any(b.startswith("dynamics_proc.model:5 -> cosim.runtime.outcome") for b in bad)
    assert any(b.startswith("renderer_proc.draw:1 -> perception_proc") for b in bad)
    assert any(b.startswith("cosim.scenario.config:2 -> cosim.scenario.profiles") for b in bad)
    assert not any(b.startswith(("cosim.testing", "dynamics_proc.model:4")) for b in bad)
    assert len(bad) == 4
    assert import_cycles(g) == [["dynamics_proc.model", "dynamics_proc.record"]]


def test_stale_imports_are_found(tmp_path):
    _tree(tmp_path, {"dynamics_proc/grain/__init__.py": "", "dynamics_proc/grain/auger.py": "",
                     "tests/test_x.py": "from dynamics_proc import auger\nfrom dynamics_proc.grain import auger\n"
                                        "import dynamics_proc.controller\n"})
    assert stale_imports(tmp_path) == ["tests/test_x.py:1: dynamics_proc has no module or name auger",
                                       "tests/test_x.py:3: no module dynamics_proc.controller"]
