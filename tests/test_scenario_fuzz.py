"""Properties of the loader on arbitrary input: it either returns a Scenario or raises ScenarioError whose
problems all point into the text (never another exception, never a position past the end)."""
from __future__ import annotations

import string

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cosim.errors import ScenarioError
from cosim.scenario.config import Scenario
from cosim.scenario.loader import load_scenario_text
from cosim.scenario.overrides import model_of as _model_of


def _known_keys(model=Scenario) -> list[str]:
    keys = []
    for name, info in model.model_fields.items():
        keys.append(name)
        sub = _model_of(info.annotation)
        if sub is not None:
            keys += _known_keys(sub)
    return sorted(set(keys))


KEYS = st.sampled_from(_known_keys()) | st.text(string.ascii_lowercase + "_", min_size=1, max_size=8)
SCALARS = (st.none() | st.booleans() | st.integers(-10**20, 10**20) | st.floats(allow_nan=True)
           | st.sampled_from(["gl", "none", "perception", "csv", "front_to_back", "1", "yes", "x.obj"]))
TREES = st.recursive(SCALARS, lambda kids: st.lists(kids, max_size=4) | st.dictionaries(KEYS, kids, max_size=5),
                     max_leaves=25)


def check(text: str, overrides=()) -> None:
    try:
        assert isinstance(load_scenario_text(text, "f.yaml", overrides), Scenario)
    except ScenarioError as e:
        assert e.problems
        lines = text.count("\n") + 1
        for p in e.problems:
            assert p.message and str(p).startswith(f"{p.file}:{p.line}:{p.col}: ")
            if p.file == "f.yaml":
                assert 1 <= p.line <= lines + 1, str(p)
            else:
                assert p.file == "<--set>" and 1 <= p.line <= len(overrides), str(p)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tree=st.dictionaries(KEYS, TREES, max_size=6), version=st.sampled_from([1, 1, 2, "1", None]),
       flow=st.booleans())
def test_structured_documents(tree, version, flow):
    doc = {"format_version": version, **tree} if version is not None else tree
    check(yaml.safe_dump(doc, default_flow_style=flow, sort_keys=False))


@settings(max_examples=150, deadline=None)
@given(head=st.booleans(), text=st.text(alphabet="ab:-[]{},#&*!|>'\"%@`\n\t 01.e<~?", max_size=60))
def test_arbitrary_text(head, text):
    check(("format_version: 1\n" if head else "") + text)


@settings(max_examples=100, deadline=None)
@given(overrides=st.lists(st.tuples(KEYS, KEYS, st.text("[]{}:,=.01ab -", max_size=8)), max_size=3))
def test_arbitrary_overrides(overrides):
    check("format_version: 1\n", [f"{a}.{b}={v}" if i % 2 else f"{a}={v}" for i, (a, b, v) in enumerate(overrides)])
