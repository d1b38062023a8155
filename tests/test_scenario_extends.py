"""``extends: NAME_OR_PATH``: a scenario that starts from a packaged scenario or another file and states only what
differs (docs/architecture.md, "Scenarios"); cycles and missing bases are refused with file:line."""
from __future__ import annotations

from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import ScenarioError
from cosim.scenario.extends import MAX_CHAIN
from cosim.scenario.loader import load_scenario, load_scenario_text, packaged_scenarios

DEFAULT = packaged_scenarios()["default"]


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_a_file_that_extends_a_packaged_scenario_is_it_but_for_what_it_states(tmp_path):
    """Without extends a YAML gets the record defaults (60 s, camera_rig); with it, default's values."""
    default = load_scenario(DEFAULT)
    bare = load_scenario(_write(tmp_path / "bare.yaml", "format_version: 1\ncontroller: {strategy: lowest_first}\n"),
                         check_world=False)
    assert (bare.duration_s, bare.sensor.method) == (60.0, "camera_rig")
    mine = load_scenario(_write(tmp_path / "mine.yaml", "format_version: 1\nextends: default\nname: mine\n"
                                "controller:\n  strategy: lowest_first\n"))
    assert (mine.duration_s, mine.sensor.method, mine.name) == (120.0, "beam_native", "mine")
    assert mine.controller.strategy == "lowest_first"
    assert mine.controller.target_fill_m == default.controller.target_fill_m == 1.9
    assert mine.model_copy(update={"name": "default", "description": default.description, "controller":
                                   default.controller, "plugin_dir": default.plugin_dir}) == default
    # name and description describe the file itself: not inherited
    plain = load_scenario(_write(tmp_path / "plain.yaml", "format_version: 1\nextends: default\n"))
    assert (plain.name, plain.description) == ("scenario", "")


def test_chains_merge_blocks_key_by_key_and_paths_resolve_against_their_own_file(tmp_path):
    (tmp_path / "common" / "cart.obj").parent.mkdir()
    (tmp_path / "common" / "cart.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    _write(tmp_path / "common" / "base.yaml", "format_version: 1\nextends: default\ncart:\n  mesh_file: cart.obj\n"
           "timing:\n  latency_frames: 3\n")
    child = _write(tmp_path / "runs" / "child.yaml", "format_version: 1\nextends: ../common/base.yaml\n"
                   "timing:\n  sensor_period_s: 0.05\n  dynamics_dt_s: 0.005\n")
    s = load_scenario(child, check_world=False)
    assert s.cart.mesh_file == tmp_path / "common" / "cart.obj"           # the base's folder, not the child's
    assert (s.timing.latency_frames, s.timing.sensor_period_s, s.duration_s) == (3, 0.05, 120.0)
    assert s.plugin_dir == str(tmp_path / "runs")                          # the loaded file's folder


def test_an_inherited_problem_is_reported_at_the_base_files_line(tmp_path):
    base = _write(tmp_path / "base.yaml", "format_version: 1\nduration_s: -1\n")
    child = _write(tmp_path / "child.yaml", "format_version: 1\nextends: base.yaml\nseed: 2\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(child)
    [problem] = info.value.problems
    assert (problem.file, problem.line, problem.col, problem.path) == (str(base.resolve()), 2, 13, "duration_s")


@pytest.mark.parametrize("files, where, message", [
    ({"a.yaml": "extends: a.yaml\n"}, "a.yaml:2:10", "the bases form a cycle: a.yaml -> a.yaml"),
    ({"a.yaml": "extends: b.yaml\n", "b.yaml": "extends: a.yaml\n"}, "b.yaml:2:10",
     "the bases form a cycle: a.yaml -> b.yaml -> a.yaml"),
    ({"a.yaml": "extends: nothere.yaml\n"}, "a.yaml:2:10", "base scenario file '{tmp}/nothere.yaml' does not exist"),
    ({"a.yaml": "extends: defualt\n"}, "a.yaml:2:10", "no such scenario file or packaged scenario"),
    ({"a.yaml": "extends: [default]\n"}, "a.yaml:2:10", "expected the name of a packaged scenario or a path"),
    ({"a.yaml": "extends: b.yaml\n", "b.yaml": "format_version: 2\n"}, "a.yaml:2:10", "is of format_version 2"),
    ({"a.yaml": "extends: b.yaml\n", "b.yaml": "- a list\n"}, "a.yaml:2:10", "is not a mapping"),
])
def test_cycles_and_missing_bases_are_refused_with_file_line(tmp_path, capsys, files, where, message):
    for name, body in files.items():
        _write(tmp_path / name, body if body.startswith(("format_version", "-")) else "format_version: 1\n" + body)
    assert main(["validate", str(tmp_path / "a.yaml")]) == 2
    err = capsys.readouterr().err
    assert f"{where}: extends: " in err and message.format(tmp=tmp_path) in err, err
    assert "Traceback" not in err


def test_a_chain_longer_than_the_limit_is_refused(tmp_path):
    for i in range(MAX_CHAIN + 2):
        _write(tmp_path / f"s{i}.yaml", f"format_version: 1\nextends: s{i + 1}.yaml\n" if i <= MAX_CHAIN else
               "format_version: 1\n")
    with pytest.raises(ScenarioError, match=f"more than {MAX_CHAIN} files extend one another"):
        load_scenario(tmp_path / "s0.yaml", check_world=False)


def test_overrides_apply_after_the_bases():
    s = load_scenario_text("format_version: 1\nextends: default\n", overrides=["duration_s=5"], check_world=False)
    assert s.duration_s == 5.0 and s.sensor.method == "beam_native"
