"""The run directory's rules (cosim/runtime/rundir.py): only the last level of --out is created unless --parents;
a reused --out of a finished run is refused unless --overwrite, which removes that run's own files and nothing
else; a user's file a run would replace is never touched."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.recording import DEFAULT_NAME
from cosim.report.figures import RUN_FIGURES
from cosim.runtime.outputs import SAVED_MAPS
from cosim.runtime.rundir import RUN_FILES, RunDirError, open_run_dir

ROOT = Path(__file__).resolve().parent.parent
GT = ["run", "default", "--renderer", "none", "--feedback", "ground_truth", "--quiet"]
PERCEPTION = ["run", "default", "--renderer", "mock", "--feedback", "perception", "--quiet"]


def test_only_the_last_level_of_out_is_created_unless_parents(tmp_path, capsys):
    out = tmp_path / "missing" / "deeper" / "run"
    assert main([*GT, "--duration", "0.2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert (f"--out {out}: its parent folder {out.parent} does not exist; create it, or add --parents" in err
            and "nothing was started" in err and "Traceback" not in err)
    assert not (tmp_path / "missing").exists()
    assert main([*GT, "--duration", "0.2", "--out", str(out), "--parents"]) == 0
    assert json.loads((out / "summary.json").read_text())["completed"] is True
    sweep = tmp_path / "nowhere" / "sweep"
    assert main(["sweep", str(ROOT / "docs" / "examples" / "strategies_sweep.yaml"), "--out", str(sweep), "--quiet"]) == 2
    assert "its parent folder" in capsys.readouterr().err and not (tmp_path / "nowhere").exists()


def test_a_reused_out_is_refused_unless_overwrite_which_clears_only_the_runs_files(tmp_path, capsys):
    out = tmp_path / "run"
    assert main([*PERCEPTION, "--duration", "0.3", "--out", str(out)]) == 0
    assert (out / "heightmap_perceived.npy").exists()
    (out / "notes.txt").write_text("mine")
    (out / "plots").mkdir()
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    capsys.readouterr()
    assert main([*GT, "--duration", "0.2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--out {out}: holds a run of 'default' (completed, " in err and "add --overwrite" in err
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before  # nothing touched
    assert main([*GT, "--duration", "0.2", "--out", str(out), "--overwrite"]) == 0
    names = {p.name for p in out.iterdir()}
    assert "heightmap_perceived.npy" not in names  # the earlier run's map does not mix with this run's
    assert {"notes.txt", "plots"} <= names and (out / "notes.txt").read_text() == "mine"
    log = (out / "log.txt").read_text()
    assert log.count("segment cosim-") == 1 and "cosim-renderer" not in log  # the ground-truth run's log alone
    assert json.loads((out / "summary.json").read_text())["feedback"] == "ground_truth"


def test_a_users_file_a_run_would_replace_is_never_touched(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "scenario.yaml").write_text("my scenario\n")
    for overwrite in (False, True):
        with pytest.raises(RunDirError, match=r"holds scenario.yaml, which a run would replace, but no earlier run"):
            open_run_dir(out, overwrite=overwrite)
    assert (out / "scenario.yaml").read_text() == "my scenario\n" and not (out / ".lock").exists()


def test_run_files_name_every_file_a_run_writes(tmp_path):
    """--overwrite removes RUN_FILES: the list must name every output (a new one joins it)."""
    assert {f"{name}.npy" for name in SAVED_MAPS} | {f"{stem}.png" for stem in RUN_FIGURES} | {DEFAULT_NAME} <= set(RUN_FILES)
    out = tmp_path / "run"
    assert main([*PERCEPTION, "--duration", "0.3", "--out", str(out), "--record"]) == 0
    written = {p.name for p in out.iterdir()}
    assert written - set(RUN_FILES) == set(), written - set(RUN_FILES)
    assert {"summary.json", "timeseries.csv", "fig7_fullness.png", DEFAULT_NAME} <= written
