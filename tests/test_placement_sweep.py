"""The camera placement study's sweep files and table (docs/placement.md): 24 placements over 3 profiles, the CI
file the same placements on short runs, and the table read from a sweep directory."""
from __future__ import annotations

import csv
import importlib.util
import json
from pathlib import Path

import numpy as np

from cosim.studies.sweepfile import load_sweep

HERE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "placement"


def _table_module():
    spec = importlib.util.spec_from_file_location("placement_table", HERE / "table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_study_has_24_placements_over_3_profiles_and_ci_runs_the_same_ones_short():
    full, ci = load_sweep(HERE / "placement_sweep.yaml"), load_sweep(HERE / "placement_ci_sweep.yaml")
    assert len(full.runs) == len(ci.runs) == 24
    profiles = {r.scenario.sensors["cam"].profile for r in full.runs}
    assert profiles == {"multisense_s21b", "oak_d", "kinect_class_structured_light"}   # tof_kinect_class, renamed
    mounts = {(r.scenario.sensors["cam"].mount.xyz_m, r.scenario.sensors["cam"].mount.rpy_deg) for r in full.runs}
    assert len(mounts) == 8
    assert {r.scenario.duration_s for r in full.runs} == {120.0} and {r.scenario.duration_s for r in ci.runs} == {0.6}
    assert [r.scenario.sensors for r in full.runs] == [r.scenario.sensors for r in ci.runs]


def test_the_table_reads_each_runs_summary(tmp_path):
    run = tmp_path / "runs" / "a"
    run.mkdir(parents=True)
    np.save(run / "heightmap_perceived.npy", np.zeros((20, 10), np.float32))
    (run / "summary.json").write_text(json.dumps({
        "timing_ms": {"frame": 250.0},
        "perception": {"fitness": {"height_sigma_m": 0.0175},
                       "sensors": {"cam": {"measure_ms": 140.0, "fill_height": {"mean_rel_error": 0.007,
                                                                                 "cells": 50.0}}}}}))
    with (tmp_path / "results.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, ["base", "sensors.cam.mount.xyz_m", "sensors.cam.mount.rpy_deg", "outcome",
                               "outcome_reason", "completed", "run_dir"])
        w.writeheader()
        w.writerow({"base": "base_s21b.yaml", "sensors.cam.mount.xyz_m": "[-2.0, 7.45, 6.0]",
                    "sensors.cam.mount.rpy_deg": "[0.0, 90.0, -90.0]", "outcome": "filled", "outcome_reason": "",
                    "completed": "True", "run_dir": "runs/a"})
    mod = _table_module()
    (row,) = mod.rows(tmp_path)
    assert row["profile"] == "s21b" and row["outcome"] == "filled"
    assert abs(row["fill-height error %"] - 0.7) < 1e-9 and row["cart seen %"] == 25.0
    assert abs(row["expected sigma cm"] - 1.75) < 1e-9 and row["frame ms"] == 250.0
    assert "| s21b |" in mod.markdown([row])
    assert mod.main([str(tmp_path)]) == 0 and (tmp_path / "placement.png").stat().st_size > 0


def _documented_sweeps() -> list[tuple[str, str]]:
    """(sweep file, table directory) of every ``python launch.py sweep`` command in docs/placement.md and
    .ci/run."""
    root = HERE.parents[2]
    lines = (root / "docs" / "placement.md").read_text().splitlines() + (root / ".ci" / "run").read_text().splitlines()
    return [(ln.split()[ln.split().index("sweep") + 1], ln) for ln in lines
            if "launch.py sweep docs/examples/placement/" in ln]


def test_the_documented_sweep_commands_parse_and_their_files_validate():
    """Every placement sweep command in the docs and in CI: the CLI parses it and its file validates (runs, bases,
    keys); CI runs the smoke file, two profiles on the spout for 0.4 s."""
    import shlex

    from cosim.cli import build_parser

    root = HERE.parents[2]
    found = _documented_sweeps()
    assert {Path(f).name for f, _ in found} >= {"placement_sweep.yaml", "placement_ci_sweep.yaml",
                                                 "placement_smoke_sweep.yaml"}
    for file, line in found:
        argv = shlex.split(line.split("#")[0].replace('"${TMPDIR:-/tmp}', '"/tmp'))
        args = build_parser().parse_args(argv[argv.index("launch.py") + 1:])
        assert args.verb == "sweep" and str(args.file) == file
        assert load_sweep(root / file).runs, file
    ci = [f for f, ln in found if "cosim-ci" in ln]
    assert ci == ["docs/examples/placement/placement_smoke_sweep.yaml"]
    smoke = load_sweep(root / ci[0])
    assert len(smoke.runs) == 2 and {r.scenario.duration_s for r in smoke.runs} == {0.4}


def test_the_pile_height_by_the_studys_definition_adds_the_floors_error():
    """docs/examples/placement/pile_height.py: a nadir camera 5 m above the floor, grain at 1 m; the floor measured
    1 cm too far and the surface 1 cm too near: the study's h (floor minus surface, both measured) errs by 2 cm,
    2 %; ours (the floor known) by 1 %. Pixels whose exact ray misses the floor or the grain are no key points."""
    from types import SimpleNamespace

    spec = importlib.util.spec_from_file_location("pile_height", HERE / "pile_height.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    from cosim.scenario.config import Cart
    from cosim.scenario.config.cameras import StereoCamera

    cart = Cart()
    cam = StereoCamera(kind="stereo_camera", mount={"parent": "world", "xyz_m": [0.0, 0.0, cart.floor_height_m + 5.0],
                                                    "rpy_deg": [0.0, 90.0, 0.0]})
    sc, pipe = SimpleNamespace(cart=cart), SimpleNamespace(spec=cam)
    zf_exact = np.array([5.0, 5.0, 5.0, 2.0])              # the last pixel meets something above the cart
    zs_exact = np.array([4.0, 4.0, 4.0, 2.0])
    empty = (sc, pipe, {}, zf_exact + 0.01, zf_exact)
    loaded = (sc, pipe, {}, zs_exact - 0.01, zs_exact)
    r = mod.pile_errors(empty, loaded, 1.0)
    assert r["key points"] == 3
    assert abs(r["study %"] - 2.0) < 1e-6 and abs(r["project %"] - 1.0) < 1e-6
