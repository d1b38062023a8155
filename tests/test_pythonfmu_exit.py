"""The pythonfmu wrapper's exit order (cosim.fmi.pythonfmu_exit): its interpreter handle emptied from an atexit
handler, registered by the FMU loader and by the exported world's model class; releasing it while instances live
and before new ones is harmless; nothing else is touched. The slow test runs a host under valgrind: without the
handler the wrapper's library destructor reads the handle's freed block at exit (the intermittent "corrupted
double-linked list", exit 134)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import fmu_builds
import pytest

from cosim.fmi import pythonfmu_exit
from cosim.fmi.describe import describe
from cosim.fmi.slave import FmuSlave

ROOT = Path(__file__).resolve().parent.parent


def _front_to_back(built_fmus, name: str = "FrontToBack3"):
    d = describe(fmu_builds.need(built_fmus, name))
    return FmuSlave(d, ["full", "height", "current"], ["section", "highest_height"], {"sections": 9}, "test")


def test_loader_registers_and_early_release_is_harmless(built_fmus, monkeypatch):
    """Loading a pythonfmu3 FMU registers its binary once; the finalizer called while an instance lives (as atexit
    does), then a second instance made and stepped: both answer as before."""
    calls = []
    monkeypatch.setattr(pythonfmu_exit.atexit, "register", lambda fn, *a: calls.append((fn, a)))
    monkeypatch.setattr(pythonfmu_exit, "_registered", set())
    full = [1.0, 1.0, 0.0] + [0.0] * 6
    height = [0.5] * 9
    with _front_to_back(built_fmus) as first:
        assert len(calls) == 1
        binary = calls[0][1][0]
        assert Path(binary).name == "FrontToBack3.so"
        pythonfmu_exit._release(binary)                   # what the atexit handler does
        with _front_to_back(built_fmus) as second:
            assert second.step(full + height + [0.0], 0.0, 0.1, 1) == [3.0, 0.5]
        assert first.step(full + height + [0.0], 0.0, 0.1, 1) == [3.0, 0.5]
    assert len(calls) == 1 + 1                             # the second slave's extraction is another binary
    assert pythonfmu_exit.release_at_exit(binary) and len(calls) == 2     # once per binary


def test_other_libraries_are_left_alone(built_fmus, tmp_path, monkeypatch):
    """A loaded library without the finalizer, a library not loaded (and not loaded by asking) and a pythonfmu
    binary under an embedded interpreter (no command line: the wrapper started it) register nothing."""
    import numpy.linalg._umath_linalg as loaded

    monkeypatch.setattr(pythonfmu_exit, "_registered", set())
    assert not pythonfmu_exit.release_at_exit(loaded.__file__)
    copy = tmp_path / "copy.so"
    shutil.copy(loaded.__file__, copy)
    assert not pythonfmu_exit.release_at_exit(copy)
    assert str(copy) not in Path("/proc/self/maps").read_text()
    with _front_to_back(built_fmus) as slave:
        binary = slave._fmu.dll._name
        monkeypatch.setattr(pythonfmu_exit, "_registered", set())
        monkeypatch.setattr(sys, "orig_argv", [])
        assert not pythonfmu_exit.host_owns_interpreter()
        assert not pythonfmu_exit.release_at_exit(binary)


def test_exported_binaries_are_found(tmp_path):
    """An unpacked FMU's binaries of one model for the platforms with the exit order (not Windows')."""
    for plat in ("linux64", "darwin64", "win64"):
        (tmp_path / "binaries" / plat).mkdir(parents=True)
    (tmp_path / "binaries" / "linux64" / "World.so").write_bytes(b"")
    (tmp_path / "binaries" / "darwin64" / "World.dylib").write_bytes(b"")
    (tmp_path / "binaries" / "win64" / "World.dll").write_bytes(b"")
    (tmp_path / "resources").mkdir()
    assert [p.name for p in pythonfmu_exit.binaries_of(tmp_path / "resources", "World")] == ["World.dylib",
                                                                                          "World.so"]


HOST = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})
    from cosim.fmi.describe import describe
    from cosim.fmi.slave import FmuSlave
    if {off}:
        import cosim.fmi.slave as slave
        slave.release_at_exit = lambda path: False
    d = describe({fmu!r})
    with FmuSlave(d, ["full", "height", "current"], ["section", "highest_height"], {{"sections": 9}}, "t") as s:
        s.step([0.0] * 19, 0.0, 0.1, 1)
    print("host done")
""")


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("valgrind") is None, reason="needs valgrind")
@pytest.mark.parametrize("off", [True, False], ids=["without", "with"])
def test_no_use_after_free_at_exit_under_valgrind(built_fmus, tmp_path, off):
    """A Python host that loads a pythonfmu3 FMU and exits, under valgrind: without the handler the wrapper's
    destructor reads freed memory at exit (the test's own check that valgrind sees it), with it nothing does."""
    script = tmp_path / "host.py"
    script.write_text(HOST.format(tests=str(ROOT / "tests"), fmu=str(fmu_builds.need(built_fmus, "FrontToBack3")),
                                  off=off))
    log = tmp_path / "vg.txt"
    env = dict(os.environ, PYTHONMALLOC="malloc", PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")]))
    done = subprocess.run(["valgrind", "--tool=memcheck", "--num-callers=12", f"--log-file={log}",
                           os.path.realpath(sys.executable), str(script)], env=env, capture_output=True,
                          text=True, timeout=600)
    assert "host done" in done.stdout, done.stderr[-2000:]
    text = log.read_text()
    freed = [block for block in text.split("\n==") if "free'd" in block]
    in_wrapper = "finalizePythonInterpreter" in text and any("free'd" in b for b in text.split("Invalid read"))
    assert in_wrapper == off, freed
