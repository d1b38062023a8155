"""The gallery of malformed scenarios (tests/scenarios_bad): each file must fail with exactly the problems that
tests/scenarios_bad/expected.yaml lists for it (file, line:col, dotted path, message fragment), in that order."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from cosim.errors import ScenarioError
from cosim.scenario.loader import SET_FILE, load_scenario

GALLERY = Path(__file__).parent / "scenarios_bad"
EXPECTED: dict = yaml.safe_load((GALLERY / "expected.yaml").read_text(encoding="utf-8"))
FILES = sorted(p.name for p in GALLERY.glob("*.yaml") if p.name != "expected.yaml")


def test_gallery_is_complete():
    assert len(FILES) >= 24
    assert sorted(EXPECTED) == FILES, "every gallery file needs an entry in expected.yaml and vice versa"


@pytest.mark.parametrize("name", FILES)
def test_malformed_scenario_reports_expected_problems(name):
    case = EXPECTED[name]
    path = GALLERY / name
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, case.get("set", ()))
    got = info.value.problems
    want = case["problems"]
    assert len(got) == len(want), "\n".join(map(str, got))
    for problem, exp in zip(got, want):
        line, col = (int(x) for x in exp["at"].split(":"))
        assert problem.file == exp.get("file", str(path)), str(problem)
        assert (problem.line, problem.col) == (line, col), str(problem)
        assert problem.path == exp["path"], str(problem)
        assert exp["message"] in problem.message, str(problem)
    in_file = [p for p in got if p.file != SET_FILE]
    assert in_file == sorted(in_file, key=lambda p: (p.line, p.col)), "problems must come in line order"


def test_every_problem_is_one_line_in_the_message():
    path = GALLERY / "several_problems.yaml"
    with pytest.raises(ScenarioError, match=r"several_problems\.yaml:3:13: duration_s: ") as info:
        load_scenario(path)
    lines = str(info.value).splitlines()
    assert lines == [str(p) for p in info.value.problems]
    assert len(lines) == len(EXPECTED["several_problems.yaml"]["problems"])
