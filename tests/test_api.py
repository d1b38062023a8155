"""The Python API (cosim.api): stepping reproduces simulate() and a launched run bit for bit, reset reproduces,
set() acts as Machine Sync's closed form and the controller say, errors are specific."""
from __future__ import annotations

import csv
import json
import math
import multiprocessing as mp
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from cosim import Simulation, SimulationResult, run
from cosim.errors import (
    InputNotSettable,
    InputOutOfRange,
    ParticipantCrashed,
    ScenarioError,
    SimulationClosed,
    SimulationDone,
    UnknownInput,
)
from cosim.runtime.inprocess import simulate
from cosim.scenario.options import load_with_options

#: a short perception-in-the-loop run with the mock renderer at a tenth of the rig's resolution (perception
#: overlaps: exercises the flush turn)
MOCK = {"renderer": "mock", "feedback": "perception", "duration": 1.3, "overrides": {"render.mock_scale": 0.1}}
#: a short ground-truth run without a renderer
GT = {"renderer": "none", "feedback": "ground_truth", "duration": 3.0}


def _same_series(a: dict, b: dict, start: int = 0) -> None:
    """Every column equal bit for bit from row ``start`` on, but the wall-clock ``*_ms`` ones."""
    assert a.keys() == b.keys()
    for k in (k for k in a if not k.endswith("_ms")):
        np.testing.assert_array_equal(a[k][start:], b[k][start:], err_msg=k)


def test_stepping_ten_at_a_time_equals_simulate_bit_for_bit():
    scenario = load_with_options("default", **MOCK)
    ref = simulate(scenario)
    with Simulation(scenario) as sim:
        assert sim.reset().frame == 0
        while not sim.done:
            obs = sim.step(10)
            assert obs.frame == sim.frame == min(10 * math.ceil(obs.frame / 10), sim.frames)
        res = sim.result
    assert res.completed and res.summary["frames"] == scenario.frames + 1
    _same_series(ref.recorder.series(), res.timeseries)
    for name, a in ref.recorder.arrays.items():
        np.testing.assert_array_equal(a, res.arrays[name], err_msg=name)
    assert "perc_state.frame" not in res.timeseries or res.timeseries["perc_state.frame"][-1] == scenario.frames


def test_state_is_keyed_like_the_timeseries_and_holds_the_current_frame():
    with Simulation("default", **MOCK) as sim:
        sim.reset()
        rows = {}
        for _ in range(12):
            obs = sim.step()
            rows[obs.frame] = (obs["dyn_state.t_s"], obs["dyn_state.cart_grain_m3"], np.array(obs["heightmap_truth"]))
        state = sim.state
        with pytest.raises(ValueError, match="read-only"):
            state["heightmap_truth"][0, 0] = 1.0
        with pytest.raises(KeyError, match="no value 'dyn_state.nope'"):
            state["dyn_state.nope"]
        sim.step(sim.frames)
        series = sim.result.timeseries
    struct_keys = [k for k in state if "." in k or k == "frame"]
    assert sorted(struct_keys) == sorted(series)      # timing.csv's wall-clock columns come last in series
    assert {"heightmap_truth", "stream", "heightmap_perceived"} <= set(state)
    for f, (t, grain, _h) in rows.items():
        assert t == series["dyn_state.t_s"][f] == pytest.approx(f * 0.1, abs=1e-12)
        assert grain == series["dyn_state.cart_grain_m3"][f]
    # the perception blocks of an overlapping run hold the previous frame until the flush
    assert state.stamps["dyn_state"] == 12 and state.stamps["heightmap_perceived"] == 11
    np.testing.assert_array_equal(rows[12][2], sim.result.arrays["heightmap_truth"] * 0 + rows[12][2])


def test_reset_with_the_same_seed_reproduces_and_another_seed_differs():
    noisy = {**MOCK, "overrides": {**MOCK["overrides"], "sensor.noise.range_sigma_m": 0.02}}
    with Simulation("default", **noisy) as sim:
        def first(seed):
            sim.reset(seed=seed)
            sim.step(6)
            return np.array([sim.state[k] for k in sim.state if k.startswith("perc_state.") and not k.endswith("_ms")])

        a, b, c = first(3), first(3), first(4)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c, equal_nan=True)


