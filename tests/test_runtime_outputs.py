"""The run directory's outputs and the in-memory view of them that the end-of-run figures are drawn from."""
from __future__ import annotations

import json

import numpy as np
import pytest

from cosim.report import load_run
from cosim.runtime.inprocess import simulate
from cosim.runtime.outputs import run_data, write_outputs, write_scenario
from cosim.runtime.stream import RunFiles
from cosim.scenario.config import Scenario


@pytest.mark.parametrize("setup", [{"feedback": "ground_truth", "renderer": "none", "duration_s": 3.0},
                                   {"feedback": "perception", "renderer": "mock", "duration_s": 0.3}])
def test_figures_see_what_the_run_directory_holds(setup, tmp_path):
    """Also with perception, whose wall-clock columns live in timing.csv beside timeseries.csv."""
    sc = Scenario.model_validate({"format_version": 1, **setup})
    run = simulate(sc)
    write_scenario(tmp_path, sc)
    summary = write_outputs(tmp_path, sc, run.recorder, run.ring, wall_time_s=run.wall_time_s, error=None)
    mem, disk = run_data(tmp_path, sc, summary, run.recorder), load_run(tmp_path)
    assert mem.scenario == disk.scenario
    assert json.dumps(mem.summary, sort_keys=True) == json.dumps(disk.summary, sort_keys=True)
    assert list(mem.series) == list(disk.series)
    for k, v in disk.series.items():
        assert mem.series[k].dtype == v.dtype and np.array_equal(mem.series[k], v, equal_nan=True), k
    assert (disk.heightmap_perceived is None) == (mem.heightmap_perceived is None) == (sc.feedback == "ground_truth")
    assert (tmp_path / "timing.csv").exists() == (sc.feedback == "perception")
    # the same rows appended in ragged blocks, as a run streams them, join up byte for byte
    streamed = tmp_path / "streamed"
    streamed.mkdir()
    files = RunFiles(streamed, run.recorder, block_s=0.0)
    for upto in (1, 2, 2, 5, 9, 17):
        files.append(min(upto, len(run.recorder.frames)))
    files.finish()
    for name in ("timeseries.csv", "timing.csv"):
        assert (streamed / name).exists() == (tmp_path / name).exists()
        if (tmp_path / name).exists():
            assert (streamed / name).read_bytes() == (tmp_path / name).read_bytes(), name
    assert mem.heightmap_truth.dtype == disk.heightmap_truth.dtype
    assert np.array_equal(mem.heightmap_truth, disk.heightmap_truth)
