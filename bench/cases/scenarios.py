"""Every packaged scenario against the default run: wall time, real-time factor and where the frame goes.

``scenarios``: each packaged scenario (``python launch.py run NAME --duration D``, as packaged: its own feedback,
renderer and sensors) is a launched run (``harness.launched``: wall time of the whole process, CPU time of its
process tree, the steady-state CPU per frame of every member). Within one sample the scenarios are run
``repeats`` times, the order rotating each time (interleaved: a machine whose speed drifts weighs on every
scenario alike), and each repeat's ratios are taken to the same repeat's ``default`` run; the figures are medians
over the repeats. Per scenario: wall s and CPU s of the whole run and their ratios to the default's, the ring's
real-time factor, the per-stage medians of the run's timing (dynamics, render, perception, frame in ms:
summary.json's ``timing_ms``), the CPU ms per frame of every member and its ratio to the default's (steadier than
wall time on a shared machine), and the targets of the wall ratio where one is set (:data:`TARGETS`) and of the
real-time factor (:data:`RT_TARGET`).

``results=PATH`` writes the table, with the machine's load average before and after, as the section
:data:`SECTION` of PATH (bench/results.md; ``run_all.py`` keeps it). Each round writes its own table over the last
one's, and the section names the round: with ``--rounds N`` the medians over the rounds are in the printed output
only, so a table of medians in results.md comes from the repeats of one round (``--opt repeats=N``)::

    python bench/run.py scenarios --opt results=bench/results.md                 # every scenario, 60 s, 2 repeats
    python bench/run.py scenarios --opt scenarios=default,tof_mast --opt duration=5
    python bench/run.py scenarios --quick                                        # a check: 2 scenarios, 2 s
"""
from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

from harness import Context, case, rotating
from harness.launched import launch_run
from harness.report import put_results_section

__all__ = ["RT_TARGET", "SECTION", "TARGETS", "put_section", "scenarios"]

#: the heading of this case's section in bench/results.md
SECTION = "## Packaged scenarios against the default run"
#: scenario -> the most wall time it may take against the default run's
TARGETS = {"tof_mast": 2.0, "stereo_spout": 3.0, "dusty": 1.5, "dense_dust": 1.5, "rough_terrain": 1.5}
#: the least real-time factor (ring) of every packaged scenario
RT_TARGET = 3.0
#: the ring members whose CPU per frame is tabled
MEMBERS = ("dynamics", "renderer", "perception", "supervisor")


def _one(tree: Path, name: str, duration: float, args: list[str]) -> dict:
    """One launched run's figures (see the module docstring)."""
    r = launch_run(tree, name, args, duration=duration, members=True)
    s, t = r["summary"], r["summary"].get("timing_ms") or {}
    row = {"wall s": r["wall_s"], "CPU s": r["cpu_s"], "real-time factor (ring)": s["real_time_factor"],
           "frame ms": t.get("frame"), "dynamics ms": t.get("dynamics"), "render ms": t.get("render"),
           "perception ms": t.get("perception")}
    for m in MEMBERS:
        row[f"{m} CPU ms/frame"] = r["cpu_ms"].get(m)
    row["CPU ms/frame"] = sum(r["cpu_ms"].values()) if r["cpu_ms"] else None
    return row


def _median(rows: list[dict]) -> dict:
    """Column-wise medians of ``rows`` (None where no row has a value)."""
    out = {}
    for k in rows[0]:
        v = [r[k] for r in rows if isinstance(r.get(k), (int, float))]
        out[k] = statistics.median(v) if v else None
    return out


def _ratios(row: dict, base: dict) -> dict:
    """``row``'s wall, CPU and CPU per frame over ``base``'s (the same repeat's default run)."""
    def q(k: str):
        return row[k] / base[k] if row.get(k) and base.get(k) else None
    return {"wall / default": q("wall s"), "CPU / default": q("CPU s"),
            "CPU per frame / default": q("CPU ms/frame")}


def _verdict(name: str, row: dict) -> str:
    """Whether ``row`` meets its targets (wall ratio where set, real-time factor)."""
    parts = []
    if name in TARGETS and row.get("wall / default") is not None:
        ok = row["wall / default"] <= TARGETS[name]
        parts.append(f"wall <= {TARGETS[name]:g}x: {'met' if ok else 'NOT met'}")
    rt = row.get("real-time factor (ring)")
    if rt is not None:
        parts.append(f"RT >= {RT_TARGET:g}: {'met' if rt >= RT_TARGET else 'NOT met'}")
    return "; ".join(parts)


@case("scenarios", "every packaged scenario against the default run: wall, real-time factor (ring), where the "
      "frame goes (stage medians, CPU per frame of each member)",
      options={"scenarios": "all", "duration": 60.0, "repeats": 2, "results": ""},
      quick={"scenarios": "default,tof_mast", "duration": 2.0, "repeats": 1}, settings=True,
      compare=("wall s", "CPU s", "real-time factor (ring)", "CPU ms/frame"))
def scenarios(ctx: Context) -> dict:
    """``scenarios``: names (comma-separated) or ``all``, the default always among them; ``duration`` simulated
    s each; ``repeats``: interleaved repeats within the sample; ``results``: write the section (module
    docstring)."""
    from cosim.scenario.loader import packaged_scenarios
    from cosim.testing.load import load_average

    names = sorted(packaged_scenarios()) if ctx["scenarios"] == "all" else ctx["scenarios"].split(",")
    names = ["default"] + [n for n in names if n != "default"]
    load0, t0 = load_average(), time.time()
    runs: dict[str, list[dict]] = {n: [] for n in names}
    for rep in range(int(ctx["repeats"])):
        got = {n: _one(ctx.tree, n, float(ctx["duration"]), ctx.launch_args()) for n in rotating(names, rep)}
        for n in names:
            runs[n].append({**got[n], **_ratios(got[n], got["default"])})
    rows = {n: _median(r) for n, r in runs.items()}
    for n, row in rows.items():
        row["targets"] = _verdict(n, row)
    title = f"packaged scenarios, {ctx['duration']:g} s simulated, {ctx['repeats']} interleaved repeat(s), medians"
    out = {title: rows, "load": {"machine": {"cores": os.cpu_count(), "load average (1 min) at start": load0,
                                             "at end": load_average(), "minutes": (time.time() - t0) / 60.0}}}
    if ctx["results"] and not ctx.quick:
        put_section(ctx.path(ctx["results"]), out, ctx["duration"], int(ctx["repeats"]), ctx.round)
    return out


def _cell(v) -> str:
    if isinstance(v, float):
        return f"{v:.3g}" if abs(v) < 100 else f"{v:.0f}"
    return "-" if v is None else str(v)


def put_section(results_md: Path, tables: dict, duration: float, repeats: int, round_index: int = 0) -> None:
    """Write ``tables`` (round ``round_index``'s, from 0) as the section :data:`SECTION` of ``results_md``,
    replacing the one there."""
    lines = [SECTION, "", f"Written by `python bench/run.py scenarios --opt duration={duration:g} --opt "
             f"repeats={repeats} --opt results=bench/results.md` "
             f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}"
             + (f"; round {round_index + 1}, its own table: the medians over the rounds are in the run's output"
                if round_index else "") + "). Targets: wall against the default run "
             + ", ".join(f"`{n}` <= {v:g}x" for n, v in TARGETS.items())
             + f"; every scenario >= {RT_TARGET:g}x real time (ring). CPU per frame is the steadier figure on a "
             "shared machine.", ""]
    put_results_section(results_md, SECTION, lines[2:], tables, _cell)