def test_api_run_writes_the_run_directory_of_a_launched_run(tmp_path):
    """Ground truth, no renderer: the API run's files and columns are a launched run's, the values bit-identical."""
    launched, api = tmp_path / "launched", tmp_path / "api"
    subprocess.run([sys.executable, "launch.py", "run", "default", "--renderer", "none", "--feedback",
                    "ground_truth", "--duration", "3", "--quiet", "--out", str(launched)], check=True,
                   stdout=subprocess.DEVNULL)
    res = run("default", **GT, out=api)
    assert res.run_dir == api and res.completed
    files = {p.name for p in launched.iterdir()} - {"log.txt", "run.json"}
    assert files == {p.name for p in api.iterdir()}
    assert {"scenario.yaml", "summary.json", "timeseries.csv", "heightmap_truth.npy"} <= files
    assert (launched / "scenario.yaml").read_text() == (api / "scenario.yaml").read_text()
    rows = [list(csv.reader((d / "timeseries.csv").open())) for d in (launched, api)]
    assert rows[0][0] == rows[1][0]                                     # the columns
    keep = [i for i, c in enumerate(rows[0][0]) if not c.endswith("_ms")]
    assert [[r[i] for i in keep] for r in rows[0]] == [[r[i] for i in keep] for r in rows[1]]
    np.testing.assert_array_equal(np.load(launched / "heightmap_truth.npy"), np.load(api / "heightmap_truth.npy"))
    s_l, s_a = (json.loads((d / "summary.json").read_text()) for d in (launched, api))
    assert s_l.keys() == s_a.keys()
    for k in ("fill", "spill", "mass_balance", "controller", "frames", "completed"):
        assert s_l[k] == s_a[k], k


def test_lateral_offset_change_follows_machine_sync_closed_form():
    """A 5 cm step of the lateral setpoint: the tractor's rear axle follows e' = -v psi, psi' = r,
    tau_s r' = k_h (kp_lat e / v - psi) - r (Machine Sync across the path with the steering lag, linearised)."""
    step_m = 0.05
    with Simulation("default", **{**GT, "duration": 20.0}) as sim:
        sim.reset()
        sim.step(50)
        s = sim.scenario
        lat0 = s.machine_sync.lateral_offset_m
        sim.set("machine_sync.lateral_offset_m", lat0 + step_m)
        e = []
        for _ in range(80):
            o = sim.step()
            rear_axle_y = o["dyn_state.tractor_y_m"] + s.tractor.rear_axle_x_m * math.sin(o["dyn_state.tractor_yaw_rad"])
            e.append(lat0 + step_m - (rear_axle_y - o["dyn_state.combine_y_m"]))
            assert o["dyn_state.setpoint_lat_m"] == lat0 + step_m
        series_before = sim.state
    v, kh, kp, ts = s.combine.speed_mps, s.machine_sync.heading_gain_ps, s.machine_sync.kp_lat, s.tractor.steer_tau_s
    a = np.array([[0.0, -v, 0.0], [0.0, 0.0, 1.0], [kh * kp / (v * ts), -kh / ts, -1.0 / ts]])
    t = s.timing.sensor_period_s * np.arange(1, 81)
    ref = np.array([(expm(a * ti) @ np.array([step_m, 0.0, 0.0]))[0] for ti in t])
    np.testing.assert_allclose(e, ref, atol=0.01 * step_m)
    assert abs(e[-1]) < 1e-3 * step_m
    assert series_before.frame == 130


def test_target_fill_change_changes_time_to_target_as_an_override_does():
    """Set after frame 0, a new target acts from frame 1 on: the run equals one that started with it (frame 0's
    row aside), and a lower target is reached sooner."""
    low = 1.5
    base = run("default", renderer="none", feedback="ground_truth")
    with Simulation("default", renderer="none", feedback="ground_truth") as sim:
        sim.reset()
        sim.set("controller.target_fill_m", low)
        sim.step(sim.frames)
        changed = sim.result
    started = run("default", renderer="none", feedback="ground_truth", overrides={"controller.target_fill_m": low})
    _same_series(started.timeseries, changed.timeseries, start=1)
    assert changed.timeseries["dyn_state.target_fill_m"][0] == base.scenario.controller.target_fill_m
    assert changed.summary["inputs_changed"] == [{"frame": 1, "t_s": 0.1, "path": "controller.target_fill_m",
                                                   "value": low}]
    t_base, t_low = base.summary["fill"]["time_to_target_s"], changed.summary["fill"]["time_to_target_s"]
    assert t_low == started.summary["fill"]["time_to_target_s"]
    assert math.isfinite(t_base) and t_low < t_base - 5.0


