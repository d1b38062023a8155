"""Progress: one labelled bar per run with an ETA (tqdm), plain lines off a terminal, nothing when quiet, and
compare's three runs each under its own name, never mixed."""
from __future__ import annotations

import io
import re
from types import SimpleNamespace

import cosim.studies.compare as compare_mod
from cosim.runtime.progress import PLAIN_INTERVAL_S, ProgressPrinter, run_progress
from cosim.scenario.loader import load_scenario, resolve_scenario_arg


def test_plain_lines_name_the_run_and_give_an_eta(monkeypatch):
    clock = [0.0]
    monkeypatch.setattr("cosim.runtime.progress.time.monotonic", lambda: clock[0])
    s = io.StringIO()
    p = ProgressPrinter(s, tty=False, name="ground_truth")
    for frame in range(0, 101):
        clock[0] = frame * 0.1  # 10 frames a second of wall time
        p(frame, 100, frame * 0.1, frame * 0.1)
    lines = s.getvalue().splitlines()
    # a line at frame 0, then one per PLAIN_INTERVAL_S of wall time, and the last frame
    assert len(lines) == 1 + int(10.0 / PLAIN_INTERVAL_S)
    assert all(line.startswith("ground_truth: ") for line in lines)
    mid = lines[1]
    assert "50/100" in mid and "1.0x real time" in mid
    eta = re.search(r"<(\d\d):(\d\d)", mid)
    assert eta and int(eta.group(1)) * 60 + int(eta.group(2)) == 5, "50 frames left at 10 frames/s: 5 s"
    assert "100/100" in lines[-1]


def test_a_terminal_gets_one_bar_with_the_name_and_a_newline_at_the_end():
    s = io.StringIO()
    p = ProgressPrinter(s, tty=True, name="perception_paper")
    for frame in range(0, 51):
        p(frame, 50, frame * 0.1, 1.0 + frame * 0.05)
    out = s.getvalue()
    assert out.count("\n") == 1 and out.endswith("\n")
    last = out.rstrip("\n").split("\r")[-1]
    assert last.startswith("perception_paper: 100%") and "50/50" in last and "sim 5.0 s" in last


def test_quiet_means_none():
    assert run_progress("x", quiet=True) is None
    assert isinstance(run_progress("x"), ProgressPrinter) and run_progress("x").name == "x"


def test_compare_gives_each_run_its_own_labelled_bar(tmp_path, monkeypatch):
    seen = []

    def fake_launch(sc, out, progress=None, **_):
        seen.append(progress)
        for frame in range(0, 11 if progress is not None else 0):
            progress(frame, 10, frame * 0.1, 0.5 + frame * 0.1)
        return SimpleNamespace(run_dir=out)

    err = io.StringIO()
    monkeypatch.setattr(compare_mod, "launch", fake_launch)
    monkeypatch.setattr(compare_mod, "load_run", lambda d: d)
    monkeypatch.setattr(compare_mod, "write_comparison_report", lambda runs, out, notes: out / "report.html")
    monkeypatch.setattr("sys.stderr", err)
    sc = load_scenario(resolve_scenario_arg("default"), extra={"renderer": "mock"})
    compare_mod.compare(sc, tmp_path, quiet=False)
    names = [p.name for p in seen]
    assert names == ["[1/3] ground_truth", "[2/3] perception_paper", "[3/3] perception_fused"]
    labels = [line.split(":")[0] for line in err.getvalue().splitlines()]
    # each run's lines together, in order, each under its own name
    assert labels == sorted(labels, key=names.index) and set(labels) == set(names)
    seen.clear()
    compare_mod.compare(sc, tmp_path, quiet=True)
    assert seen == [None, None, None]
