"""Plug-in points (docs/plugins.md): resolution (built-in table, entry points, import paths), checks at
validation (file:line:col, exit 2, nothing started), a user's strategy picking the sections launched and in
process, a user's controller, --no-plugins and the validate inventory."""
from __future__ import annotations

import os
import subprocess
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest
import tomllib

from cosim.cli import main
from cosim.errors import ScenarioError
from cosim.runtime.inprocess import simulate
from cosim.scenario.loader import load_scenario, load_scenario_text, resolve_scenario_arg
from cosim.scenario.plugins import (
    BUILTINS,
    ENTRY_POINT_GROUPS,
    PluginError,
    distribution_of,
    load_plugin,
    resolve_plugin,
)
from dynamics_proc import closed_loop
from dynamics_proc.control.strategies import front_to_back

ROOT = Path(__file__).resolve().parent.parent

#: a strategy module that is not in the project: the middle section first, then outwards (ties to the front)
MIDDLE_OUT = '''
def middle_out(full, height, current):
    if 0 <= current < full.size and not full[current]:
        return current
    middle = (full.size - 1) / 2.0
    for i in sorted(range(full.size), key=lambda i: (abs(i - middle), i)):
        if not full[i]:
            return i
    return -1
'''
#: the 1-based sections middle_out visits with 9 sections
MIDDLE_OUT_ORDER = [5, 4, 6, 3, 7, 2, 8, 1, 9]
#: quick ideal-feedback runs that fill more than one section: the cart starts 1.6 m full (target 1.9 m)
QUICK = ["--feedback", "ground_truth", "--renderer", "none", "--duration", "40", "--set", "grain.initial_fill_m=1.6",
         "--set", "outputs.figures=false"]


def _module(tmp_path: Path, source: str, stem: str = "strat") -> str:
    """Write ``source`` as a uniquely named module in ``tmp_path``; its name."""
    name = f"{stem}_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(source)
    return name


def _sequence(targets: np.ndarray) -> list[int]:
    """The distinct sections (1-based) in the order targeted, 0 (none) left out."""
    seq: list[int] = []
    for t in targets.astype(int):
        if t and (not seq or seq[-1] != t):
            seq.append(int(t))
    return seq


def _csv_column(path: Path, column: str) -> np.ndarray:
    import csv
    with open(path, newline="") as f:
        return np.array([float(r[column]) for r in csv.DictReader(f)])


# ------------------------------------------------------------------------------------------- resolution
def test_builtin_table_is_the_packages_entry_points():
    eps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    assert {g: eps[ENTRY_POINT_GROUPS[g]] for g in BUILTINS} == BUILTINS
    for group, table in BUILTINS.items():
        for name in table:
            info = resolve_plugin(group, name)
            assert info.builtin and Path(info.file).is_relative_to(ROOT)
    assert load_plugin("strategies", "front_to_back") is front_to_back


