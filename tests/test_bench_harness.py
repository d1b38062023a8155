"""bench/run.py and bench/harness: the case list, interleaved rounds, medians and paired ratios, A/B of trees, the
Markdown and JSON, bad input; and that every bench script or case the repository cites exists (so the harness and
the docs cannot rot apart)."""
from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

from harness import Arm, Case, OptionError, aggregate, alternating, paired_ratios, parse_arms, run_cases  # noqa: E402
from harness.report import markdown, to_json  # noqa: E402


def bench(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "bench/run.py", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


def test_list_names_every_case_with_one_line():
    out = bench("--list")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    names = [line.split()[0] for line in lines]
    assert names == sorted(names) and len(set(names)) == len(names)
    # the measurements of the scripts the harness replaced, each a case
    for name in ("e2e", "startup", "ring_latency", "render_fps", "beam_native", "mock_cast", "frame_path", "curves",
                 "sweep_throughput", "sweep_engine", "perception_replay", "viewer", "viewer_panels", "reliability",
                 "fmu", "identity", "beam_solids", "beam_surface", "sensor_cost", "stereo_pile_height"):
        assert name in names, name
    assert all(len(line.split(None, 1)) == 2 for line in lines)            # a name and a summary on each line


def test_describe_gives_the_options_with_their_quick_values():
    out = bench("--describe", "e2e")
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("e2e: ") and "duration = 120.0   (--quick: 2.0)" in out.stdout
    assert "scenario settings (--set, --variant): yes" in out.stdout


def _case(log: list, **kw) -> Case:
    """A case whose samples are a known function of the arm and the round (in-process)."""
    def measure(ctx):
        log.append((ctx.round, ctx.arm, ctx.settings))
        k = {"a": 1.0, "b": 2.0}[ctx.arm]
        return {"t": {"row": {"ms": k * (10 + ctx.round), "label": "same", "n": ctx.opts["n"]}}}
    return Case("fake", "a fake case", measure, options={"n": 3}, quick={"n": 1}, rounds=4, settings=True, **kw)


def test_rounds_interleave_arms_and_give_medians_and_paired_ratios():
    log: list = []
    arms = [Arm("a", ROOT, ("x=1",)), Arm("b", ROOT)]
    s = run_cases([_case(log)], arms, settings=("y=2",), in_process=True, command="python bench/run.py fake", log=None)
    # A B, B A, A B, B A; every arm gets the common settings before its own
    assert [(r, a) for r, a, _ in log] == [(0, "a"), (0, "b"), (1, "b"), (1, "a"), (2, "a"), (2, "b"), (3, "b"),
                                           (3, "a")]
    assert {st for _, a, st in log if a == "a"} == {("y=2", "x=1")}
    res = s.results[0]
    med = res.median()
    # a: 10, 11, 12, 13 -> median 11.5 (10-13); b twice that
    assert (med["a"]["t"]["row"]["ms"].median, med["a"]["t"]["row"]["ms"].lo) == (11.5, 10.0)
    assert med["b"]["t"]["row"]["ms"].hi == 26.0 and med["b"]["t"]["row"]["n"].median == 3
    ratio = res.paired()["b"]["t"]["row"]
    assert ratio["ms"].median == pytest.approx(2.0) and ratio["ms"].lo == pytest.approx(2.0)
    assert ratio["label"] == "same"
    md = markdown(s)
    assert "`python bench/run.py fake`" in md and "load average" in md and "| a | row | 11.50 (10.00-13.00) |" in md
    assert "### b / a: t (each round's own ratio)" in md and "2.000x" in md
    js = to_json(s)
    json.dumps(js, allow_nan=False)
    assert js["cases"]["fake"]["samples"]["b"][3]["t"]["row"]["ms"] == 26.0


def test_quick_takes_the_quick_options_and_one_round():
    log: list = []
    s = run_cases([_case(log)], [Arm("a")], quick=True, in_process=True, log=None)
    assert len(log) == 1 and s.results[0].opts == {"n": 1} and s.quick


def test_aggregate_and_paired_leave_out_what_is_missing():
    samples = [{"t": {"r": {"x": 1.0, "y": None}}}, {"t": {"r": {"x": float("nan"), "y": "text"}}},
               {"t": {"r": {"x": 3.0}}}]
    agg = aggregate(samples)
    assert (agg["t"]["r"]["x"].median, agg["t"]["r"]["x"].n) == (2.0, 2) and agg["t"]["r"]["y"] == "text"
    verdicts = aggregate([{"t": {"r": {"v": "met"}}}, {"t": {"r": {"v": "NOT met"}}}, {"t": {"r": {"v": "met"}}}])
    assert verdicts["t"]["r"]["v"] == "round 1: met / round 2: NOT met / round 3: met"  # not the first round's word
    ratios = paired_ratios([{"t": {"r": {"x": 2.0, "d": "abc"}}}, {"t": {"r": {"x": 0.0, "d": "abc"}}}],
                           [{"t": {"r": {"x": 3.0, "d": "abc"}}}, {"t": {"r": {"x": 5.0, "d": "abd"}}}])
    assert ratios["t"]["r"]["x"].n == 1 and ratios["t"]["r"]["x"].median == 1.5 and ratios["t"]["r"]["d"] == "differs"
    assert alternating([1, 2, 3], 0) == [1, 2, 3] and alternating([1, 2, 3], 1) == [3, 2, 1]


def test_arms_and_options_refuse_bad_input(tmp_path):
    assert parse_arms() == [Arm("this")]
    arms = parse_arms([f"main={ROOT}"], ["gt=feedback=ground_truth", "gt=renderer=none"])
    assert arms[1] == Arm("gt", ROOT, ("feedback=ground_truth", "renderer=none"))
    with pytest.raises(OptionError, match="not a source tree"):
        parse_arms([f"x={tmp_path}"])
    with pytest.raises(OptionError, match="NAME=PATH=VALUE"):
        parse_arms(variants=["gt=feedback"])
    with pytest.raises(OptionError, match="unknown option"):
        _case([]).resolve(given={"frames": 2})


@pytest.mark.parametrize("args, message", [
    (("no_such_case",), "no case named 'no_such_case'"),
    (("rig_plan", "--opt", "frames=3"), "none of rig_plan has an option 'frames'"),
    (("rig_plan", "--set", "duration_s=3"), "rig_plan run(s) no scenario"),
])
def test_bad_command_lines_exit_2_with_the_reason(args, message):
    out = bench(*args)
    assert out.returncode == 2 and message in out.stderr, out.stderr


def test_two_cheap_cases_quick_as_ab_of_two_trees(tmp_path):
    """rig_plan and viewer_panels, each sample in a worker of its tree; the same tree twice: the planned rigs are
    deterministic, so their paired ratios are exactly 1 and every text is the same."""
    out = bench("rig_plan", "viewer_panels", "--quick", "--tree", "a=.", "--tree", "b=.", "--json",
                str(tmp_path / "r.json"))
    assert out.returncode == 0, out.stderr[-3000:]
    assert "## rig_plan:" in out.stdout and "## viewer_panels:" in out.stdout and "load average" in out.stdout
    js = json.loads((tmp_path / "r.json").read_text())
    rig = js["cases"]["rig_plan"]
    assert [a["label"] for a in rig["arms"]] == ["a", "b"] and rig["rounds"] == 1
    rows = rig["samples"]["a"][0]["planned rigs"]
    assert len(rows) == 3
    for row in rows.values():
        assert row["cameras"] >= 1 and 0 < row["worst error deg"] <= 0.2 and row["pixels"] > 10_000
    for row in rig["paired"]["b"]["planned rigs"].values():
        assert row["pixels"]["median"] == 1.0 and row["sizes"] == "same"
    panels = js["cases"]["viewer_panels"]["median"]["a"]["panel drawings"]
    assert {"rgb", "depth", "lidar_top", "heightmaps"} <= set(panels)
    assert all(math.isfinite(p["CPU ms"]["median"]) and p["CPU ms"]["median"] > 0 for p in panels.values())


def test_a_failed_sample_is_reported_and_the_exit_status_says_so():
    # frames=0: the ring has no turns to time; the worker fails, the others' results are still printed
    out = bench("rig_plan", "ring_latency", "--opt", "ring_latency.frames=0", "--opt", "rig_plan.bounds=0.5")
    assert out.returncode == 1 and "**FAILED**: case ring_latency" in out.stdout and "## rig_plan:" in out.stdout


# -- what the repository cites exists ----------------------------------------------------------------------------
_SCRIPT = re.compile(r"\bbench/(\w+\.py)\b")
_RUN = re.compile(r"bench/run\.py ((?:\w+ ?)+)")


def _tracked() -> list[Path]:
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=False).stdout.split()
    return [ROOT / f for f in out if f.endswith((".py", ".md", ".yaml", ".toml", ".frag"))
            and f != "tests/test_bench_harness.py"]                # its own fake case and bad names


