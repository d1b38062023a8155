"""examples/run_examples.py: what it runs in a folder, and that a failing example is named and fails the run."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
RUNNER = REPO / "examples" / "run_examples.py"


def _folder(root: Path, name: str, files: dict[str, str]) -> Path:
    d = root / name
    d.mkdir(parents=True)
    for n, text in files.items():
        (d / n).write_text(text)
    return d


def test_runner_runs_build_then_scripts_and_names_the_failing_example(tmp_path):
    root = tmp_path / "examples"
    _folder(root, "a_good", {
        "build.py": "from pathlib import Path\nPath(__file__).with_name('built.txt').write_text('x')\n",
        "script.py": ("import os, pathlib\nassert os.environ['GRAINCOSIM_EXAMPLE_QUICK'] == '1'\n"
                      "assert pathlib.Path(__file__).with_name('built.txt').exists()\n"
                      "import cosim.api\nif __name__ == '__main__':\n    print('ran')\n"),
        "plugin_module.py": "raise SystemExit('a plug-in module is not run as a script')\n",
    })
    _folder(root, "b_bad", {"cells.py": "# %%\nraise RuntimeError('broken example')\n"})
    p = subprocess.run([sys.executable, str(RUNNER), "--root", str(root)], capture_output=True, text=True,
                       cwd=tmp_path)
    assert p.returncode == 1
    assert "a_good:\n  build.py: ok" in p.stdout and "script.py: ok" in p.stdout
    assert "plugin_module.py" not in p.stdout
    assert "cells.py: FAILED (exit status 1)" in p.stdout and "RuntimeError: broken example" in p.stdout
    assert "FAILED examples: b_bad (cells.py: exit status 1)" in p.stderr
    ok = subprocess.run([sys.executable, str(RUNNER), "--root", str(root), "a_good"], capture_output=True, text=True)
    assert ok.returncode == 0 and "1 example(s) passed" in ok.stdout
    unknown = subprocess.run([sys.executable, str(RUNNER), "--root", str(root), "nope"], capture_output=True,
                             text=True)
    assert unknown.returncode == 2 and "no example nope" in unknown.stderr