def test_a_fresh_simulations_step_n_runs_n_frames_after_frame_0():
    """README's ``sim.step(50)  # 5 s``: the implicit reset's frame 0 is not one of the n."""
    with Simulation("default", **{**GT, "duration": 6.0}) as sim:
        o = sim.step(50)
        assert o.frame == 50 and o["dyn_state.t_s"] == pytest.approx(5.0, abs=1e-12)
    with Simulation("default", **GT) as sim:
        assert sim.step().frame == 1


def test_combine_speed_change_moves_the_combine_at_the_new_speed():
    with Simulation("default", **GT) as sim:
        sim.step(10)
        x0 = sim.state["dyn_state.combine_x_m"]
        sim.set("combine.speed_mps", 3.0)
        o = sim.step(10)
    assert o["dyn_state.combine_speed_mps"] == 3.0
    assert o["dyn_state.combine_x_m"] - x0 == pytest.approx(3.0 * 1.0, abs=1e-9)


def test_errors_are_specific():
    sim = Simulation("default", **{**GT, "duration": 0.5})
    with pytest.raises(UnknownInput, match="'machine_sync.nope' is not a scenario field"):
        sim.set("machine_sync.nope", 1.0)
    with pytest.raises(InputNotSettable, match="'cart.interior_length_m' cannot change during a run"):
        sim.set("cart.interior_length_m", 6.0)
    with pytest.raises(InputOutOfRange, match=r"target_fill_m = 9.0: .*above the wall top"):
        sim.set("controller.target_fill_m", 9.0)
    with pytest.raises(InputOutOfRange, match=r"combine.speed_mps = -1.0: .*greater than or equal to 0"):
        sim.set("combine.speed_mps", -1.0)
    with pytest.raises(InputOutOfRange, match="must be finite"):
        sim.set("machine_sync.lateral_offset_m", float("nan"))
    with pytest.raises(InputOutOfRange, match="a number is needed"):
        sim.set("machine_sync.lateral_offset_m", "7")
    with pytest.raises(ValueError, match="n must be >= 1"):
        sim.step(0)
    sim.step(100)
    assert sim.done and sim.frame == sim.frames == 5
    with pytest.raises(SimulationDone, match="has run its last frame"):
        sim.step()
    with pytest.raises(SimulationDone, match="reset"):
        sim.set("combine.speed_mps", 1.0)
    assert sim.reset().frame == 0 and not sim.done
    sim.close()
    sim.close()
    with pytest.raises(SimulationClosed, match="is closed"):
        sim.step()
    with pytest.raises(SimulationClosed, match="is closed"):
        sim.reset()
    with pytest.raises(ValueError, match="only 'inprocess'"):
        Simulation("default", transport="processes")
    with pytest.raises(ScenarioError, match="no such scenario"):
        Simulation("no_such_scenario")
    with pytest.raises(ScenarioError, match="timing.sensor_period_s"):
        Simulation("default", set=["timing.sensor_period_s=-1"])


def test_a_participant_fault_ends_the_run_named_and_writes_the_outputs(tmp_path, monkeypatch):
    import dynamics_proc.participant as dp

    real = dp.step_frame

    def failing(w, meas, p):
        if w.frame == 6:
            raise FloatingPointError("bad state")
        return real(w, meas, p)

    monkeypatch.setattr(dp, "step_frame", failing)
    sim = Simulation("default", **GT, out=tmp_path)
    sim.step(3)
    with pytest.raises(ParticipantCrashed, match="dynamics raised FloatingPointError at frame 7: bad state") as ei:
        sim.step(10)
    assert ei.value.process == "dynamics" and ei.value.frame == 7
    assert sim.done and sim.frame == 6
    with pytest.raises(SimulationDone, match="stopped on an error"):
        sim.step()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["completed"] is False and summary["frames"] == 7
    assert summary["error"]["process"] == "dynamics"
    assert len((tmp_path / "timeseries.csv").read_text().splitlines()) == 1 + 7
    sim.close()


def _pool_job(seed: int) -> tuple[bool, int, float]:
    res = run("default", **{**MOCK, "duration": 1.0}, seed=seed)
    return res.completed, res.summary["frames"], float(res.timeseries["dyn_state.t_s"][-1])


def test_runs_inside_a_daemonic_pool_worker():
    with mp.get_context("spawn").Pool(1) as pool:
        assert pool.map(_pool_job, [1]) == [(True, 11, 1.0)]