def test_every_bench_script_and_case_cited_exists():
    files = _tracked()
    if not files:
        pytest.skip("not a git checkout")
    from harness import load_cases

    cases = load_cases()
    missing = []
    for f in files:
        text = f.read_text(errors="replace")
        # HISTORY.md names the retired scripts (test below); every other file only what exists
        for m in _SCRIPT.finditer("" if f.name == "HISTORY.md" else text):
            if not (BENCH / m.group(1)).exists():
                missing.append(f"{f.relative_to(ROOT)}: bench/{m.group(1)}")
        for m in _RUN.finditer(text):
            for word in m.group(1).split():
                if word not in cases and not word.isupper():
                    missing.append(f"{f.relative_to(ROOT)}: case {word}")
    assert missing == [], "bench scripts or cases cited that do not exist:\n" + "\n".join(missing)


def test_retired_scripts_are_reachable_at_the_commit_history_names():
    """HISTORY.md's table of retired scripts names a commit that still has each one (git show COMMIT:PATH)."""
    text = (BENCH / "HISTORY.md").read_text()
    section = text.split("## Retired scripts", 1)[1].split("\n## ", 1)[0]
    commit = re.search(r"commit `([0-9a-f]{7,40})`", section).group(1)
    scripts = sorted(set(re.findall(r"`bench/(\w+\.py)\b", section)) - {"run.py", "run_all.py"})
    assert len(scripts) >= 30
    if subprocess.run(["git", "cat-file", "-e", f"{commit}^{{commit}}"], cwd=ROOT).returncode != 0:
        pytest.skip(f"commit {commit} not in this clone")
    for s in scripts:
        assert not (BENCH / s).exists(), f"bench/{s} is listed as retired but still here"
        got = subprocess.run(["git", "cat-file", "-e", f"{commit}:bench/{s}"], cwd=ROOT)
        assert got.returncode == 0, f"bench/{s} is not in commit {commit}"


def test_a_worker_runs_with_single_threaded_pools_unless_the_caller_sized_them(tmp_path):
    from harness.arms import worker_env

    env = worker_env(tmp_path, {"PATH": "/bin", "OPENBLAS_NUM_THREADS": "4"})
    assert env["PYTHONPATH"] == str(tmp_path) and env["PATH"] == "/bin"
    assert env["OPENBLAS_NUM_THREADS"] == "4"                       # the caller's choice is kept
    assert env["OMP_NUM_THREADS"] == env["MKL_NUM_THREADS"] == env["OPENCV_FOR_THREADS_NUM"] == "1"
