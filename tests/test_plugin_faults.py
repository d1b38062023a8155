"""Plug-in run-time faults (docs/plugins.md): a plug-in that raises or returns a bad value ends the run cleanly
with the plug-in, the frame and the cause named; a launched run exits 1 with that message."""
from __future__ import annotations

import re
import uuid
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import PluginFault
from cosim.runtime.inprocess import simulate
from cosim.scenario.loader import load_scenario_text
from dynamics_proc import closed_loop

FAULTY = '''
import math
import numpy as np
from dataclasses import replace
from dynamics_proc.control.protocol import ControllerCommand
from perception_proc.staged import heightmap_stage, impact_stage

calls = 0

def raises_on_third_call(full, height, current):
    global calls
    calls += 1
    if calls == 3:
        raise RuntimeError("boom on call 3")
    return 0

def section_99(full, height, current):
    return 99

class Bad:
    """A controller returning the command ``KIND`` breaks."""
    KIND = ""
    def __init__(self, params, scenario):
        self.n = params.sections
    def initial_state(self):
        return None
    def step(self, state, inp):
        good = ControllerCommand(0, False, 1.0)
        return {"nan_desired": (None, replace(good, desired_m=math.nan)),
                "nudge_2": (None, replace(good, nudge=2)),
                "fullness_shape": (None, replace(good, fullness=np.zeros(self.n + 1))),
                "not_a_pair": good}[self.KIND]

def nan_desired(params, scenario):
    c = Bad(params, scenario); c.KIND = "nan_desired"; return c

def nudge_2(params, scenario):
    c = Bad(params, scenario); c.KIND = "nudge_2"; return c

def fullness_shape(params, scenario):
    c = Bad(params, scenario); c.KIND = "fullness_shape"; return c

def not_a_pair(params, scenario):
    c = Bad(params, scenario); c.KIND = "not_a_pair"; return c

def wrong_shape(ctx, inp, cart):
    hm = heightmap_stage(ctx, inp, cart)
    return replace(hm, heights=np.zeros((3, 4), np.float32))

def infinite_heights(ctx, inp, cart):
    hm = heightmap_stage(ctx, inp, cart)
    hm.heights[0, 0] = np.inf
    return hm

def nan_impact(ctx, inp, cart, hm):
    imp = impact_stage(ctx, inp, cart, hm)
    return replace(imp, valid=True, xyz=np.array([1.0, 1.0, np.nan]))

def algorithm_raises_at_frame_2(ctx, inp):
    if inp.frame == 2:
        raise ValueError("no cart today")
    from perception_proc.staged import staged
    return staged(ctx, inp)

def algorithm_wrong_type(ctx, inp):
    return {"cart": None}
'''


@pytest.fixture
def faulty(tmp_path) -> tuple[Path, str]:
    """(folder, module name) of the faulty plug-ins, a fresh module per test."""
    name = f"faulty_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(FAULTY)
    return tmp_path, name


def _scenario(folder: Path, body: str) -> Path:
    path = folder / "s.yaml"
    path.write_text("format_version: 1\n" + body)
    return path


# ------------------------------------------------------------------------------------- launched: exit 1
@pytest.mark.parametrize("fn, frame, cause", [
    ("raises_on_third_call", 4, "raised RuntimeError: boom on call 3"),
    ("section_99", 2, "returned 99; a strategy returns a section index in 0..8, or -1 when every section is full"),
])
def test_launched_strategy_fault_exits_1_naming_plugin_and_frame(faulty, capsys, shm_clean, fn, frame, cause):
    folder, mod = faulty        # beside the scenario, not on sys.path: the children find it through plugin_dir
    path = _scenario(folder, f"feedback: ground_truth\nrenderer: none\nduration_s: 1.0\noutputs:\n  figures: false\n"
                     f"controller:\n  strategy: {mod}:{fn}\n")
    assert main(["run", str(path), "--out", str(folder / "run"), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert (f"error: dynamics raised PluginFault at frame {frame}: plug-in controller.strategy = '{mod}:{fn}' at "
            f"frame {frame}: {cause}") in out
    assert "completed: False" in out


def test_launched_perception_stage_fault_exits_1(faulty, capsys, shm_clean):
    folder, mod = faulty
    path = _scenario(folder, f"renderer: mock\nduration_s: 0.3\noutputs:\n  figures: false\n"
                     f"perception:\n  stages:\n    heightmap: {mod}:wrong_shape\n")
    assert main(["run", str(path), "--out", str(folder / "run"), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert re.search(rf"error: perception raised PluginFault at frame 0: plug-in perception.stages.heightmap = "
                     rf"'{mod}:wrong_shape' at frame 0: height map heights must be a \(60, 30\) float array \(the "
                     rf"controller grid\), got \(3, 4\) float32", out), out


# ----------------------------------------------------------------------------------- in process: raises
@pytest.mark.parametrize("fn, cause", [
    ("nan_desired", "desired_m must be a finite number (m), got nan"),
    ("nudge_2", "nudge must be -1, 0 or +1, got 2"),
    ("fullness_shape", "fullness must be a (9,) float64 array, got (10,) float64"),
    ("not_a_pair", "step returned ControllerCommand, expected (state, ControllerCommand)"),
])
def test_controller_bad_command_names_plugin_and_frame(faulty, monkeypatch, fn, cause):
    folder, mod = faulty
    monkeypatch.syspath_prepend(str(folder))
    s = load_scenario_text(f"format_version: 1\nfeedback: ground_truth\nrenderer: none\nduration_s: 1.0\n"
                           f"controller:\n  model: {mod}:{fn}\n")
    with pytest.raises(PluginFault, match=re.escape(f"plug-in controller.model = '{mod}:{fn}' at frame 1: {cause}")):
        closed_loop.simulate(s)


@pytest.mark.parametrize("key, fn, frame, cause", [
    ("stages:\n    heightmap", "infinite_heights", 0,
     "height map has infinite heights (NaN marks a cell without an answer)"),
    ("stages:\n    impact", "nan_impact", 0, "a valid impact needs a finite (3,) point"),
    ("algorithm", "algorithm_raises_at_frame_2", 2, "raised ValueError: no cart today"),
    ("algorithm", "algorithm_wrong_type", 0, "returned dict, expected PerceptionOutput"),
])
def test_perception_fault_in_process_names_plugin_and_frame(faulty, monkeypatch, shm_clean, key, fn, frame, cause):
    folder, mod = faulty
    s = load_scenario_text(f"format_version: 1\nrenderer: mock\nperception:\n  {key}: {mod}:{fn}\n",
                           base_dir=folder)
    point = "perception." + key.replace(":\n    ", ".")
    with pytest.raises(PluginFault, match=re.escape(f"plug-in {point} = '{mod}:{fn}' at frame {frame}: {cause}")):
        simulate(s, frames=3)
