"""Plug-ins are imported in a guarded way (cosim/scenario/probe.py, docs/plugins.md): a module that exits the
interpreter, kills it, hangs or raises when imported is a refusal naming the plug-in (exit 2), never a silent
exit 0 with nothing run; and ``launch.py``, ``python -m cosim`` and the ``graincosim`` command find modules alike."""
from __future__ import annotations

import os
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

import cosim.scenario.probe as probe
from cosim.cli import main
from cosim.testing.load import promised

ROOT = Path(__file__).resolve().parent.parent

STRATEGY = "\ndef f(full, height, current):\n    return 0\n"


def _scenario(tmp_path: Path, source: str, key: str = "strategy", group: str = "controller") -> tuple[Path, str]:
    """A scenario naming ``<module>:f`` at ``group.key``, the module beside it holding ``source``."""
    name = f"guard_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(source + STRATEGY)
    path = tmp_path / "s.yaml"
    path.write_text(f"format_version: 1\nrenderer: none\nfeedback: ground_truth\n{group}:\n  {key}: {name}:f\n")
    return path, name


CASES = [
    ("import sys\nsys.exit(0)\n", "importing module '{name}' calls sys.exit(0)"),
    ("import os\nos._exit(0)\n", "importing module '{name}' ends the interpreter (os._exit at import time, exit "
                                  "status 0)"),
    ("raise SystemExit(3)\n", "calls sys.exit(3)"),
    ("import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n", "kills the interpreter (SIGKILL)"),
    ("raise RuntimeError('no licence server')\n", "failed: RuntimeError: no licence server"),
]


@pytest.mark.parametrize("fork", [True, False], ids=["fork", "fresh interpreter"])
@pytest.mark.parametrize("source, message", CASES)
def test_an_import_that_ends_the_interpreter_is_refused_naming_the_plugin(tmp_path, capsys, monkeypatch, source,
                                                                           message, fork):
    monkeypatch.setattr(probe, "can_fork", lambda: fork)
    path, name = _scenario(tmp_path, source)
    message = message.format(name=name)
    out = tmp_path / "run"
    for verb in (["validate"], ["run", "--out", str(out), "--quiet"])[: 2 if fork else 1]:
        assert main([verb[0], str(path), *verb[1:]]) == 2
        err = capsys.readouterr().err
        assert f"{path}:5:13: controller.strategy: plug-in '{name}:f': " in err and message in err, err
        assert "nothing was started" in err and not out.exists()
    assert name not in sys.modules or message.startswith("failed")


@pytest.mark.parametrize("fork", [True, False], ids=["fork", "fresh interpreter"])
def test_an_import_that_hangs_is_refused_after_the_time_limit(tmp_path, capsys, monkeypatch, fork):
    monkeypatch.setattr(probe, "PLUGIN_IMPORT_IDLE_S", 1.0)
    monkeypatch.setattr(probe, "can_fork", lambda: fork)
    path, name = _scenario(tmp_path, "import time\ntime.sleep(600)\n")
    t = time.monotonic()
    assert main(["validate", str(path)]) == 2
    assert time.monotonic() - t < promised(30.0, 120.0)
    err = capsys.readouterr().err
    assert f"controller.strategy: plug-in '{name}:f': importing module '{name}' made no progress for 1 s" in err


@pytest.mark.parametrize("fork", [True, False], ids=["fork", "fresh interpreter"])
def test_a_slow_import_that_progresses_is_waited_for_and_a_loop_is_stopped_by_its_cpu_time(tmp_path, fork,
                                                                                           monkeypatch):
    """The probe judges progress, not the clock: an import that computes for 3 s (a large library's first import
    on a busy machine) passes a 1 s idle limit; one that loops forever is stopped by its CPU budget."""
    monkeypatch.setattr(probe, "PLUGIN_IMPORT_IDLE_S", 1.0)
    slow = f"slow_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{slow}.py").write_text("import time\nt = time.process_time() + 3.0\n"
                                         "while time.process_time() < t:\n    pass\n")
    assert probe.probe_imports([slow], [str(tmp_path), *sys.path], fork=fork) == {}
    monkeypatch.setattr(probe, "PLUGIN_IMPORT_CPU_S", 1.0)
    loop = f"loop_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{loop}.py").write_text("while True:\n    pass\n")
    refused = probe.probe_imports([loop], [str(tmp_path), *sys.path], fork=fork)
    assert refused[loop].startswith(f"importing module '{loop}' did not finish within 1 s of CPU time")


@pytest.mark.parametrize("fork", [True, False], ids=["fork", "fresh interpreter"])
def test_every_module_is_probed_even_after_one_that_raises(tmp_path, fork):
    bad = f"raise_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{bad}.py").write_text("print('at import')\nraise ValueError('x')\n")
    ends = f"exit_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{ends}.py").write_text("import os\nos._exit(7)\n")
    fine = f"fine_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{fine}.py").write_text("print('done')\n")
    refused = probe.probe_imports([bad, ends, fine], [str(tmp_path), *sys.path], fork=fork)
    assert list(refused) == [ends] and "exit status 7" in refused[ends]
    assert fine not in sys.modules                                          # probed, not imported here
    assert probe.probe_imports(["json", "os"], fork=fork) == {}             # imported already: not probed


def test_the_real_command_exits_2_not_0(tmp_path):
    """The launcher process itself: os._exit(0) in a plug-in module used to end validate with exit 0."""
    path, name = _scenario(tmp_path, "import os\nos._exit(0)\n")
    r = subprocess.run([sys.executable, str(ROOT / "launch.py"), "validate", str(path)], capture_output=True,
                       text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 2, r.stderr
    assert f"plug-in '{name}:f': importing module '{name}' ends the interpreter (os._exit" in r.stderr
    assert "Traceback" not in r.stderr


def test_the_three_entries_resolve_modules_alike(tmp_path):
    """A module in the working directory is not a plug-in the scenario can see (it is for none of the three
    entries); the same module beside the scenario (plugin_dir) is found by all three."""
    work, elsewhere = tmp_path / "work", tmp_path / "elsewhere"
    work.mkdir()
    elsewhere.mkdir()
    name = f"cwdmod_{uuid.uuid4().hex[:8]}"
    (work / f"{name}.py").write_text(STRATEGY)
    scenario = elsewhere / "s.yaml"
    scenario.write_text("format_version: 1\nrenderer: none\nfeedback: ground_truth\n")
    script_dir = tmp_path / "bin"                      # what pip writes for the graincosim console script
    script_dir.mkdir()
    (script_dir / "graincosim").write_text("import sys\nfrom cosim.entry import run_cli\nsys.exit(run_cli())\n")
    entries = {"launch.py": [sys.executable, str(ROOT / "launch.py")],
               "python -m cosim": [sys.executable, "-m", "cosim"],
               "graincosim": [sys.executable, str(script_dir / "graincosim")]}
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for how, argv in entries.items():
        r = subprocess.run([*argv, "validate", str(scenario), "--set", f"controller.strategy={name}:f"], cwd=work,
                           capture_output=True, text=True, timeout=120, env=env)
        assert r.returncode == 2 and f"no module named '{name}'" in r.stderr, (how, r.stderr)
        r = subprocess.run([*argv, "validate", str(scenario), "--set", f"controller.strategy={name}:f", "--set",
                            f"plugin_dir={work}"], cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
        assert r.returncode == 0 and f"file {work / (name + '.py')}" in r.stdout, (how, r.stderr)
