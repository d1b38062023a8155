"""The world exported as an FMU (``launch.py export-fmu``, docs/fmu.md "Export"): the externally driven grain model
against the built-in one, the FMU's description and fmpy's validation, its stepping contract, FMI 3.0, GL, and
what an export refuses. The closed loop with a foreign master is tests/test_fmu_master.py."""
from __future__ import annotations

import math
import zipfile
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import yaml

from cosim.cli import main
from cosim.scenario.loader import load_scenario
from cosim.scenario.options import load_with_options
from dynamics_proc.fmu.external import WorldInputs, grain_params, initial_grain, initial_inputs, step_grain
from dynamics_proc.model import ModelParams, initial_world, signals, step_frame, truth_measurement

fmpy = pytest.importorskip("fmpy", reason="FMU tests need fmpy (pip install -e \".[test]\")")
pytest.importorskip("pythonfmu", reason="the export needs pythonfmu (pip install -e \".[test]\")")

from fmpy.model_description import read_model_description  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "examples" / "simulink_master" / "scenario.yaml"
PERIOD_S = 0.1
#: perception of a flat, level fill against the truth: the section peaks of the perceived map (mock renderer,
#: exact ray cast, codec quantisation ~2 mm) within 2 cm; the perceived cart pose within 5 cm and 1 degree
PERCEIVED_HEIGHT_TOL_M, CART_POS_TOL_M, CART_YAW_TOL_RAD = 0.02, 0.05, math.radians(1.0)


def _inputs(sig: dict, flow_m3ps: float) -> WorldInputs:
    names = {f.name for f in fields(WorldInputs)} - {"auger_on", "flow_m3ps"}
    return WorldInputs(**{n: sig[n] for n in names}, auger_on=bool(sig["auger_on"]), flow_m3ps=flow_m3ps)


def test_external_grain_is_the_builtin_grain_model():
    """Given the built-in run's frame-end poses, spout and the volume each frame delivered (as a flow over the
    frame), the externally driven grain model deposits the same grain at the same impact: heights, spill and impact
    agree to round-off over a 40 s fill of several sections."""
    s = load_with_options(SCENARIO, feedback="ground_truth", renderer="none", duration=40.0)
    p = ModelParams.from_scenario(s)
    w = initial_world(s, p)
    ext = initial_grain(s, _inputs(signals(w, p), 0.0))
    q = grain_params(s)
    np.testing.assert_array_equal(ext.heights, w.heights)
    history = {}
    for m in range(1, s.frames + 1):
        history[m - 1] = truth_measurement(w.heights, p)
        nxt = step_frame(w, history.get(m - 1 - s.timing.latency_frames), p)
        ext = step_grain(ext, _inputs(signals(nxt, p), (nxt.delivered_m3 - w.delivered_m3) / PERIOD_S), q)
        w = nxt
        assert np.max(np.abs(ext.heights - w.heights)) < 1e-9, m
        assert ext.impact.surface == w.impact.surface
        np.testing.assert_allclose(ext.impact.grid, w.impact.grid, atol=1e-9)
    assert w.delivered_m3 > 2.0 and w.nudges >= 10                  # the fill, section by section
    assert ext.delivered_m3 == pytest.approx(w.delivered_m3, abs=1e-12)
    assert ext.spilled_m3 == pytest.approx(w.spilled_m3, abs=1e-12)


@pytest.fixture(scope="module")
def world_fmu(tmp_path_factory) -> Path:
    """The example scenario exported with the documented command (FMI 2.0, mock renderer)."""
    out = tmp_path_factory.mktemp("export") / "GrainWorld.fmu"
    assert main(["export-fmu", str(SCENARIO), "--out", str(out)]) == 0
    return out


