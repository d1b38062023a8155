"""Scenario loading: YAML marks, YAML 1.2 scalars, --set and option overrides, path resolution, packaged
scenarios, the problem format and the check command."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cosim.errors import Problem, ScenarioError
from cosim.scenario.config import Scenario, Sensor
from cosim.scenario.loader import (
    OPTIONS_FILE,
    SET_FILE,
    load_scenario,
    load_scenario_text,
    packaged_scenarios,
    path_fields,
    resolve_scenario_arg,
)

REPO = Path(__file__).resolve().parents[1]


def problems(text: str, overrides=(), **kw) -> list[Problem]:
    with pytest.raises(ScenarioError) as info:
        load_scenario_text(text, "s.yaml", overrides, **kw)
    return info.value.problems


# ------------------------------------------------------------------------------------------ the format
def test_problem_format_is_file_line_col_path_message():
    with pytest.raises(ScenarioError) as info:
        load_scenario_text("format_version: 1\ntiming:\n  sensor_period_s: -0.1\n", "dir/s.yaml")
    assert str(info.value) == "dir/s.yaml:3:20: timing.sensor_period_s: Input should be greater than 0 s, got -0.1 s"


def test_problems_are_sorted_by_line_then_overrides():
    got = problems("format_version: 1\nviewer: 2\nseed: -1\nbogus: 3\n", ["seed=x"], extra={"renderer": "vk"})
    assert [(p.file, p.line, p.path) for p in got] == [
        ("s.yaml", 2, "viewer"), ("s.yaml", 4, "bogus"), (SET_FILE, 1, "seed"), (OPTIONS_FILE, 0, "renderer"),
    ]


def test_short_tuple_is_reported_once_at_the_list():
    got = problems("format_version: 1\nsensor:\n  mount:\n    xyz_m: [1.0]\n")
    assert [(p.line, p.col, p.path, p.message) for p in got] == [(4, 12, "sensor.mount.xyz_m", "expected 3 items, got 1")]


def test_missing_key_points_at_its_mapping():
    got = problems("# a comment first\n\n  name: x\n  seed: 1\n")
    assert [(p.line, p.col, p.path) for p in got] == [(3, 3, "format_version")]
    assert got[0].message.startswith("missing required key 'format_version'")


def test_duplicate_key_inside_a_list_of_mappings_and_deep_nesting():
    got = problems("format_version: 1\nsensor:\n  noise:\n    dropout: 0.1\n    dropout: 0.2\n")
    assert [(p.line, p.col, p.path) for p in got] == [(5, 5, "sensor.noise.dropout")]
    assert "first defined at line 4" in got[0].message


def test_non_string_keys_and_unsupported_tags_are_problems():
    got = problems("format_version: 1\n1: a\ndescription: !!binary aGVsbG8=\n")
    assert [(p.line, p.path) for p in got] == [(2, ""), (3, "description")]
    assert "keys must be strings, got 1" in got[0].message
    assert "unsupported YAML value of type bytes" in got[1].message


def test_merge_keys_and_multiple_documents_are_rejected():
    got = problems("format_version: 1\nbase: &b {seed: 1}\n<<: *b\n")
    assert any(p.line == 3 and "merge keys" in p.message for p in got)
    with pytest.raises(ScenarioError, match=r"s\.yaml:2:1: <root>: YAML syntax error: .*single document"):
        load_scenario_text("format_version: 1\n---\nformat_version: 1\n", "s.yaml")


def test_unreadable_file_is_a_scenario_error(tmp_path):
    with pytest.raises(ScenarioError, match=r"nope\.yaml:0:0: <root>: cannot read scenario file"):
        load_scenario(tmp_path / "nope.yaml")
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes(b"format_version: 1\ndescription: caf\xe9\n")
    with pytest.raises(ScenarioError, match="cannot read scenario file"):
        load_scenario(bad)


# ------------------------------------------------------------------------------------ YAML 1.2 scalars
def test_yaml_12_scalars():
    s = load_scenario_text(
        "format_version: 1\nintegrator: {rtol: 1e-6, atol: 1E-9}\nrender: {rgb: on}\nname: 2024-01-01\n"
        "description: yes\nseed: 0x10\n"
    )
    assert (s.integrator.rtol, s.integrator.atol) == (1e-6, 1e-9)
    assert s.render.rgb == "on" and s.name == "2024-01-01" and s.description == "yes" and s.seed == 16


def test_rate_ratio_is_reported_with_other_problems_of_its_section():
    got = problems("format_version: 1\ntiming:\n  sensor_period_s: 0.1\n  dynamics_dt_s: 0.04\n  latency_frames: x\n")
    assert [(p.line, p.col, p.path) for p in got] == [(4, 18, "timing.dynamics_dt_s"), (5, 19, "timing.latency_frames")]
    assert "= 2.5 is not an integer >= 1" in got[0].message
    # the default dynamics step against a period it does not divide: reported at the section
    got = problems("format_version: 1\ntiming:\n  sensor_period_s: 0.015\n")
    assert [(p.line, p.col, p.path) for p in got] == [(2, 1, "timing.dynamics_dt_s")]


def test_strict_json_mode_types():
    got = problems("format_version: 1\nduration_s: '30'\nviewer: 0\nseed: 1.0\ncombine: {start_xy_m: 5}\n")
    assert [p.path for p in got] == ["duration_s", "viewer", "seed", "combine.start_xy_m"]
    assert load_scenario_text("format_version: 1\nduration_s: 30\n").duration_s == 30.0  # int is a valid float


# -------------------------------------------------------------------------------------------- overrides
def test_set_overrides_from_the_issue():
    s = load_scenario_text(
        "format_version: 1\ntiming: {sensor_period_s: 0.1, latency_frames: 2}\n", overrides=[
            "timing.sensor_period_s=0.05", "sensor.mount.xyz_m=[1,2,3]", "controller.strategy=lowest_first",
        ])
    assert s.timing.sensor_period_s == 0.05 and s.timing.latency_frames == 2  # sparse: the rest of timing stays
    # one field of a nested block: its siblings keep the block's default (the mast's orientation), not Mount()'s
    assert s.sensor.mount.xyz_m == (1.0, 2.0, 3.0) and s.sensor.mount.rpy_deg == Sensor().mount.rpy_deg != (0, 0, 0)
    assert s.controller.strategy == "lowest_first"


def test_later_overrides_win_and_mappings_merge():
    s = load_scenario_text("format_version: 1\ntiming: {latency_frames: 2}\n", overrides=[
        "seed=1", "seed=2", "timing={sensor_period_s: 0.2, dynamics_dt_s: 0.05}"])
    assert s.seed == 2
    assert (s.timing.sensor_period_s, s.timing.dynamics_dt_s, s.timing.latency_frames) == (0.2, 0.05, 2)


def test_set_value_error_reports_the_override_position():
    got = problems("format_version: 1\n", ["timing={sensor_period_s: 0.1, dynamics_dt_s: 0.03}"])
    assert [(p.file, p.line, p.col, p.path) for p in got] == [(SET_FILE, 1, 46, "timing.dynamics_dt_s")]
    got = problems("format_version: 1\n", ["seed=1", "timing={sensor_period_s: -1}"])
    assert [(p.file, p.line, p.col, p.path) for p in got] == [(SET_FILE, 2, 26, "timing.sensor_period_s")]


def test_set_into_a_value_that_is_not_a_mapping():
    got = problems("format_version: 1\ntiming: 3\n", ["timing.latency_frames=2"])
    assert [(p.file, p.path) for p in got] == [("s.yaml", "timing"), (SET_FILE, "timing.latency_frames")]
    assert "Input should be a mapping, got 3" in got[0].message
    assert "cannot set a key inside 'timing': it is not a mapping" in got[1].message


def test_overrides_must_be_a_sequence_of_strings():
    with pytest.raises(TypeError, match="sequence of 'PATH=VALUE' strings"):
        load_scenario_text("format_version: 1\n", overrides="seed=1")


def test_extra_options_apply_like_set():
    s = load_scenario_text("format_version: 1\nrenderer: gl\n", extra={
        "renderer": "mock", "seed": 7, "duration_s": 12.5, "viewer": None, "sensor.mount.xyz_m": (1, 2, 3)})
    assert (s.renderer, s.seed, s.duration_s, s.viewer, s.sensor.mount.xyz_m) == ("mock", 7, 12.5, False, (1, 2, 3))
    got = problems("format_version: 1\n", extra={"renderr": "mock", "render": {"width_px": 2}})
    assert [(p.file, p.path) for p in got] == [(OPTIONS_FILE, "render.width_px"), (OPTIONS_FILE, "renderr")]
    assert "did you mean 'renderer'" in got[1].message


def test_override_can_fix_a_bad_file_value():
    s = load_scenario_text("format_version: 1\nduration_s: -1\n", overrides=["duration_s=5"])
    assert s.duration_s == 5.0


# ------------------------------------------------------------------------------------------------ paths
def test_path_fields_are_found_by_walking_the_model():
    found = set(path_fields())
    assert {("combine", "mesh_file"), ("tractor", "mesh_file"), ("cart", "mesh_file"),
            ("sensor", "pattern", "csv_file")} <= found


def test_relative_paths_resolve_against_the_scenario_file(tmp_path, monkeypatch):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "cart.obj").write_text("v 0 0 0\n")
    (tmp_path / "beams.csv").write_text("0,0\n")
    scen = tmp_path / "s.yaml"
    scen.write_text("format_version: 1\ncart: {mesh_file: meshes/cart.obj}\n"
                    "sensor: {pattern: {preset: csv, csv_file: beams.csv}}\n")
    monkeypatch.chdir(REPO)  # the working directory must not matter
    s = load_scenario(scen, check_world=False)  # a one-vertex mesh: only the path matters here
    assert s.cart.mesh_file == tmp_path / "meshes" / "cart.obj" and s.cart.mesh_file.is_absolute()
    assert s.sensor.pattern.csv_file == tmp_path / "beams.csv"


def test_set_paths_resolve_against_the_working_directory(tmp_path, monkeypatch):
    (tmp_path / "combine.obj").write_text("v 0 0 0\n")
    monkeypatch.chdir(tmp_path)
    s = load_scenario(resolve_scenario_arg("default"), ["combine.mesh_file=combine.obj"], check_world=False)
    assert s.combine.mesh_file == tmp_path / "combine.obj"
    got = problems("format_version: 1\n", ["tractor.mesh_file=missing.obj"])
    assert [(p.file, p.line, p.col, p.path) for p in got] == [(SET_FILE, 1, 19, "tractor.mesh_file")]
    assert str(tmp_path / "missing.obj") in got[0].message


def test_every_relative_path_given_on_the_command_line_resolves_against_the_working_directory(tmp_path, monkeypatch):
    """As documented (README, docs/CONTRACTS.md): --set and options against the working directory, the file's values
    against the file's folder; plugin_dir and sensor.pattern.csv_file included."""
    (tmp_path / "mods").mkdir()
    (tmp_path / "beams.csv").write_text("elevation_deg,azimuth_deg\n0,0\n")
    monkeypatch.chdir(tmp_path)
    s = load_scenario(resolve_scenario_arg("default"), ["plugin_dir=mods", "sensor.pattern.preset=csv",
                                                        "sensor.pattern.csv_file=beams.csv"], check_world=False)
    assert s.plugin_dir == str(tmp_path / "mods") and s.sensor.pattern.csv_file == tmp_path / "beams.csv"
    s = load_scenario_text("format_version: 1\n", extra={"plugin_dir": "mods"})
    assert s.plugin_dir == str(tmp_path / "mods")
    s = load_scenario_text("format_version: 1\nplugin_dir: mods\n", base_dir=REPO)
    assert s.plugin_dir == str(REPO / "mods")


