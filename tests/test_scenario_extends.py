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


TOF = ("sensors:\n  tof:\n    kind: depth_camera\n    profile: tof_kinect_class\n    range_max_m: 8.0\n"
       "    mount: {parent: combine, xyz_m: [-3.5, 5.0, 6.0], rpy_deg: [0.0, 52.0, 116.0]}\n")


def test_sensors_replaces_the_bases_sensor_and_back(tmp_path):
    """A base's one-LiDAR ``sensor:`` is not inherited by a file that gives ``sensors:`` (and a base's
    ``sensors:`` not by one that gives ``sensor:``): no "remove sensor:" for a key the user's file does not have."""
    (tmp_path / "cams.yaml").write_text("format_version: 1\nextends: default\n" + TOF)
    s = load_scenario(tmp_path / "cams.yaml", check_world=False)
    assert list(s.sensor_set) == ["tof"] and s.lidar is None
    (tmp_path / "lidar.yaml").write_text("format_version: 1\nextends: tof_mast\nsensor:\n  method: beam_native\n")
    s = load_scenario(tmp_path / "lidar.yaml", check_world=False)
    assert s.sensors == {} and s.lidar.method == "beam_native" and list(s.sensor_set) == ["lidar"]
    # a file that gives both is still refused, at its own sensors key
    (tmp_path / "both.yaml").write_text("format_version: 1\nextends: default\nsensor:\n  method: beam_native\n"
                                        + TOF)
    with pytest.raises(ScenarioError, match=r"both\.yaml:5:1: sensors: both sensor: and sensors: are given"):
        load_scenario(tmp_path / "both.yaml", check_world=False)


def test_a_cross_check_points_at_the_users_line_that_sets_the_value(tmp_path):
    (tmp_path / "mine.yaml").write_text("format_version: 1\nextends: default\ncontroller:\n  strategy: lowest_first\n"
                                        "  target_fill_m: 190\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "mine.yaml")
    [p] = info.value.problems
    assert (p.file, p.line, p.col, p.path) == (str(tmp_path / "mine.yaml"), 5, 18, "controller.target_fill_m")
    assert "target_fill_m (190) is above the wall top" in p.message