def test_exported_fmu_passes_fmpy_validation_and_declares_the_contract(world_fmu):
    assert validate_fmu(str(world_fmu)) == []
    md = read_model_description(str(world_fmu))
    assert md.fmiVersion == "2.0" and md.coSimulation is not None and md.modelExchange is None
    assert md.coSimulation.modelIdentifier == "GrainWorld" and md.coSimulation.needsExecutionTool
    assert not md.coSimulation.canHandleVariableCommunicationStepSize
    assert float(md.defaultExperiment.stepSize) == PERIOD_S
    ins = {v.name: v for v in md.modelVariables if v.causality == "input"}
    outs = {v.name for v in md.modelVariables if v.causality == "output"}
    assert list(ins) == [f.name for f in fields(WorldInputs)] and ins["auger_on"].type == "Boolean"
    start = initial_inputs(load_scenario(SCENARIO))              # the scenario's t = 0 scene, auger off
    for f in fields(WorldInputs):
        assert float(ins[f.name].start == "true" if f.name == "auger_on" else ins[f.name].start) == pytest.approx(
            float(getattr(start, f.name)), abs=1e-12), f.name
    for name in ("perceived_height_m", "perceived_fullness", "true_height_m", "true_fullness", "true_mean_height_m"):
        assert {f"{name}[{k}]" for k in range(1, 10)} <= outs
    assert {"perceived_cart_x_m", "perceived_impact_gx_m", "coverage", "true_impact_gx_m", "spilled_m3"} <= outs
    with zipfile.ZipFile(world_fmu) as zf:
        carried = yaml.safe_load(zf.read("resources/scenario.yaml"))
    assert (carried["feedback"], carried["renderer"], carried["timing"]["schedule"]) == (
        "perception", "mock", "sequential")
    assert carried["vehicles"]["tractor_cart"]["fmu"] is None and carried["grain"]["initial_fill_m"] == 1.5


class _Driven:
    """The exported FMU instantiated with fmpy (FMI 2.0), initialised; names -> value references."""

    def __init__(self, path: Path):
        from fmpy.fmi2 import FMU2Slave

        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.dir = fmpy.extract(str(path))
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="world")
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def real(self, *names):
        return self.fmu.getReal([self.vr[n] for n in names])

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def test_frame_zero_perceives_the_start_scene_and_steps_are_one_frame(world_fmu):
    """After initialisation the outputs describe frame 0 (the start values' scene): perception found the cart where
    it stands and the flat 1.5 m fill. Each doStep is one frame, the inputs held: a flow of 0.1 m^3/s for 5 frames
    delivers 0.05 m^3, all of it into the cart. A step of another size, or from another time, is refused."""
    w = _Driven(world_fmu)
    try:
        start = {v.name: float(v.start) for v in w.md.modelVariables if v.causality == "input" and v.type == "Real"}
        assert w.fmu.getInteger([w.vr["frame"]]) == [0] and w.fmu.getBoolean([w.vr["perceived_cart_valid"]]) == [1]
        x, y, yaw = w.real("perceived_cart_x_m", "perceived_cart_y_m", "perceived_cart_yaw_rad")
        assert math.hypot(x - start["cart_x_m"], y - start["cart_y_m"]) < CART_POS_TOL_M
        assert abs(yaw - start["cart_yaw_rad"]) < CART_YAW_TOL_RAD
        truth = w.real(*(f"true_height_m[{k}]" for k in range(1, 10)))
        seen = w.real(*(f"perceived_height_m[{k}]" for k in range(1, 10)))
        assert truth == [1.5] * 9
        assert np.max(np.abs(np.array(seen) - 1.5)) < PERCEIVED_HEIGHT_TOL_M
        w.fmu.setReal([w.vr["flow_m3ps"]], [0.1])
        w.fmu.setBoolean([w.vr["auger_on"]], [True])
        for k in range(5):
            w.fmu.doStep(k * PERIOD_S, PERIOD_S)
        assert w.fmu.getInteger([w.vr["frame"]]) == [5]
        delivered, in_cart, spilled = w.real("delivered_m3", "in_cart_m3", "spilled_m3")
        assert delivered == pytest.approx(0.05, abs=1e-15) and in_cart == pytest.approx(0.05, abs=1e-12)
        assert spilled == 0.0 and w.real("peak_height_m")[0] > 1.5
        with pytest.raises(fmpy.fmi1.FMICallException, match="fmi2DoStep failed"):
            w.fmu.doStep(0.5, 0.05)                              # half a frame
        with pytest.raises(fmpy.fmi1.FMICallException, match="fmi2DoStep failed"):
            w.fmu.doStep(0.7, PERIOD_S)                          # the world stands at 0.5 s
        w.fmu.doStep(0.5, PERIOD_S)                              # still good after a refusal
        assert w.fmu.getInteger([w.vr["frame"]]) == [6]
    finally:
        w.close()


