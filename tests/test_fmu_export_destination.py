"""Where ``export-fmu --out`` writes (cosim/fmi/export/destination.py): checked before anything is built, written
atomically, the file written named, a control byte in ``--out`` never echoed raw, and an FMU named like a Python
module (gc.fmu, json.fmu, time.fmu) that still loads and steps in fmpy."""
from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import OutputError
from cosim.fmi.export.destination import DestinationError, fmu_destination, shown, write_atomically

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "examples" / "simulink_master" / "scenario.yaml"
PERIOD_S = 0.1


#: output stem -> model identifier, in a fresh interpreter (one that has loaded an FMU has its module imported)
IDENTIFIERS = {"gc": "gc_fmu", "json": "json_fmu", "time": "time_fmu", "numpy": "numpy_fmu", "GrainWorld": "GrainWorld",
               "3d": "M3d", "class": "Mclass", "my world": "my_world"}


def test_the_model_identifier_never_names_an_importable_module():
    code = ("import json, sys; from pathlib import Path; from cosim.fmi.export.build import model_identifier; "
            "print(json.dumps({s: model_identifier(Path(f'/x/{s}.fmu')) for s in json.loads(sys.argv[1])}))")
    out = subprocess.run([sys.executable, "-c", code, json.dumps(list(IDENTIFIERS))], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, check=True).stdout
    assert json.loads(out) == IDENTIFIERS


def test_destinations_are_checked_before_anything_is_built(tmp_path):
    (tmp_path / "dir").mkdir()
    assert fmu_destination(tmp_path / "dir", "default") == tmp_path / "dir" / "default.fmu"
    with pytest.raises(DestinationError, match="its folder .* does not exist; create it, or add --parents"):
        fmu_destination(tmp_path / "no" / "w.fmu", "default")
    assert fmu_destination(tmp_path / "no" / "w.fmu", "default", parents=True) == tmp_path / "no" / "w.fmu"
    with pytest.raises(DestinationError, match=r"ends in \.fmu"):
        fmu_destination(tmp_path / "w.zip", "default")
    (tmp_path / "notes.fmu").write_text("my notes")
    with pytest.raises(DestinationError, match="not an FMU, which export never replaces"):
        fmu_destination(tmp_path / "notes.fmu", "default", overwrite=True)
    (tmp_path / "ro").mkdir(mode=0o500)
    if not os.access(tmp_path / "ro", os.W_OK):                   # root may write anywhere
        with pytest.raises(DestinationError, match="permission denied"):
            fmu_destination(tmp_path / "ro" / "w.fmu", "default")


def test_a_failed_write_leaves_nothing_truncated(tmp_path, monkeypatch):
    built = tmp_path / "built.fmu"
    built.write_bytes(b"PK" + b"x" * 100_000)
    out = tmp_path / "out.fmu"
    out.write_bytes(b"the earlier FMU")

    def full(*_a, **_k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("shutil.copyfile", full)
    with pytest.raises(OutputError, match="no space left on device writing .*out.fmu"):
        write_atomically(built, out)
    assert out.read_bytes() == b"the earlier FMU" and sorted(p.name for p in tmp_path.iterdir()) == \
        ["built.fmu", "out.fmu"]


def test_an_escape_byte_in_out_is_never_echoed_raw(tmp_path, capsys):
    out = tmp_path / "a\x1b[31mred.fmu"
    assert shown(out).startswith("'") and "\x1b" not in shown(out) and "\\x1b" in shown(out)
    assert main(["export-fmu", "default", "--out", str(tmp_path / "missing" / "a\x1b[2Jb.fmu")]) == 2
    err = capsys.readouterr().err
    assert "\x1b" not in err and "\\x1b[2J" in err and "does not exist" in err


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    pytest.importorskip("fmpy", reason="FMU tests need fmpy (pip install -e \".[test]\")")
    pytest.importorskip("pythonfmu", reason="the export needs pythonfmu (pip install -e \".[test]\")")
    return tmp_path_factory.mktemp("export")


def test_gc_fmu_loads_and_steps_in_fmpy(exported, capsys):
    import fmpy
    from fmpy.fmi2 import FMU2Slave
    from fmpy.model_description import read_model_description

    out = exported / "gc.fmu"
    assert main(["export-fmu", str(SCENARIO), "--out", str(out)]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {out}: FMI 2.0")
    md = read_model_description(str(out))
    assert md.coSimulation.modelIdentifier == "gc_fmu"
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = fmpy.extract(str(out))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier="gc_fmu", instanceName="world")
    fmu.instantiate()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for k in range(3):
            fmu.doStep(k * PERIOD_S, PERIOD_S)
        assert fmu.getInteger([vr["frame"]]) == [3]
        fmu.terminate()
    finally:
        fmu.freeInstance()


def test_an_existing_folder_gets_the_scenarios_name_and_an_fmu_is_replaced_only_with_overwrite(exported, capsys):
    folder = exported / "into"
    folder.mkdir()
    assert main(["export-fmu", str(SCENARIO), "--out", str(folder)]) == 0
    written = folder / "simulink_master.fmu"
    assert capsys.readouterr().out.startswith(f"wrote {written}: ") and written.is_file()
    assert main(["export-fmu", str(SCENARIO), "--out", str(written)]) == 2
    assert "holds an FMU; choose another --out, or add --overwrite" in capsys.readouterr().err
    before = written.stat().st_mtime_ns
    assert main(["export-fmu", str(SCENARIO), "--out", str(written), "--overwrite"]) == 0
    assert written.stat().st_mtime_ns >= before and [p.name for p in folder.iterdir()] == ["simulink_master.fmu"]


def test_runs_out_is_escaped_too(tmp_path):
    from cosim.runtime.rundir import RunDirError, make_out_dir

    with pytest.raises(RunDirError) as info:
        make_out_dir(tmp_path / "missing" / "a\x1b]0;title\x07b")
    assert "\x1b" not in str(info.value) and "\x07" not in str(info.value) and "\\x1b]0;title\\x07b" in str(info.value)
