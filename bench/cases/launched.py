"""Launched runs as a user makes them (``python launch.py run``): end to end, and start-up and teardown step by step.

``e2e``: one launched run per sample (``harness.launched``): wall time of the whole process and CPU time of its whole
process tree, the ring's real-time factor, start-up and shut-down from the launcher's last log line, the per-stage
medians of summary.json, the steady-state CPU per frame of every process (their sum over the core count is the
shortest frame the machine allows however well the stages overlap), the LiDAR range error and the fill.

``startup``: per sample a short perception run and the same scenario's ground-truth run (``--feedback ground_truth
--renderer none``), the order alternating with the round: each step from log.txt (the launcher's own start, set-up,
each child's start: interpreter and imports, create, start; the shut-down: children, outputs, figures) and the
perception run's excess over the ground-truth run less the renderer's start (the GL context), which should be at
most 0.
"""
from __future__ import annotations

import os
import re
import time

from harness import Context, case
from harness.launched import launch_run

__all__ = ["e2e", "fill_figures", "log_steps", "range_figures", "startup"]

#: the launcher's last log line: start-up to the first frame and shut-down by part
_LAUNCH = re.compile(r"start-up ([\d.]+) s to the first frame \(set-up before spawning ([\d.]+) s\), shut-down "
                     r"([\d.]+) s \(children ([\d.]+) s, outputs ([\d.]+) s, figures(?: and observers)? ([\d.]+) s\)")
#: a child's start line
_CHILD = re.compile(r"cosim\.(\w+): started \(pid \d+\) ([\d.]+) s after its spawn: interpreter and imports ([\d.]+) s, "
                    r"create ([\d.]+) s, start ([\d.]+) s")
_STAMP = re.compile(r"^(\d\d):(\d\d):(\d\d\.\d+) ")
#: the ground-truth run's launch.py arguments
GROUND_TRUTH = ("--feedback", "ground_truth", "--renderer", "none")
#: the fill figures of summary.json: column -> getter
_FILL = {"lowest section peak m": lambda f, s: min(f["section_peak_height_m"], default=None),
         "highest section peak m": lambda f, s: max(f["section_peak_height_m"], default=None),
         "max overfill m": lambda f, s: f.get("max_overfill_m"), "profile RMSE m": lambda f, s: f.get("profile_rmse_m"),
         "time to target s": lambda f, s: f.get("time_to_target_s"),
         "spill kg": lambda f, s: s.get("spill", {}).get("mass_kg"),
         "mass balance, relative error": lambda f, s: s.get("mass_balance", {}).get("relative_error")}


def log_steps(log: str, started: float) -> dict[str, float]:
    """Seconds of each start-up and teardown step in a run's log.txt (``started``: time.time() at the launch)."""
    out: dict[str, float] = {}
    first = next((m for m in map(_STAMP.match, log.splitlines()) if m), None)
    if first is not None:
        t = time.localtime(started)
        out["launcher start"] = (int(first.group(1)) * 3600 + int(first.group(2)) * 60 + float(first.group(3))
                                 - (t.tm_hour * 3600 + t.tm_min * 60 + t.tm_sec + started % 1.0))
    for m in _CHILD.finditer(log):
        for key, v in zip(("ready", "imports", "create", "start"), m.groups()[1:]):
            out[f"{m.group(1)} {key}"] = float(v)
    m = _LAUNCH.search(log)
    if m:
        out.update(zip(("first frame", "set-up", "shut-down", "children", "outputs", "figures"), map(float, m.groups())))
    return out


def fill_figures(summary: dict) -> dict:
    f = summary.get("fill") or {}
    f = {**f, "section_peak_height_m": f.get("section_peak_height_m") or []}
    return {k: get(f, summary) for k, get in _FILL.items()}


