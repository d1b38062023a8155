"""Reproduce the README's headline figures in one command, into ``bench/results.json`` and ``bench/results.md``,
with the benchmark harness (``bench/harness``, the cases of ``bench/cases``).

What it measures (each figure names its source in the Markdown):

* case ``e2e`` with two arms, the default run (``python launch.py run default``: GL, perception feedback) and the same
  scenario's ground-truth-only run (``--set feedback=ground_truth --set renderer=none``), ``rounds`` of each,
  interleaved (A B, B A, ...): whole-process wall time, the CPU time of the whole process tree (the launcher, its
  children and theirs, a process that outlives its parent included) and the ring's real-time factor (medians), and
  the perception run's cost over ground truth in wall and in CPU time: the ratio of the medians, and the median (and
  range) of each round's own ratio, which cancels the VM's speed drifting between rounds; the targets (at most
  :data:`TARGET_WALL` and :data:`TARGET_CPU`, medians of the rounds' own ratios) are checked;
* from the first default run's summary: fill, spill, mass balance, the LiDAR range error against the exact ray
  cast; the ground-truth run's section peaks;
* case ``beam_native``: the render + LiDAR step of ``sensor.method: beam_native`` against ``camera_rig`` on the same
  sample frames: CPU ms per frame and the ratio;
* case ``mock_cast``: the mock renderer's frame (rigid bodies built once) against the GL renderer's;
* cases ``curves`` and ``sweep_throughput`` (``--no-curves`` leaves them out and keeps the curves of the
  results.md it replaces, marked with the run that measured them): CPU per frame against beams and the
  grain grid, sweep runs per hour with 1 and 2 local workers.

The sections other commands write into results.md (the field-conditions suite, "Under load" of case
``underload``, the packaged scenarios of case ``scenarios``, the GPU's) are kept as they are.

``--quick`` is a check of the script (short runs, one round, few frames): its numbers are not the headline
figures. Usage::

    python bench/run_all.py                      # the headline figures (an hour on 2 cores)
    python bench/run_all.py --quick --out bench/out/quick # a few minutes: structure only
"""
from __future__ import annotations

import argparse
import json
import re
import shlex
import statistics
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

from cases.scenarios import SECTION as SCENARIOS_HEADING  # noqa: E402
from cases.underload import SECTION as UNDERLOAD_HEADING  # noqa: E402
from field_suite import SECTION as SUITE_HEADING  # noqa: E402
from harness import ROOT, Arm, Result, get, run_cases  # noqa: E402
from harness.report import table, to_json  # noqa: E402

__all__ = ["ARMS", "figures", "kept_suite_section", "main", "measure", "render_markdown"]

#: the two arms of the headline comparison: the ground-truth run first (the baseline of the ratios)
ARMS = (Arm("ground_truth", ROOT, ("feedback=ground_truth", "renderer=none")), Arm("perception", ROOT))
#: the perception run's cost over the ground-truth run that the project aims at (medians of the rounds' own ratios)
TARGET_WALL, TARGET_CPU = 2.0, 3.0
#: case options of the full and the quick run (the renderer is added to e2e's perception arm and to the step)
FULL = {"rounds": 5, "e2e": {"duration": 120.0, "members": False}, "beam_native": {"frames": 40, "errors": False},
        "mock_cast": {"frames": 20, "arms": "embree-static,gl"}, "curves": {"frames": 60, "warmup": 100},
        "sweep_throughput": {"runs": 4, "duration": 20.0, "feedback": "perception", "arms": "sweep1,sweep2",
                             "run_figures": False}, "sweep_rounds": 2}
QUICK = {"rounds": 1, "e2e": {"duration": 3.0, "members": False}, "beam_native": {"frames": 2, "errors": False},
         "mock_cast": {"frames": 2, "arms": "embree-static,gl"}, "curves": {"frames": 3, "warmup": 2},
         "sweep_throughput": {"runs": 2, "duration": 1.0, "feedback": "perception", "arms": "sweep1,sweep2",
                              "run_figures": False}, "sweep_rounds": 1}


def _median(samples: list[dict], table_name: str, row: str, col: str) -> float:
    return statistics.median(s[table_name][row][col] for s in samples)


