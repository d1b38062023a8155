"""An override changes only what it names, everywhere: a YAML that states one field of a nested block, ``--set``,
the API's ``overrides=`` and a sweep's values. A scan of every leaf field of every packaged scenario."""
from __future__ import annotations

import json
import typing

import pytest
import yaml

from cosim.errors import ScenarioError
from cosim.scenario.config import Scenario
from cosim.scenario.config.fielddraw import replaced_keys
from cosim.scenario.loader import load_scenario, load_scenario_text, packaged_scenarios
from cosim.scenario.options import load_with_options
from cosim.scenario.overrides import model_of
from cosim.scenario.yamlmarks import Loader as _Loader

PACKAGED = packaged_scenarios()


def _leaves(model=Scenario, prefix: tuple = ()) -> list[tuple[str, ...]]:
    """Every non-record field under ``model`` (records that are optional, such as an FMU, are left out: stating
    one of their keys gives the whole record)."""
    out = []
    for name, info in model.model_fields.items():
        sub = model_of(info.annotation)
        if sub is not None and typing.get_origin(info.annotation) is None:
            out += _leaves(sub, prefix + (name,))
        elif sub is None:
            out.append(prefix + (name,))
    return out


LEAVES = _leaves()


def _flat(data, prefix=()) -> dict:
    if isinstance(data, dict):
        return {k: v for key, value in data.items() for k, v in _flat(value, prefix + (key,)).items()}
    return {prefix: data}


def _get(data: dict, loc):
    for part in loc:
        data = data[part]
    return data


def _other(value, loc) -> list:
    """Candidate values other than ``value`` for the field at ``loc`` (tried in order until one is valid)."""
    info = Scenario
    for part in loc[:-1]:
        info = model_of(info.model_fields[part].annotation)
    ann = info.model_fields[loc[-1]].annotation
    choices = [a for a in typing.get_args(ann)] if typing.get_origin(ann) is typing.Literal else []
    if choices:
        return [c for c in choices if c != value]
    if isinstance(value, bool):
        return [not value]
    if isinstance(value, int):
        return [value + 1, value - 1]
    if isinstance(value, float):        # another value (0.99 x 0 is 0 again)
        return [v for v in (value * 1.01 + 0.001, value * 0.99, value + 0.5, value - 0.5) if v != value]
    if isinstance(value, list) and value and all(isinstance(v, (int, float)) for v in value):
        return [[value[0] + 0.5, *value[1:]], [value[0] - 0.5, *value[1:]]]
    if isinstance(value, str) and loc[-1] in ("name", "description"):
        return [value + "x"]
    return []


def _diff(a: Scenario, b: Scenario) -> set:
    fa, fb = _flat(a.model_dump(mode="json")), _flat(b.model_dump(mode="json"))
    return {k for k in fa if fa[k] != fb[k]}


def _may_move(base: Scenario, loc: tuple) -> set:
    """What a change of leaf ``loc`` may move besides itself. A case that draws its field (``field.draw``,
    docs/field.md) draws the leaves ``field.base`` records from the seed and the ``field.*`` ranges, from the value
    its file states as the base: so the seed or a range moves every drawn leaf, and a drawn leaf moves its base."""
    drawn = {tuple(k.split(".")) for k in (base.field.base or {})} if base.field.draw else set()
    out: set = set()
    if drawn and (loc == ("seed",) or loc[0] == "field"):
        out |= drawn
    if loc in drawn:
        out |= {loc, ("field", "base", ".".join(loc))}
    return out


def _replaced(base: Scenario) -> set:
    """The leaves the seed's draw replaces (a --set of one is refused: docs/field.md)."""
    return {tuple(k.split(".")) for k in replaced_keys(base.field.model_dump(mode="json"))}


#: the scenarios whose every leaf is scanned in the fast suite (the default, two field cases that draw, the three
#: camera cases); the rest run with -m slow
FAST = {"default", "high_flow", "dusty", "stereo_spout", "tof_mast", "lidar_and_stereo"}
SCANNED = [pytest.param(n, marks=() if n in FAST else pytest.mark.slow) for n in sorted(PACKAGED)]


def _within(moved: set, loc: tuple, allowed: set) -> bool:
    """Every moved leaf is ``loc`` or one ``allowed`` (or lies under one: a drawn list)."""
    return all(m == loc or any(m[:len(a)] == a for a in allowed) for m in moved)


def test_the_scan_covers_every_leaf():
    assert len(LEAVES) > 120
    assert ("sensor", "mount", "rpy_deg") in LEAVES and ("sensor", "mount", "xyz_m") in LEAVES