def range_figures(summary: dict) -> dict:
    """The LiDAR range error of summary.json in mm (empty where the run evaluated none)."""
    re_ = (summary.get("perception") or {}).get("range_error") or {}
    if not re_.get("frames_evaluated"):
        return {}
    mm = {k: (None if re_.get(k) is None else 1e3 * re_[k]) for k in ("mean_m", "median_m", "p99_m", "max_m",
                                                                      "working_p99_m")}
    above = re_.get("working_frac_above_5cm")
    return {"evaluation": re_.get("evaluation"), "frames evaluated": re_.get("frames_evaluated"),
            "mean mm": mm["mean_m"], "median mm": mm["median_m"], "p99 mm": mm["p99_m"], "max mm": mm["max_m"],
            "p99 in 2-15 m mm": mm["working_p99_m"],
            "% above 5 cm in 2-15 m": None if above is None else 100.0 * above}


@case("e2e", "launched runs end to end: wall, process-tree CPU, real-time factor, start-up, stages, CPU per frame "
      "of every process", options={"scenario": "default", "duration": 120.0, "members": True},
      quick={"duration": 2.0}, rounds=3, settings=True,
      compare=("wall s", "CPU s", "ring wall s", "real-time factor (ring)", "CPU ms per frame"))
def e2e(ctx: Context) -> dict:
    """One ``python launch.py run SCENARIO --duration D`` of the arm's tree and settings (module docstring);
    ``members``: sample each process's CPU per frame (the harness polls /proc every 50 ms)."""
    r = launch_run(ctx.tree, ctx["scenario"], ctx.launch_args(), duration=ctx["duration"], members=ctx["members"])
    s, steps = r["summary"], log_steps(r["log"], r["started"])
    period = s["sim_time_s"] / max(s["frames"] - 1, 1)
    row = {"frames": s["frames"], "wall s": r["wall_s"], "CPU s": r["cpu_s"], "ring wall s": s["wall_time_s"],
           "real-time factor (ring)": s["real_time_factor"], "real-time factor (whole process)":
           s["sim_time_s"] / r["wall_s"], "start-up s": steps.get("first frame"), "shut-down s": steps.get("shut-down"),
           "of which figures s": steps.get("figures")}
    out = {"run": {ctx["scenario"]: row},
           "per-stage medians of summary.json (ms)": {"ms": dict(s.get("timing_ms") or {})}}
    if r["cpu_ms"]:
        total = sum(r["cpu_ms"].values())
        cores = os.cpu_count() or 1
        out["CPU per frame, steady state"] = {**{m: {"CPU ms per frame": v} for m, v in r["cpu_ms"].items()},
                                              "all": {"CPU ms per frame": total}}
        row["CPU-bound real-time factor"] = 1e3 * period / (total / cores) if total > 0 else None
    rng = range_figures(s)
    if rng:
        out["LiDAR range error against the exact ray cast"] = {"mm": rng}
    out["fill"] = {ctx["scenario"]: fill_figures(s)}
    return out


@case("startup", "start-up and teardown step by step, a short perception run against its ground-truth run",
      options={"scenario": "default", "duration": 0.1}, rounds=5, settings=True,
      compare=("perception", "ground truth", "wall s", "CPU s"))
def startup(ctx: Context) -> dict:
    """A perception run and the ground-truth run of the same scenario (module docstring), order alternating by
    round; steps from log.txt, and the perception run's excess over the ground-truth run."""
    args = {"perception": ctx.launch_args(), "ground truth": [*ctx.launch_args(), *GROUND_TRUTH]}
    order = list(args) if ctx.round % 2 == 0 else list(args)[::-1]
    runs = {k: launch_run(ctx.tree, ctx["scenario"], args[k], duration=ctx["duration"]) for k in order}
    steps = {k: {"wall": r["wall_s"], "process-tree CPU": r["cpu_s"], **log_steps(r["log"], r["started"])}
             for k, r in runs.items()}
    table = {}
    for k in list(args):
        for step, v in steps[k].items():
            table.setdefault(step, {})[k] = v
    p, g = runs["perception"], runs["ground truth"]
    gl = steps["perception"].get("renderer start", 0.0)
    excess = {"wall s": p["wall_s"] - g["wall_s"], "CPU s": p["cpu_s"] - g["cpu_s"],
              "wall less the renderer's start s (target: at most 0)": p["wall_s"] - g["wall_s"] - gl}
    return {"steps (s)": table, "perception run less ground-truth run": {"difference": excess}}
