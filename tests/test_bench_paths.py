"""Results name source trees and run folders without the machine's absolute paths (bench/harness/arms.py)."""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

from harness.arms import shown_path  # noqa: E402

#: a string that starts like an absolute path of a POSIX or Windows machine
ABSOLUTE = re.compile(r'"(/[A-Za-z]|[A-Za-z]:\\)')


def test_paths_show_relative_to_the_checkout_or_by_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert shown_path(ROOT) == "."
    assert shown_path(ROOT / "bench" / "out" / "identity" / "this") == "bench/out/identity/this"
    assert shown_path(tmp_path / "runs" / "a") == "runs/a"
    assert shown_path(tmp_path.parent) == tmp_path.parent.name


def test_the_committed_results_hold_no_absolute_path():
    text = (BENCH / "results.json").read_text(encoding="utf-8")
    json.loads(text)
    assert not ABSOLUTE.findall(text)


#: an absolute path of a machine in a command line shown to a user
MACHINE_PATH = re.compile(r"(?<![\w.~$}])/(tmp|work|home|root|Users|var)/")


def test_usage_lines_hold_no_absolute_path():
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), BENCH / "README.md",
             BENCH / "run.py", BENCH / "run_all.py", ROOT / "cosim" / "cli.py"]
    lines = [f"{p.relative_to(ROOT)}:{i}: {line.strip()}" for p in pages
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if "python " in line and MACHINE_PATH.search(line)]
    assert not lines, "usage lines with a machine's absolute path:\n" + "\n".join(lines)
    assert MACHINE_PATH.search("python bench/run.py e2e --tree main=/work/main")
