"""Input limits and the frame-0 plausibility checks beyond the gallery: sizes, memory, the CLI."""
from __future__ import annotations

from pathlib import Path

import pytest

from cosim.errors import RunRefused, ScenarioError
from cosim.runtime.capacity import check_segment_fits
from cosim.runtime.specs import build_schema, ring_specs
from cosim.scenario.loader import MAX_SCENARIO_BYTES, load_scenario, load_scenario_text, resolve_scenario_arg
from cosim.scenario.memory import PROCESS_BYTES_PER_BEAM, SHARED_BYTES_PER_BEAM, Room, memory_problems
from cosim.scenario.plausibility import implausible
from cosim.scenario.yamlmarks import MAX_VALUES

DEFAULT = resolve_scenario_arg("default")


def test_a_file_over_the_size_limit_is_refused_unread(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_text("format_version: 1\n" + "#" * MAX_SCENARIO_BYTES + "\n")
    with pytest.raises(ScenarioError, match=r"big.yaml:1:1: <root>: the scenario is 1.0 MiB; scenarios are "
                                            r"limited to 1 MiB") as info:
        load_scenario(big)
    assert len(info.value.problems) == 1
    with pytest.raises(ScenarioError, match="limited to 1 MiB"):
        load_scenario_text("format_version: 1\n" + " " * MAX_SCENARIO_BYTES)


def test_aliases_count_each_time_they_are_used():
    """A list of n aliases of one scalar counts n + 7 values (the root, three keys, two scalar values, the list):
    fine at the budget, refused one past it, at the alias that crosses it."""
    def text(n):
        return "format_version: 1\ndescription: &a text\nseed: [" + ", ".join(["*a"] * n) + "]\n"

    with pytest.raises(ScenarioError) as info:  # within the budget: only the schema complains (seed is an int)
        load_scenario_text(text(MAX_VALUES - 7))
    assert "expands" not in str(info.value) and "seed" in str(info.value)
    # reported at the anchored value that is used over and over, with the path of the use that crossed the budget
    with pytest.raises(ScenarioError, match=rf"<string>:2:14: seed\[{MAX_VALUES - 7}\]: the document expands to "
                                            f"more than {MAX_VALUES:,} values") as info:
        load_scenario_text(text(MAX_VALUES - 6))
    assert len(info.value.problems) == 1


def test_pattern_memory_is_beams_times_bytes_per_beam():
    s = load_scenario(DEFAULT)
    beams = s.sensor.pattern.azimuth_count * s.sensor.pattern.elevation_count
    shared = beams * SHARED_BYTES_PER_BEAM
    total = shared + beams * PROCESS_BYTES_PER_BEAM
    assert memory_problems(s, free=(shared, total)) == []
    [(loc, message)] = memory_problems(s, free=(shared - 1, total))
    assert loc == ("sensor", "pattern") and f"{beams:,} beams need at least" in message
    assert memory_problems(s, free=(shared, total - 1)) != []


def test_the_schema_allows_a_pattern_the_machine_cannot_hold(tmp_path):
    """100000 x 10000 beams pass the schema's bounds; the memory check refuses them at the pattern's line."""
    path = tmp_path / "beams.yaml"
    path.write_text("format_version: 1\nsensor:\n  pattern:\n    preset: grid\n    azimuth_count: 100000\n"
                    "    elevation_count: 10000\n")
    s = load_scenario(path, check_world=False)
    problems = memory_problems(s, free=(16 << 30, 64 << 30))
    assert problems and "100000 x 10000 = 1,000,000,000 beams need at least 14.9 GiB of shared memory" in problems[0][1]
    if implausible(s):  # on this machine too (unless it has ~110 GiB free): at file:line
        with pytest.raises(ScenarioError, match=r"beams.yaml:3:3: sensor.pattern: 100000 x 10000"):
            load_scenario(path)


def test_a_sensor_under_the_grain_surface_is_refused():
    s_text = ("format_version: 1\nsensor:\n  mount: {parent: cart, xyz_m: [0.0, 0.0, 1.5], "
              "rpy_deg: [90.0, 60.0, 75.0]}\n")
    with pytest.raises(ScenarioError, match=r"x.yaml:3:32: sensor.mount.xyz_m: the sensor is inside the cart, "
                                            r"under the grain surface at world \(-4.65, 7.40, 1.50\) m"):
        load_scenario_text(s_text, "x.yaml", check_world=True)


def test_every_packaged_scenario_is_plausible():
    from cosim.scenario.loader import packaged_scenarios

    for name, path in packaged_scenarios().items():
        assert implausible(load_scenario(path, check_world=False)) == [], name


def test_a_segment_larger_than_dev_shm_is_refused_naming_the_largest_blocks():
    s = load_scenario(DEFAULT).model_copy(update={"renderer": "mock"})
    schema = build_schema(s, ring_specs(s))
    check_segment_fits(schema, free=(schema.total_nbytes, schema.total_nbytes))
    with pytest.raises(RunRefused, match=r"the run needs .* of shared memory, but /dev/shm has 1.0 KiB free .*"
                                         r"largest blocks: lidar_points 38400x4 600.0 KiB, "):  # 240 x 160 beams x 4 float32
        check_segment_fits(schema, free=(1024, 1 << 40))


def test_cli_validate_exits_2_with_file_line(capsys):
    from pathlib import Path

    from cosim.cli import main

    bad = Path(__file__).parent / "scenarios_bad" / "sensor_underground.yaml"
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:5:12: sensor.mount.xyz_m: the sensor is 50.00 m below the ground" in err


# ---------------------------------------------------------------------------------- the address-space limit
_UNDER_LIMIT = """
import resource, sys
if __name__ == "__main__":
    from cosim.cli import main
    from cosim.scenario.memory import CHILD_MAPPED_BYTES, room
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_MAPPED_BYTES + (128 << 20), resource.RLIM_INFINITY))
    print("address space", room().address_space, file=sys.stderr)
    sys.exit(main(["run", "default", "--set", "sensor.method=camera_rig", "--set", "render.rig=fixed",
                   "--set", "render.cameras=4", "--set", "render.width_px=4096", "--set", "render.height_px=4096",
                   "--out", sys.argv[1], "--quiet"]))
"""


def test_a_segment_beyond_the_address_space_limit_is_refused_before_anything_starts(tmp_path):
    """Under ``ulimit -v`` a 257 MiB segment fits /dev/shm and the memory, but no child could map it: refused
    (exit 2) before anything starts, not tracebacks from the children after start-up."""
    import os
    import subprocess
    import sys

    script = tmp_path / "under_limit.py"
    script.write_text(_UNDER_LIMIT)
    out = tmp_path / "run"
    r = subprocess.run([sys.executable, str(script), str(out)], capture_output=True, text=True, timeout=180,
                       env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
    assert r.returncode == 2, r.stderr
    assert "address space 134217728" in r.stderr                            # 1 GiB + 128 MiB less 1 GiB
    assert "the run needs 256.7 MiB of shared memory" in r.stderr and "128.0 MiB of address space" in r.stderr
    assert "ulimit -v" in r.stderr and "nothing was started" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()


def test_the_pattern_memory_counts_the_address_space():
    s = load_scenario(DEFAULT, check_world=False)
    beams = s.sensor.pattern.azimuth_count * s.sensor.pattern.elevation_count
    need = beams * (SHARED_BYTES_PER_BEAM + PROCESS_BYTES_PER_BEAM)
    assert memory_problems(s, free=Room(1 << 40, 1 << 40, need)) == []
    [(loc, message)] = memory_problems(s, free=Room(1 << 40, 1 << 40, need - 1))
    assert loc == ("sensor", "pattern") and "of address space for them (ulimit -v)" in message
    schema = build_schema(s.model_copy(update={"renderer": "mock"}), ring_specs(s))
    with pytest.raises(RunRefused, match=r"ulimit -v"):
        check_segment_fits(schema, free=Room(1 << 40, 1 << 40, schema.total_nbytes - 1))
    check_segment_fits(schema, free=Room(1 << 40, 1 << 40, schema.total_nbytes))


def test_a_csv_table_too_large_to_read_is_refused_unread(tmp_path, monkeypatch):
    import cosim.scenario.plausibility as plaus

    table = tmp_path / "beams.csv"
    table.write_text("elevation_deg,azimuth_deg\n" + "0.0,0.0\n" * 100)
    path = tmp_path / "s.yaml"
    path.write_text("format_version: 1\nsensor:\n  pattern: {preset: csv, csv_file: beams.csv}\n")
    monkeypatch.setattr(plaus, "MAX_CSV_BYTES", 512)
    with pytest.raises(ScenarioError, match=r"s.yaml:3:36: sensor.pattern.csv_file: the beam table is 826 B; "
                                            r"tables are limited to 512 B"):
        load_scenario(path)


def test_a_point_on_a_shared_face_is_inside_the_union_and_one_on_the_outer_face_is_not():
    """Cart frame: the front wall spans x 3.00 .. 3.08 m, the left wall y 1.50 .. 1.58 m up to x = 3.00 m."""
    def at(xyz):
        text = (f"format_version: 1\nsensor:\n  mount: {{parent: cart, xyz_m: {list(xyz)}, "
                "rpy_deg: [90.0, 60.0, 75.0]}\n")
        try:
            load_scenario_text(text, "x.yaml", check_world=True)
        except ScenarioError as e:
            return " ".join(p.message for p in e.problems)
        return ""
    assert "inside the cart's walls" in at((3.0, 1.54, 1.5))                # the shared face: inside the union
    assert "inside the cart's walls" in at((0.0, 1.54, 3.0))                # a wall's top under its rim bar
    assert "inside" not in at((3.0, 1.58, 2.5))                             # the outer edge where two walls meet
    assert "inside" not in at((3.0, 1.59, 1.5))                             # outside the walls