def test_a_directory_is_not_a_mesh_file(tmp_path):
    (tmp_path / "d").mkdir()
    got = problems("format_version: 1\ncart:\n  mesh_file: d\n", base_dir=tmp_path)
    assert [(p.line, p.col, p.path) for p in got] == [(3, 14, "cart.mesh_file")]
    assert "is not a file" in got[0].message


# ---------------------------------------------------------------------------------------------- packaged
def test_packaged_default_is_the_papers_case():
    assert "default" in packaged_scenarios()
    path = resolve_scenario_arg("default")
    assert path == REPO / "cosim" / "scenarios" / "default.yaml"
    s = load_scenario(path)
    assert (s.feedback, s.renderer, s.controller.strategy) == ("perception", "gl", "front_to_back")
    assert s.grain.initial_fill_m == pytest.approx(s.cart.interior_depth_m / 2)  # half full
    assert s.grain.initial_fill_m < s.controller.target_fill_m < s.cart.interior_depth_m
    assert 90.0 <= s.duration_s <= 120.0
    assert s.participants == ("dynamics", "renderer", "perception")


def test_every_packaged_scenario_loads():
    for name, path in packaged_scenarios().items():
        assert isinstance(load_scenario(path), Scenario), name


def test_resolve_scenario_arg(tmp_path):
    f = tmp_path / "mine.yaml"
    f.write_text("format_version: 1\n")
    assert resolve_scenario_arg(str(f)) == f
    with pytest.raises(ScenarioError, match=r"no_such:0:0: <root>: no such scenario file or packaged scenario "
                                            r"\(packaged: .*default"):
        resolve_scenario_arg("no_such")


# ------------------------------------------------------------------------------------- command line (cli.py)
def test_invalid_scenario_exits_2_without_traceback():
    bad = REPO / "tests" / "scenarios_bad" / "several_problems.yaml"
    run = subprocess.run([sys.executable, "-m", "cosim", "validate", str(bad), "--set", "seed=-1"],
                         capture_output=True, text=True, cwd=REPO, timeout=60)
    assert run.returncode == 2 and run.stdout == ""
    assert "Traceback" not in run.stderr
    lines = run.stderr.splitlines()
    assert lines[0] == f"{bad}:3:13: duration_s: Input should be greater than 0 s, got 0 s"
    assert "<--set>:1:6: seed: Input should be greater than or equal to 0, got -1" in lines
