"""No function of the source is longer than :data:`MAX_LINES` lines (its ``def`` to its last line, docstring and
comments included): a longer one is split into named stages. Complexity and the number of arguments are ruff's
(C901, PLR0913; pyproject.toml)."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: the source: the packages, the benchmarks, the examples and the launcher
SOURCE = ("cosim", "shm_schema", "dynamics_proc", "renderer_proc", "perception_proc", "bench", "examples")
MAX_LINES = 80


def long_functions(text: str, max_lines: int = MAX_LINES) -> list[tuple[str, int, int]]:
    """(name, first line, length in lines) of every function or method in ``text`` longer than ``max_lines``."""
    return [(n.name, n.lineno, n.end_lineno - n.lineno + 1) for n in ast.walk(ast.parse(text))
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > max_lines]


def source_files() -> list[Path]:
    files = [p for d in SOURCE for p in sorted((ROOT / d).rglob("*.py"))
             if "build" not in p.relative_to(ROOT).parts]
    return files + [ROOT / "launch.py"]


def test_no_function_is_longer_than_the_limit():
    long = [f"{p.relative_to(ROOT)}:{line}: {name} has {n} lines" for p in source_files()
            for name, line, n in long_functions(p.read_text(encoding="utf-8"))]
    assert not long, f"functions over {MAX_LINES} lines:\n" + "\n".join(long)


def test_the_count_spans_def_to_last_line():
    body = "\n".join(f"    x{i} = {i}" for i in range(79))
    assert long_functions(f"def f():\n{body}\n") == []                      # 80 lines
    assert long_functions(f"class C:\n    def g(self):\n    {body.replace(chr(10), chr(10) + '    ')}\n"
                          f"        return 1\n") == [("g", 2, 81)]


def test_the_controller_step_is_four_short_stages():
    """controller_step runs ingest -> fullness -> aim -> safety, each under 60 lines (docs/paper.md)."""
    import inspect

    from dynamics_proc.control import controller

    for name in ("ingest", "fullness", "aim", "safety", "controller_step"):
        lines = inspect.getsource(getattr(controller, name)).count("\n")
        assert lines < 60, f"{name} has {lines} lines"
    body = inspect.getsource(controller.controller_step)
    assert [s for s in ("ingest(", "fullness(", "aim(", "safety(") if s not in body] == []


def test_the_command_line_is_a_table_of_verbs():
    from cosim import cli

    assert set(cli.PLAIN_VERBS) | set(cli.SCENARIO_VERBS) == set(cli.VERBS)
    assert not set(cli.PLAIN_VERBS) & set(cli.SCENARIO_VERBS)