def test_importing_cosim_modules_does_not_import_the_api():
    code = ("import sys, cosim, cosim.runtime.child, cosim.runtime.launcher, dynamics_proc.participant; "
            "assert 'cosim.api' not in sys.modules and 'cosim.runtime.state' not in sys.modules; "
            "from cosim import Simulation; assert 'cosim.api' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_result_type():
    res = run("default", **{**GT, "duration": 0.3})
    assert isinstance(res, SimulationResult) and res.run_dir is None and res.error is None
    assert len(res.timeseries["frame"]) == 4 and res.arrays["heightmap_truth"].ndim == 2


def _python_blocks(path, after: str = ""):
    text = (REPO / path).read_text()
    text = text[text.index(after):] if after else text
    return [b.split("```", 1)[0] for b in text.split("```python\n")[1:]]


REPO = __import__("pathlib").Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("path,after", [("README.md", "## Python API"), ("docs/api.md", "")])
def test_documented_examples_run(path, after, tmp_path, monkeypatch):
    """The first Python block of the README's API section and of docs/api.md run as written."""
    monkeypatch.chdir(tmp_path)
    code = _python_blocks(path, after)[0]
    exec(compile(code, f"{path} (first python block)", "exec"), {})
    assert any((tmp_path / "runs").iterdir())


@pytest.mark.slow
def test_runs_inside_a_dask_worker():
    """A Dask worker process is daemonic, so nothing in the run may spawn (start-up of the cluster: ~5 s)."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as c, \
            distributed.Client(c) as client:
        res = client.submit(run, "default", renderer="mock", feedback="perception", duration=1.0, seed=2).result()
    assert res.completed and len(res.timeseries["frame"]) == 11 and res.error is None


def test_inputs_lists_what_set_accepts():
    with Simulation("default", **GT) as sim:
        assert sim.inputs == ("machine_sync.longitudinal_offset_m", "machine_sync.lateral_offset_m",
                              "combine.speed_mps", "controller.target_fill_m")
        assert sim.frame == 0


def test_record_writes_an_mcap_recording_of_every_frame(tmp_path):
    from cosim.recording.reader import read_recording

    with pytest.raises(ValueError, match="record= needs out="):
        Simulation("default", **GT, record=True)
    res = run("default", **{**GT, "duration": 1.0}, out=tmp_path, record=True)
    rec = read_recording(tmp_path / "recording.mcap")
    assert rec.frames == list(range(11)) and not rec.truncated
    assert res.summary["frames"] == 11


def test_allow_plugins_false_refuses_a_scenario_that_names_a_plug_in():
    from cosim.errors import ScenarioError

    path = Path(__file__).resolve().parents[1] / "examples" / "own_strategy" / "scenario.yaml"
    with pytest.raises(ScenarioError, match="controller.strategy"):
        Simulation(path, allow_plugins=False)
    with pytest.raises(ScenarioError, match="controller.strategy"):
        Simulation("default", overrides={"controller.strategy": "json:dumps"}, allow_plugins=False)


NO_GUARD = """
import sys
sys.path[:0] = [{root!r}]
import cosim
from cosim.recording.reader import read_recording
from cosim.runtime.launcher import launch
from cosim.scenario.options import load_with_options

res = cosim.run("default", renderer="none", feedback="ground_truth", duration=1.0, out={out!r}, record=True)
print("api", res.completed, res.error, read_recording({out!r} + "/recording.mcap").frames == list(range(11)))
launched = launch(load_with_options("default", renderer="mock", duration=0.5), {out!r} + "-launched",
                  console_log=False)
print("launch", launched.completed, launched.error)
"""


def test_a_plain_script_without_a_main_guard_runs_and_records(tmp_path):
    """The run's processes (ring children, the recorder) never run the user's script again (spawning.py): a script
    without ``if __name__ == "__main__":`` records, and launches, as one with it."""
    script = tmp_path / "plain.py"
    script.write_text(NO_GUARD.format(root=str(Path(__file__).resolve().parents[1]), out=str(tmp_path / "run")))
    r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.splitlines() == ["api True None True", "launch True None"], r.stdout + r.stderr[-3000:]
    assert "Traceback" not in r.stderr


def test_a_recording_asked_for_and_not_written_is_the_results_error(tmp_path):
    from cosim.errors import RecordingFailed

    (tmp_path / "a_folder.mcap").mkdir()  # the recorder cannot open it as a file
    res = run("default", **{**GT, "duration": 1.0}, out=tmp_path / "run", record=tmp_path / "a_folder.mcap")
    assert isinstance(res.error, RecordingFailed) and not res.completed
    assert f"recording {tmp_path / 'a_folder.mcap'} is incomplete: " in str(res.error)
    assert res.error.process == "recorder"
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["error"]["type"] == "RecordingFailed"
    assert summary["frames"] == summary["frames_planned"] == 11  # the simulation itself ran to its end