def _spread(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def _run_figures(samples: list[dict], scenario: str) -> dict:
    run = "run"
    out = {"wall_s": _median(samples, run, scenario, "wall s"), "cpu_s": _median(samples, run, scenario, "CPU s"),
           "ring_wall_s": _median(samples, run, scenario, "ring wall s"),
           "real_time_factor": _median(samples, run, scenario, "real-time factor (ring)")}
    fill = samples[0]["fill"][scenario]
    out["fill"] = {"section_peak_min_m": fill["lowest section peak m"], "section_peak_max_m": fill["highest section peak m"],
                   "max_overfill_m": fill["max overfill m"], "profile_rmse_m": fill["profile RMSE m"],
                   "time_to_target_s": fill["time to target s"], "spill_kg": fill["spill kg"],
                   "mass_balance_relative_error": fill["mass balance, relative error"]}
    return out


def figures(e2e: Result, step: Result | None = None, mock: Result | None = None, curves: list[Result] = ()) -> dict:
    """The results (``results.json``) from the harness's results of the cases."""
    scenario = e2e.opts["scenario"]
    gt, p = e2e.samples["ground_truth"], e2e.samples["perception"]
    res = {"perception": _run_figures(p, scenario), "ground_truth": _run_figures(gt, scenario)}
    rng = p[0].get("LiDAR range error against the exact ray cast", {}).get("mm", {})

    def mm(k: str) -> float | None:
        return None if rng.get(k) is None else rng[k] / 1e3
    above = rng.get("% above 5 cm in 2-15 m")
    res["perception"]["range_error"] = {
        "evaluation": rng.get("evaluation"), "frames_evaluated": rng.get("frames evaluated"), "mean_m": mm("mean mm"),
        "median_m": mm("median mm"), "p99_m": mm("p99 mm"), "max_m": mm("max mm"), "working_p99_m": mm("p99 in 2-15 m mm"),
        "working_frac_above_5cm": None if above is None else above / 100}
    paired = {k: [a["run"][scenario][c] / b["run"][scenario][c] for a, b in zip(p, gt)]
              for k, c in (("wall", "wall s"), ("cpu", "CPU s"))}
    pr, g = res["perception"], res["ground_truth"]
    res["ratio"] = {"wall": pr["wall_s"] / g["wall_s"], "cpu": pr["cpu_s"] / g["cpu_s"],
                    "ring_wall": pr["ring_wall_s"] / g["ring_wall_s"], "wall_paired": _spread(paired["wall"]),
                    "cpu_paired": _spread(paired["cpu"])}
    res["targets"] = {"wall": TARGET_WALL, "cpu": TARGET_CPU, "wall_met": res["ratio"]["wall_paired"]["median"] <= TARGET_WALL,
                      "cpu_met": res["ratio"]["cpu_paired"]["median"] <= TARGET_CPU}
    if step is not None and step.samples["this"]:
        rows = step.samples["this"][0]["render + LiDAR step"]
        k = step.opts["renderers"]
        cr, bn = rows[f"{k} camera_rig"]["CPU ms/frame"], rows[f"{k} beam_native"]["CPU ms/frame"]
        res["lidar_step"] = {"renderer": k, "frames": step.opts["frames"], "camera_rig_cpu_ms": cr,
                             "beam_native_cpu_ms": bn, "ratio_cpu": bn / cr}
    if mock is not None and mock.samples["this"]:
        rows = mock.samples["this"][0]["beam renderers, default scene"]
        if "gl" in rows and "embree-static" in rows:
            m, gl = rows["embree-static"]["CPU ms/frame"], rows["gl"]["CPU ms/frame"]
            res["mock_frame"] = {"frames": mock.opts["frames"], "mock_cpu_ms": m, "gl_cpu_ms": gl, "ratio_cpu": m / gl}
    if curves:
        res["curves"] = {r.case.name: {"options": r.opts, "rounds": r.rounds, "median": _plain(r.median()["this"])}
                         for r in curves if r.samples["this"]}
    return res


def _plain(agg: dict) -> dict:
    from harness.rounds import Stat

    return {t: {r: {c: (v.median if isinstance(v, Stat) else v) for c, v in cells.items()} for r, cells in rows.items()}
            for t, rows in agg.items()}


def _mm(x) -> str:
    return "-" if x is None else f"{1e3 * x:.2f}"


def render_markdown(res: dict, quick: bool = False) -> str:
    """The results as Markdown (``bench/results.md``)."""
    m, p, g, re_ = res["meta"], res["perception"], res["ground_truth"], res["perception"]["range_error"]
    pf, gf = p["fill"], g["fill"]
    above = "-" if re_["working_frac_above_5cm"] is None else f"{100 * re_['working_frac_above_5cm']:.3f}"
    lines = [
        "# Current benchmark results", "",
        f"Written by `{m['command']}` at {m['written_utc']} from commit `{m['commit']}`: {m['cores']} cores "
        f"({m['machine']}), Python {m['python']}, load average {m['load_average'][0]:.1f} at the start and "
        f"{m['load_average'][1]:.1f} at the end. Scenario `{m['scenario']}`, {m['duration_s']:g} s simulated, "
        f"{m['rounds']} interleaved round(s); medians. The dated log of earlier measurements is `bench/HISTORY.md`; "
        "each figure's case can be run alone with `python bench/run.py CASE` (bench/README.md).", "",
    ]
    if quick:
        lines += ["**Quick mode: short runs, a check of the script, not the headline figures.**", ""]
    r, t = res["ratio"], res["targets"]
    lines += [
        "| run | wall s (whole process) | CPU s (process tree) | ring wall s | real-time factor (ring) |",
        "|---|---:|---:|---:|---:|",
        f"| default (perception feedback, renderer {m['renderer']}) | {p['wall_s']:.2f} | {p['cpu_s']:.2f} | "
        f"{p['ring_wall_s']:.2f} | {p['real_time_factor']:.2f} |",
        f"| ground truth (`--feedback ground_truth --renderer none`) | {g['wall_s']:.2f} | {g['cpu_s']:.2f} | "
        f"{g['ring_wall_s']:.2f} | {g['real_time_factor']:.2f} |", "",
        f"Perception run over ground-truth run, each round's own ratio: **{r['wall_paired']['median']:.2f}x** "
        f"whole-process wall time (median; {r['wall_paired']['min']:.2f}-{r['wall_paired']['max']:.2f}x; ratio of "
        f"the medians {r['wall']:.2f}x), **{r['cpu_paired']['median']:.2f}x** CPU time of the process tree "
        f"({r['cpu_paired']['min']:.2f}-{r['cpu_paired']['max']:.2f}x; ratio of the medians {r['cpu']:.2f}x); "
        f"{r['ring_wall']:.2f}x ring wall time. Targets: wall at most {t['wall']:.1f}x "
        f"({'met' if t['wall_met'] else 'NOT met'}), CPU at most {t['cpu']:.1f}x "
        f"({'met' if t['cpu_met'] else 'NOT met'}). (Case `e2e`.)", "",
        "| fill | default | ground truth |", "|---|---:|---:|",
    ]
    for key, label in (("section_peak_min_m", "lowest section peak (m)"), ("section_peak_max_m",
                       "highest section peak (m)"), ("max_overfill_m", "max overfill (m)"),
                       ("profile_rmse_m", "profile RMSE (m)"), ("time_to_target_s", "time to target (s)"),
                       ("spill_kg", "spill (kg)"), ("mass_balance_relative_error", "mass balance, relative error")):
        cell = [("-" if d[key] is None else f"{d[key]:.4g}") for d in (pf, gf)]
        lines.append(f"| {label} | {cell[0]} | {cell[1]} |")
    lines += [
        "", f"LiDAR range error of the default run against the exact ray cast (evaluation: {re_['evaluation']}; "
        f"{re_['frames_evaluated']} frames): mean {_mm(re_['mean_m'])} mm, median {_mm(re_['median_m'])} mm, p99 "
        f"{_mm(re_['p99_m'])} mm, max {_mm(re_['max_m'])} mm; in 2-15 m: p99 {_mm(re_['working_p99_m'])} mm, "
        f"{above} % of beams above 5 cm.", ""]
    st = res.get("lidar_step")
    if st:
        lines += [f"Render + LiDAR step, {st['renderer']}, {st['frames']} sample frames interleaved: beam_native "
                  f"{st['beam_native_cpu_ms']:.2f} ms CPU against camera_rig {st['camera_rig_cpu_ms']:.2f} ms: "
                  f"**{st['ratio_cpu']:.2f}x** (case `beam_native`).", ""]
    mf = res.get("mock_frame")
    if mf:
        lines += [f"Mock renderer frame (exact ray cast, rigid bodies built once) against the GL renderer's, "
                  f"{mf['frames']} sample frames interleaved: {mf['mock_cpu_ms']:.2f} against {mf['gl_cpu_ms']:.2f} ms "
                  f"CPU: **{mf['ratio_cpu']:.2f}x** (target: at most 1x; case `mock_cast`).", ""]
    if res.get("curves"):
        lines += [f"{CURVES_HEADING} (cases `curves` and `sweep_throughput`)", ""]
        for name, c in res["curves"].items():
            for title, rows in c["median"].items():
                lines += [f"### {title}" + (f" ({name})" if name != "curves" else ""), ""]
                lines += table({"this": {title: rows}}, title) + [""]
    return "\n".join(lines)


#: the heading of the cost curves' section, which a run with ``--no-curves`` keeps from the earlier results.md
CURVES_HEADING = "## How the cost grows"
KEPT = "Kept from results.md as written"


def _section(text: str, heading: str) -> str:
    """The section of Markdown ``text`` from ``heading`` to the next second-level heading (or the end), or ""."""
    if heading not in text:
        return ""
    body = text.split(heading, 1)[1]
    nxt = body.find("\n## ")
    return heading + (body if nxt < 0 else body[:nxt + 1])


#: the heading of the GPU figures (measured on a lent device machine, by hand: the table says when none was lent)
GPU_HEADING = "## GPU"
#: the sections of results.md that other commands write, kept as they are
KEPT_SECTIONS = (SCENARIOS_HEADING, GPU_HEADING, UNDERLOAD_HEADING, SUITE_HEADING)


def kept_suite_section(results_md: Path) -> str:
    """The sections of an existing ``results_md`` that other commands write (:data:`KEPT_SECTIONS`: the packaged
    scenarios of case ``scenarios``, the GPU's, case ``underload``'s, the field-conditions suite's from
    bench/field_suite.py's hours-long sweep), which this script does not rerun, or ""."""
    text = results_md.read_text() if results_md.exists() else ""
    return "".join("\n" + s for s in (_section(text, h) for h in KEPT_SECTIONS) if s)


def kept_curves_section(results_md: Path) -> str:
    """The cost curves' section of an existing ``results_md``, for a run with ``--no-curves``, its heading naming
    the run that measured it (the time and commit of that file's "Written by" line), or ""."""
    text = results_md.read_text() if results_md.exists() else ""
    section = _section(text, CURVES_HEADING)
    if not section:
        return ""
    if KEPT in section:                                          # kept once already: its origin stands
        return "\n" + section
    stamp = re.search(r"^Written by .*? at (\S+) from commit `(\w+)`", text, re.M)
    origin = f"at {stamp[1]} from commit `{stamp[2]}`" if stamp else "by an earlier run"
    head, rest = section.split("\n", 1)
    return f"\n{head}\n\n{KEPT} {origin}: this run left the curves out.\n{rest}"


def measure(quick: bool = False, renderer: str = "gl", scenario: str = "default", curves: bool = True,
            command: str = "python bench/run_all.py") -> dict:
    """Every figure (the module docstring) as one JSON-able dict, with the harness's sessions under ``sessions``."""
    cfg = QUICK if quick else FULL
    e2e = run_cases([get("e2e")], [ARMS[0], Arm("perception", ROOT, (f"renderer={renderer}",))], rounds=cfg["rounds"],
                    quick=quick, opts={"e2e": {**cfg["e2e"], "scenario": scenario}}, command=command)
    cases = [get("beam_native"), get("mock_cast")] + ([get("curves")] if curves else [])
    one = run_cases(cases, [Arm("this")], rounds=1, quick=quick, command=command,
                    opts={"beam_native": {**cfg["beam_native"], "renderers": renderer}, "mock_cast": cfg["mock_cast"],
                          "curves": cfg["curves"]})
    sessions = [e2e, one]
    if curves:
        sessions.append(run_cases([get("sweep_throughput")], [Arm("this")], rounds=cfg["sweep_rounds"], quick=quick,
                                  command=command, opts={"sweep_throughput": cfg["sweep_throughput"]}))
    failed = [f for s in sessions for r in s.results for f in r.failures]
    if failed:
        raise RuntimeError("a case failed:\n" + "\n".join(failed))
    by = {r.case.name: r for s in sessions for r in s.results}
    res = figures(by["e2e"], by["beam_native"], by["mock_cast"],
                  [by[n] for n in ("curves", "sweep_throughput") if n in by])
    first = e2e
    res["meta"] = {"command": command, "scenario": scenario, "duration_s": cfg["e2e"]["duration"],
                   "rounds": cfg["rounds"], "renderer": renderer, "written_utc": first.written_utc,
                   "cores": first.machine["cores"], "machine": first.machine["cpu"], "python": first.machine["python"],
                   "load_average": [first.load_before, sessions[-1].load_after],
                   "commit": first.commits["perception"]}
    res["sessions"] = [to_json(s) for s in sessions]
    return res


def main(argv: list[str] | None = None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="short runs, one round: checks the script only")
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--renderer", default="gl", choices=("gl", "mock"), help="of the default run and the step")
    ap.add_argument("--out", type=Path, default=ROOT / "bench", help="folder of results.json and results.md")
    ap.add_argument("--no-curves", dest="curves", action="store_false", help="leave the cost curves out (the last results.md's are kept, with their origin)")
    a = ap.parse_args(argv)
    res = measure(a.quick, a.renderer, a.scenario, a.curves, "python bench/run_all.py " + shlex.join(argv))
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "results.json").write_text(json.dumps(res, indent=1, allow_nan=False) + "\n")
    md = render_markdown(res, a.quick)
    if not a.curves:
        md += kept_curves_section(a.out / "results.md")
    md += kept_suite_section(a.out / "results.md")
    (a.out / "results.md").write_text(md)
    print(md)
    return res


if __name__ == "__main__":
    main()