@pytest.mark.parametrize("name", SCANNED)
def test_an_override_changes_only_what_it_names(name):
    """For every leaf of every packaged scenario: ``--set`` to its own value changes nothing; ``--set`` to another
    valid value changes that leaf and nothing else; a leaf the seed's draw replaces is refused, naming its range."""
    path = PACKAGED[name]
    base = load_scenario(path, check_world=False)
    data = base.model_dump(mode="json")
    replaced = _replaced(base)
    changed = 0
    for loc in LEAVES:
        key, value = ".".join(loc), _get(data, loc)
        if loc in replaced:
            with pytest.raises(ScenarioError, match=f"'{key}' is drawn per seed"):
                load_scenario(path, [f"{key}={json.dumps(value)}"], check_world=False)
            continue
        same = load_scenario(path, [f"{key}={json.dumps(value)}"], check_world=False)
        diff = _diff(base, same)
        assert not diff or _within(diff, loc, _may_move(base, loc)), \
            f"{name}: --set {key} to its own value moved {sorted(diff)}"
        for other in _other(value, loc):
            try:
                moved = load_scenario(path, [f"{key}={json.dumps(other)}"], check_world=False)
            except ScenarioError:
                continue                    # not a valid value here (a cross-field rule): try the next
            diff = _diff(base, moved)
            # a drawn leaf is drawn again from its field.* range: setting it moves its recorded base only
            assert diff and (loc in diff or loc in _may_move(base, loc)) and _within(diff, loc, _may_move(base, loc)), \
                f"{name}: --set {key}={other} moved {sorted(diff)}"
            changed += 1
            break
    assert changed > 100


@pytest.mark.parametrize("name", SCANNED)
def test_a_yaml_that_states_one_field_of_a_block_keeps_the_rest(name, tmp_path):
    """The packaged file with one more key stated, in a block it may not have: only that key moves."""
    base = load_scenario(PACKAGED[name], check_world=False)
    raw = yaml.load(PACKAGED[name].read_text(), Loader=_Loader)
    data = base.model_dump(mode="json")
    for loc in LEAVES:
        if loc[-1] == "plugin_dir":
            continue                        # the loader sets it from the file's folder
        doc = json.loads(json.dumps(raw))
        node = doc
        for part in loc[:-1]:
            node = node.setdefault(part, {})
        node[loc[-1]] = _get(data, loc)
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
        got = load_scenario_text(path.read_text(), str(path), base_dir=PACKAGED[name].parent)
        diff = _diff(base, got)
        assert not diff or _within(diff, loc, _may_move(base, loc)), \
            f"{name}: stating only {'.'.join(loc)} moved {sorted(diff)}"


def test_the_issues_case_in_every_form(tmp_path):
    """``sensor.mount.rpy_deg`` alone kept the mast's position, ``xyz_m`` alone its orientation: YAML, --set,
    the API's overrides= and a sweep."""
    mast = load_scenario(PACKAGED["default"], check_world=False).sensor.mount
    assert mast.xyz_m == (-3.5, 5.0, 6.0)
    s = load_scenario(PACKAGED["default"], ["sensor.mount.rpy_deg=[90, 65, 75]"])
    assert s.sensor.mount.xyz_m == mast.xyz_m and s.sensor.mount.rpy_deg == (90.0, 65.0, 75.0)
    s = load_scenario_text("format_version: 1\nsensor:\n  mount:\n    xyz_m: [-3.5, 5.0, 6.5]\n")
    assert s.sensor.mount.rpy_deg == mast.rpy_deg and s.sensor.mount.parent == "combine"
    s = load_with_options("default", overrides={"sensor.mount.rpy_deg": [90, 65, 75]})
    assert s.sensor.mount.xyz_m == mast.xyz_m
    s = load_with_options("default", overrides={"sensor.mount": {"xyz_m": [-3.5, 5.0, 6.5]}})
    assert s.sensor.mount.rpy_deg == mast.rpy_deg
    from cosim.studies.sweepfile import load_sweep

    sweep = tmp_path / "sweep.yaml"
    sweep.write_text("format_version: 1\nbase: default\nset:\n  sensor.mount.rpy_deg: [90, 65, 75]\n"
                     "grid:\n  sensor.mount.xyz_m: [[-3.5, 5.0, 6.0], [-3.5, 5.0, 6.5]]\n")
    runs = load_sweep(sweep).runs
    assert [r.scenario.sensor.mount.rpy_deg for r in runs] == [(90.0, 65.0, 75.0)] * 2
    assert [r.scenario.sensor.mount.xyz_m[2] for r in runs] == [6.0, 6.5]