def test_fmi3_export_has_arrays_and_passes_validation(tmp_path):
    pytest.importorskip("pythonfmu3", reason="the FMI 3.0 export needs pythonfmu3 (pip install -e \".[test]\")")
    from fmpy.fmi3 import FMU3Slave

    out = tmp_path / "World3.fmu"
    assert main(["export-fmu", "default", "--fmi", "3", "--out", str(out)]) == 0       # default: 1.0 m of grain
    assert validate_fmu(str(out)) == []
    md = read_model_description(str(out))
    var = {v.name: v for v in md.modelVariables}
    assert md.fmiVersion == "3.0" and var["perceived_height_m"].shape == (9,) and var["frame"].type == "Int32"
    d = fmpy.extract(str(out))
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="world")
    fmu.instantiate()
    try:
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        assert fmu.getFloat64([var["true_height_m"].valueReference], 9) == [1.0] * 9
        fmu.setFloat64([var["flow_m3ps"].valueReference], [0.1])
        fmu.doStep(0.0, PERIOD_S)
        assert fmu.getFloat64([var["delivered_m3"].valueReference]) == [pytest.approx(0.01, abs=1e-15)]
        with pytest.raises(fmpy.fmi1.FMICallException, match="fmi3DoStep failed with status 3"):
            fmu.doStep(PERIOD_S, 2 * PERIOD_S)
        fmu.terminate()
    finally:
        fmu.freeInstance()


def test_gl_export_sees_what_the_mock_sees(world_fmu, tmp_path, ctx):
    """Where a GL context can be made (``ctx`` skips otherwise), ``--renderer gl`` renders the same scene: frame 0's
    perceived section heights within 1 cm of the mock renderer's."""
    out = tmp_path / "WorldGL.fmu"
    assert main(["export-fmu", str(SCENARIO), "--renderer", "gl", "--out", str(out)]) == 0
    names = [f"perceived_height_m[{k}]" for k in range(1, 10)]
    gl, mock = _Driven(out), _Driven(world_fmu)
    try:
        np.testing.assert_allclose(gl.real(*names), mock.real(*names), atol=0.01)
    finally:
        gl.close()
        mock.close()


def test_what_an_export_refuses(tmp_path, capsys):
    (tmp_path / "s.yaml").write_text("format_version: 1\nperception:\n  algorithm: my_mod:perceive\n")
    (tmp_path / "my_mod.py").write_text("def perceive(*a, **k):\n    return None\n")
    assert main(["export-fmu", str(tmp_path / "s.yaml"), "--out", str(tmp_path / "x.fmu")]) == 2
    err = capsys.readouterr().err
    assert "export-fmu: perception.algorithm = 'my_mod:perceive': an exported FMU carries the scenario's files but " \
           "not its Python modules" in err, err
    assert main(["export-fmu", "default", "--renderer", "none", "--out", str(tmp_path / "x.fmu")]) == 2
    assert "renderer: feedback 'perception' needs a renderer ('gl' or 'mock'), not 'none'" in capsys.readouterr().err
    assert main(["export-fmu", "default", "--out", str(tmp_path / "x.fmu"), "--set", "terrain.grade_pct=5"]) == 2
    assert "export-fmu: the world driven from outside stands on flat ground" in capsys.readouterr().err
    assert main(["export-fmu", "default", "--out", str(tmp_path / "x.fmu"), "--set", "timing.sensor_period_s=-1"]) == 2
    assert not (tmp_path / "x.fmu").exists()