def test_entry_point_from_an_installed_distribution(tmp_path, monkeypatch):
    name = _module(tmp_path, MIDDLE_OUT, "epmod")
    dist = tmp_path / "fillers-1.2.3.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: fillers\nVersion: 1.2.3\n")
    (dist / "entry_points.txt").write_text(f"[graincosim.strategies]\nmiddle_out = {name}:middle_out\n")
    (dist / "top_level.txt").write_text(f"{name}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    info = resolve_plugin("strategies", "middle_out")
    assert not info.builtin and info.target == f"{name}:middle_out"
    assert distribution_of(info) == ("fillers", "1.2.3")
    assert info.obj(np.zeros(9, bool), np.zeros(9), -1) == 4
    with pytest.raises(PluginError, match="'middle_out' is not built in and plug-ins are disabled"):
        resolve_plugin("strategies", "middle_out", allow_external=False)
    # an installed distribution cannot replace a built-in of the same name
    (dist / "entry_points.txt").write_text(f"[graincosim.strategies]\nfront_to_back = {name}:middle_out\n")
    assert load_plugin("strategies", "front_to_back") is front_to_back


# ----------------------------------------------------------------------------------- checks at validation
@pytest.mark.parametrize("ref, message", [
    ("no_such_mod_q7:f", r"plug-in 'no_such_mod_q7:f': no module named 'no_such_mod_q7' \(looked in"),
    ("{mod}:missing", r"plug-in '{mod}:missing': module '{mod}' has no attribute 'missing'"),
    ("{mod}:NOT_CALLABLE", r"plug-in '{mod}:NOT_CALLABLE' is not callable \(a 'int' object\)"),
    ("{mod}:two_args", r"plug-in '{mod}:two_args' has signature \(full, height\), which cannot be called as "
                       r"\(full, height, current\)"),
    ("spiral", r"unknown strategies plug-in 'spiral': not built in"),
])
def test_bad_plugin_is_a_scenario_error_and_nothing_starts(tmp_path, capsys, ref, message):
    mod = _module(tmp_path, "NOT_CALLABLE = 3\ndef two_args(full, height):\n    return 0\n")
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"format_version: 1\nrenderer: none\nfeedback: ground_truth\ncontroller:\n"
                        f"  strategy: {ref.format(mod=mod)}\n")
    out = tmp_path / "run"
    assert main(["run", str(scenario), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"{scenario}:5:13: controller.strategy: " in err
    assert __import__("re").search(message.format(mod=mod), err), err
    assert "nothing was started" in err and not out.exists()


def test_bad_plugin_given_with_set_is_reported_at_the_override(tmp_path, capsys):
    assert main(["validate", "default", "--set", "perception.stages.rim=nowhere_mod_z1:rim"]) == 2
    assert "<--set>:1:23: perception.stages.rim: plug-in 'nowhere_mod_z1:rim': no module named" in \
        capsys.readouterr().err


def test_no_plugins_refuses_external_and_validate_lists_what_loads(tmp_path, capsys):
    mod = _module(tmp_path, MIDDLE_OUT)
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"format_version: 1\ncontroller:\n  strategy: {mod}:middle_out\n")
    assert main(["validate", str(scenario), "--no-plugins"]) == 2
    assert (f"{scenario}:3:13: controller.strategy: plug-in '{mod}:middle_out' is not built in and plug-ins are "
            "disabled") in capsys.readouterr().err
    assert main(["validate", "default", "--no-plugins"]) == 0       # built-ins are always allowed
    capsys.readouterr()
    assert main(["validate", str(scenario)]) == 0
    out = capsys.readouterr().out
    assert (f"plug-in controller.strategy = {mod}:middle_out: EXTERNAL (runs its code); file "
            f"{tmp_path / (mod + '.py')}; version unknown") in out
    assert f"plug-in controller.model = section_fill: built in; file {ROOT / 'dynamics_proc' / 'control' / 'controller.py'}" in out
    with pytest.raises(ScenarioError, match="plug-ins are disabled"):
        load_scenario(scenario, allow_plugins=False)
    for verb in ("run", "compare"):
        out = tmp_path / verb
        assert main([verb, str(scenario), "--no-plugins", "--out", str(out), "--quiet"]) == 2
        assert "plug-ins are disabled" in capsys.readouterr().err and not out.exists()


def test_plugin_dir_is_the_scenario_folder_and_travels():
    s = load_scenario(resolve_scenario_arg("default"))
    assert s.plugin_dir == str(resolve_scenario_arg("default").resolve().parent)
    assert load_scenario_text("format_version: 1\nplugin_dir: sub\n", base_dir="/tmp").plugin_dir == "/tmp/sub"


# ----------------------------------------------------------------------------- a user's strategy at work
def test_strategy_on_pythonpath_picks_the_sections_launched_and_in_process(tmp_path, monkeypatch):
    mod = _module(tmp_path, MIDDLE_OUT)
    ref = f"controller.strategy={mod}:middle_out"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    out = tmp_path / "run"
    done = subprocess.run([sys.executable, "launch.py", "run", "default", *QUICK, "--set", ref, "--quiet", "--out",
                           str(out)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    launched = _sequence(_csv_column(out / "timeseries.csv", "dyn_state.target_section"))
    assert len(launched) >= 2 and launched == MIDDLE_OUT_ORDER[:len(launched)]

    monkeypatch.syspath_prepend(str(tmp_path))
    extra = {"feedback": "ground_truth", "renderer": "none", "duration_s": 40.0}
    s = load_scenario(resolve_scenario_arg("default"), ["grain.initial_fill_m=1.6", ref], extra=extra)
    series = simulate(s).recorder.series()
    assert _sequence(series["dyn_state.target_section"]) == launched
    base = simulate(s.model_copy(update={"controller": s.controller.model_copy(
        update={"strategy": "front_to_back"})})).recorder.series()
    assert _sequence(base["dyn_state.target_section"])[:2] == [1, 2]


# --------------------------------------------------------------------------- a user's controller at work
STAY_PUT = '''
import math
from dynamics_proc.control.protocol import ControllerCommand

class StayPut:
    """Never nudges; runs the auger once a measurement has arrived, on the section under the spout."""
    def __init__(self, params, scenario):
        self.p = params
    def initial_state(self):
        return 0
    def step(self, state, inp):
        seen = state + (inp.heights is not None)
        k = min(int(inp.spout_x_m / self.p.length_m * self.p.sections), self.p.sections - 1)
        return seen, ControllerCommand(0, seen > 0, inp.spout_x_m, target=k, seen=seen > 0)
'''


def test_a_controller_class_drives_the_plant(tmp_path, monkeypatch):
    mod = _module(tmp_path, STAY_PUT, "ctrl")
    monkeypatch.syspath_prepend(str(tmp_path))
    s = load_scenario_text(f"format_version: 1\nfeedback: ground_truth\nrenderer: none\nduration_s: 5.0\n"
                           f"controller:\n  model: {mod}:StayPut\n")
    r = closed_loop.simulate(s)
    ser = r.series
    assert np.all(ser["dyn_state.nudge_count"] == 0)
    assert np.all(ser["dyn_state.setpoint_long_m"] == s.machine_sync.longitudinal_offset_m)
    assert ser["dyn_state.auger_on"][:2].tolist() == [0, 0] and np.all(ser["dyn_state.auger_on"][2:] == 1)
    assert np.all(ser["dyn_state.target_section"][2:] == ser["dyn_state.target_section"][2])
    assert np.all(np.isnan(ser["dyn_state.control_effort_m"][1:]))     # not reported by this controller
    assert ser["dyn_state.delivered_m3"][-1] > 0.1


# ------------------------------------------------------------------------ the documented examples at work
def _doc_block(marker: str) -> str:
    """The ```python block of docs/plugins.md that contains ``marker``."""
    text = (ROOT / "docs" / "plugins.md").read_text()
    blocks = __import__("re").findall(r"```python\n(.*?)```", text, flags=__import__("re").S)
    found = [b for b in blocks if marker in b]
    assert len(found) == 1, marker
    return found[0]


def test_documented_controller_and_algorithm_run(tmp_path, monkeypatch, shm_clean):
    ctrl = _module(tmp_path, _doc_block("class StayPut"), "docctrl")
    algo = _module(tmp_path, _doc_block("def no_impact"), "docalgo")
    monkeypatch.syspath_prepend(str(tmp_path))
    s = load_scenario_text(f"format_version: 1\nfeedback: ground_truth\nrenderer: none\nduration_s: 3.0\n"
                           f"controller:\n  model: {ctrl}:StayPut\n")
    ser = closed_loop.simulate(s).series
    assert np.all(ser["dyn_state.nudge_count"] == 0) and np.all(ser["dyn_state.auger_on"][2:] == 1)
    s = load_scenario_text(f"format_version: 1\nrenderer: mock\nperception:\n  algorithm: {algo}:no_impact\n")
    run = simulate(s, frames=2)
    ser = run.recorder.series()
    assert np.all(ser["perc_state.cart_valid"] == 1) and np.all(ser["perc_state.impact_valid"] == 0)
    assert np.all(np.isnan(ser["perc_state.impact_gx_m"])) and np.all(ser["perc_state.coverage"] > 0.5)


def test_own_perception_example_stage_maps_the_grain(shm_clean):
    """examples/own_perception: the user's height map stage produces the map the controller acts on, within a
    few cm of the truth over most of the cart."""
    from perception_proc.accuracy.stage import heightmap_error, truth_on_grid

    s = load_scenario(ROOT / "examples" / "own_perception" / "scenario.yaml")
    assert s.perception.stages.heightmap == "cell_median:cell_median"
    run = simulate(s, frames=2)
    perceived = run.recorder.arrays["heightmap_perceived"]
    truth = truth_on_grid(run.recorder.arrays["heightmap_truth"], s.grain.cell_m, perceived.shape, s.cart)
    rmse, bias, coverage = heightmap_error(perceived, truth)
    assert coverage > 0.6 and rmse < 0.05 and abs(bias) < 0.03, (rmse, bias, coverage)
    import cell_median  # imported from the scenario's folder by the loader
    assert Path(cell_median.__file__).parent == ROOT / "examples" / "own_perception"


def test_own_strategy_example_validates_and_is_refused_without_plugins(capsys):
    path = str(ROOT / "examples" / "own_strategy" / "scenario.yaml")
    assert main(["validate", path]) == 0
    assert ("plug-in controller.strategy = middle_out:middle_out with middle=4: EXTERNAL (runs its code)"
            in capsys.readouterr().out)
    assert main(["validate", path, "--no-plugins"]) == 2
    assert "plug-ins are disabled" in capsys.readouterr().err


# ------------------------------------------------------------------------------------ plug-in options
#: a strategy with an option: the sections in ``order`` first (0-based), then front to back
ORDERED = '''
def ordered(full, height, current, *, order=()):
    if 0 <= current < full.size and not full[current]:
        return current
    for i in [*order, *range(full.size)]:
        if not full[i]:
            return i
    return -1
'''


def test_options_reach_the_plugin_launched_and_in_process(tmp_path, monkeypatch):
    mod = _module(tmp_path, ORDERED)
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"format_version: 1\ncontroller:\n  strategy: {mod}:ordered\n  strategy_options:\n"
                        "    order: [6, 2]\n")
    out = tmp_path / "run"
    assert main(["run", str(scenario), *QUICK, "--quiet", "--out", str(out)]) == 0
    launched = _sequence(_csv_column(out / "timeseries.csv", "dyn_state.target_section"))
    assert len(launched) >= 2 and launched[:2] == [7, 3]
    extra = {"feedback": "ground_truth", "renderer": "none", "duration_s": 40.0}
    s = load_scenario(scenario, ["grain.initial_fill_m=1.6", "controller.strategy_options.order=[8, 0]"], extra=extra)
    assert s.controller.strategy_options == {"order": [8, 0]} and hash(s) == hash(s.model_copy())
    assert _sequence(simulate(s).recorder.series()["dyn_state.target_section"])[:2] == [9, 1]


@pytest.mark.parametrize("yaml_tail, overrides, where, message", [
    ("  strategy: {mod}:ordered\n  strategy_options:\n    order: [1]\n    width: 2\n", [],
     "{scenario}:8:12: controller.strategy_options.width: ", r"plug-in '{mod}:ordered' takes no option 'width': .*"
                                                             r"options: order"),
    ("  target_fill_m: 1.8\n", ["controller.model_options.gain=2"], "<--set>:1:31: controller.model_options.gain: ",
     r"plug-in 'section_fill' takes no option 'gain'.*options: none"),
    ("  strategy: {mod}:ordered\n", ["perception.stages.rim_options.z=1"], "<--set>:1:33: perception.stages.rim_options.z",
     r"plug-in 'builtin' takes no option 'z'"),
    ("  strategy: {mod}:ordered\n  strategy_options: [1, 2]\n", [], "{scenario}:6:21: controller.strategy_options: ",
     r"Input should be a (valid dictionary|mapping)"),
])
def test_bad_options_are_reported_at_their_key_and_nothing_starts(tmp_path, capsys, yaml_tail, overrides, where,
                                                                  message):
    mod = _module(tmp_path, ORDERED)
    scenario = tmp_path / "s.yaml"
    scenario.write_text("format_version: 1\nrenderer: none\nfeedback: ground_truth\ncontroller:\n"
                        + yaml_tail.format(mod=mod))
    out = tmp_path / "run"
    sets = [a for o in overrides for a in ("--set", o)]
    assert main(["run", str(scenario), *sets, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert where.format(scenario=scenario) in err, err
    assert __import__("re").search(message.format(mod=mod), err), err
    assert not out.exists()


def test_load_plugin_binds_options_as_keywords(tmp_path, monkeypatch):
    mod = _module(tmp_path, ORDERED)
    monkeypatch.syspath_prepend(str(tmp_path))
    pick = load_plugin("strategies", f"{mod}:ordered", options={"order": [3]})
    assert pick(np.zeros(9, bool), np.full(9, np.nan), -1) == 3
    assert load_plugin("strategies", f"{mod}:ordered")(np.zeros(9, bool), np.full(9, np.nan), -1) == 0
    with pytest.raises(PluginError, match="takes no option 'size'"):
        load_plugin("strategies", "front_to_back", options={"size": 1})


def test_validate_lists_a_plugins_options(tmp_path, capsys):
    mod = _module(tmp_path, ORDERED)
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"format_version: 1\ncontroller:\n  strategy: {mod}:ordered\n  strategy_options:\n"
                        "    order: [4, 3]\n")
    assert main(["validate", str(scenario)]) == 0
    assert f"plug-in controller.strategy = {mod}:ordered with order=[4, 3]: EXTERNAL (runs its code)" in \
        capsys.readouterr().out


def test_own_strategy_examples_option_moves_the_start(tmp_path):
    """The example's README: --set controller.strategy_options.middle=6 fills section 7 first, then 6 and 8."""
    path = ROOT / "examples" / "own_strategy" / "scenario.yaml"
    extra = {"duration_s": 40.0}
    seqs = {}
    for middle in (4, 6):
        s = load_scenario(path, ["grain.initial_fill_m=1.6", f"controller.strategy_options.middle={middle}"],
                          extra=extra)
        seqs[middle] = _sequence(simulate(s).recorder.series()["dyn_state.target_section"])
    assert seqs[4][:2] == [5, 4] and seqs[6][:2] == [7, 6]
    with pytest.raises(ScenarioError, match="takes no option 'centre'"):
        load_scenario(path, ["controller.strategy_options.centre=3"])


def test_which_distribution_provides_a_plugin_scans_the_installed_packages_at_most_once(monkeypatch):
    """This project's built-ins are named without a scan of every installed package's metadata (seconds on a busy
    machine, once per plug-in, was most of validate's time); another's scans once per sys.path."""
    from importlib import metadata

    import cosim.scenario.plugins as plugins

    calls = []
    real = metadata.packages_distributions
    monkeypatch.setattr(plugins.metadata, "packages_distributions", lambda: calls.append(1) or real())
    plugins._packages_distributions.cache_clear()
    assert distribution_of(resolve_plugin("strategies", "front_to_back"))[0] == "graincosim"
    assert calls == []
    numpy_like = plugins.PluginInfo("strategies", "x", "numpy:ones", False, "", np.ones)
    assert distribution_of(numpy_like)[0] == "numpy" and distribution_of(numpy_like)[0] == "numpy"
    assert calls == [1]
    plugins._packages_distributions.cache_clear()
