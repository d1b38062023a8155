"""Reproduce the README's headline figures in one command, into ``bench/results.json`` and ``bench/results.md``.

What it measures (each figure names its source in the Markdown):

* the default run (``python launch.py run default``: GL, perception feedback) and the same scenario's
  ground-truth-only run (``--feedback ground_truth --renderer none``), ``--rounds`` of each, interleaved
  (A B, B A, ...): whole-process wall time, the CPU time of the whole process tree (the launcher, its children
  and theirs, reaped by this script as their subreaper, so a process that outlives its parent is counted too)
  and the ring's real-time factor (medians), and the perception run's cost over ground truth in wall time and
  in CPU time: the ratio of the medians, and the median (and range) of each round's own ratio, which cancels
  the VM's speed drifting between rounds (it drifts by up to 2x within an hour); the targets (at most
  :data:`TARGET_WALL` and :data:`TARGET_CPU`, medians of the rounds' own ratios) are checked;
* from the first default run's summary: fill (section peaks, max overfill, profile RMSE, time to target),
  spill, mass balance, and the LiDAR range error against the exact ray cast (mean, median, p99, max, share
  above 5 cm and p99 in 2-15 m); the ground-truth run's section peaks;
* the render + LiDAR step of ``sensor.method: beam_native`` against ``camera_rig`` on the same sample frames
  (``bench/beam_native.py``'s methods, interleaved per frame): CPU ms per frame and the ratio.

``--quick`` is a smoke test of the script itself (short runs, one round, few frames): its numbers are not
the headline figures. Usage::

    python bench/run_all.py                      # the headline figures (several minutes)
    python bench/run_all.py --quick --out /tmp/r # seconds to a minute: structure only
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

__all__ = ["RUNS", "launch", "main", "render_markdown", "step_ratio", "kept_suite_section"]

#: the two runs whose wall times are compared: label -> extra launch.py arguments
RUNS = {"perception": [], "ground_truth": ["--feedback", "ground_truth", "--renderer", "none"]}
#: the perception run's cost over the ground-truth run that the project aims at (medians of the rounds' own ratios)
TARGET_WALL, TARGET_CPU = 2.0, 3.0
#: how long the reaping waits for the processes that outlive a run's launcher (its resource tracker), s
REAP_S = 5.0
#: prctl option that makes this process the subreaper of its descendants
_PR_SET_CHILD_SUBREAPER = 36
#: full and quick settings: simulated seconds per run, interleaved rounds, sample frames of the step ratio
FULL = {"duration": 120.0, "rounds": 5, "frames": 40}
QUICK = {"duration": 3.0, "rounds": 1, "frames": 2}


def become_subreaper() -> bool:
    """Make this process the subreaper of its descendants (Linux), so that the CPU time of a process that
    outlives its parent (reparented here, reaped by :func:`reap`) is counted; False where it cannot."""
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def reap(timeout_s: float = REAP_S) -> None:
    """Wait for every remaining child (orphans reparented here included), up to ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            if time.monotonic() > deadline:
                return
            time.sleep(0.01)


def tree_cpu_s() -> float:
    """CPU time (user + system, s) of every child this process has reaped so far, and of their reaped children."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def launch(scenario: str, duration: float, extra: list[str]) -> dict:
    """One ``launch.py run`` from this tree: {"wall_s": whole process, "cpu_s": its whole process tree's CPU,
    "summary": summary.json}."""
    with tempfile.TemporaryDirectory(prefix="run-all-") as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "launch.py", "run", scenario, "--duration", str(duration), "--out", str(out),
               "--quiet", *extra]
        reap(0.0)
        c0 = tree_cpu_s()
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        wall = time.perf_counter() - t0
        reap()
        cpu = tree_cpu_s() - c0
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr[-2000:]}")
        summary = json.loads((out / "summary.json").read_text())
    return {"wall_s": wall, "cpu_s": cpu, "summary": summary}


def _fill(summary: dict) -> dict:
    f, m = summary.get("fill", {}), summary.get("mass_balance", {})
    peaks = f.get("section_peak_height_m") or []
    return {"section_peak_min_m": min(peaks) if peaks else None, "section_peak_max_m": max(peaks) if peaks else None,
            "max_overfill_m": f.get("max_overfill_m"), "profile_rmse_m": f.get("profile_rmse_m"),
            "time_to_target_s": f.get("time_to_target_s"), "spill_kg": summary.get("spill", {}).get("mass_kg"),
            "mass_balance_relative_error": m.get("relative_error")}


def _range_error(summary: dict) -> dict:
    re = summary.get("perception", {}).get("range_error", {})
    keys = ("evaluation", "frames_evaluated", "mean_m", "median_m", "p99_m", "max_m", "working_frac_above_5cm",
            "working_p99_m")
    return {k: re.get(k) for k in keys}


def step_ratio(frames: int, renderer: str) -> dict:
    """Render + LiDAR step CPU ms per frame of both sensor methods on the same sample frames (interleaved)."""
    import numpy as np
    from beam_native import BeamNative, CameraRig, timed

    from cosim.scenario.config import Scenario
    from cosim.world.scene import scene_from_state
    from renderer_proc.sample import sample_frame

    sc = Scenario(format_version=1)
    methods = {"camera_rig": CameraRig(sc, renderer), "beam_native": BeamNative(sc, renderer)}
    cpu = {k: [] for k in methods}
    for i, t in enumerate(np.linspace(0.0, 8.0, frames)):
        state, heights, stream = sample_frame(sc, float(t))
        scene = scene_from_state(sc, state, heights, stream)
        for k in (list(methods) if i % 2 == 0 else list(methods)[::-1]):
            cpu[k].append(timed(methods[k], scene, state)[1])
    med = {k: statistics.median(v) for k, v in cpu.items()}
    return {"renderer": renderer, "frames": frames, "camera_rig_cpu_ms": med["camera_rig"],
            "beam_native_cpu_ms": med["beam_native"], "ratio_cpu": med["beam_native"] / med["camera_rig"]}


def _med(runs: list[dict], get) -> float:
    return statistics.median(get(r) for r in runs)


def measure(scenario: str, duration: float, rounds: int, frames: int, renderer: str) -> dict:
    """Every figure (see the module docstring) as one JSON-able dict."""
    load0 = os.getloadavg()[0]
    runs: dict[str, list[dict]] = {k: [] for k in RUNS}
    labels = list(RUNS)
    for r in range(rounds):
        for lab in (labels if r % 2 == 0 else labels[::-1]):
            extra = RUNS[lab] if lab == "ground_truth" else RUNS[lab] + ["--renderer", renderer]
            runs[lab].append(launch(scenario, duration, extra))
            print(f"round {r + 1} {lab}: {runs[lab][-1]['wall_s']:.1f} s", file=sys.stderr, flush=True)
    out = {}
    for lab, rs in runs.items():
        out[lab] = {"wall_s": _med(rs, lambda x: x["wall_s"]), "cpu_s": _med(rs, lambda x: x["cpu_s"]),
                    "ring_wall_s": _med(rs, lambda x: x["summary"]["wall_time_s"]),
                    "real_time_factor": _med(rs, lambda x: x["summary"]["real_time_factor"]),
                    "fill": _fill(rs[0]["summary"])}
    out["perception"]["range_error"] = _range_error(runs["perception"][0]["summary"])
    pairs = list(zip(runs["perception"], runs["ground_truth"]))
    paired = {k: [a[k] / b[k] for a, b in pairs] for k in ("wall_s", "cpu_s")}
    out["ratio"] = {"wall": out["perception"]["wall_s"] / out["ground_truth"]["wall_s"],
                    "cpu": out["perception"]["cpu_s"] / out["ground_truth"]["cpu_s"],
                    "ring_wall": out["perception"]["ring_wall_s"] / out["ground_truth"]["ring_wall_s"],
                    "wall_paired": _spread(paired["wall_s"]), "cpu_paired": _spread(paired["cpu_s"])}
    out["targets"] = {"wall": TARGET_WALL, "cpu": TARGET_CPU,
                      "wall_met": out["ratio"]["wall_paired"]["median"] <= TARGET_WALL,
                      "cpu_met": out["ratio"]["cpu_paired"]["median"] <= TARGET_CPU}
    out["lidar_step"] = step_ratio(frames, renderer)
    out["meta"] = {"scenario": scenario, "duration_s": duration, "rounds": rounds, "renderer": renderer,
                   "written_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                   "cores": os.cpu_count(), "machine": platform.processor() or platform.machine(),
                   "python": platform.python_version(), "load_average": [load0, os.getloadavg()[0]],
                   "commit": _commit()}
    return out


def _spread(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def _commit() -> str | None:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def _mm(x) -> str:
    return "-" if x is None else f"{1e3 * x:.2f}"


def render_markdown(res: dict, quick: bool = False) -> str:
    """The results as Markdown (``bench/results.md``)."""
    m, p, g, re, st = res["meta"], res["perception"], res["ground_truth"], res["perception"]["range_error"], \
        res["lidar_step"]
    pf, gf = p["fill"], g["fill"]
    above = "-" if re["working_frac_above_5cm"] is None else f"{100 * re['working_frac_above_5cm']:.3f}"
    lines = [
        "# Current benchmark results", "",
        f"Written by `python bench/run_all.py{' --quick' if quick else ''}` at {m['written_utc']} from commit "
        f"`{m['commit']}`: {m['cores']} cores ({m['machine']}), Python {m['python']}, load average "
        f"{m['load_average'][0]:.1f} at the start and {m['load_average'][1]:.1f} at the end. Scenario "
        f"`{m['scenario']}`, {m['duration_s']:g} s simulated, {m['rounds']} interleaved round(s); medians. "
        "The dated log of earlier measurements is `bench/HISTORY.md`.", "",
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
        f"({'met' if t['cpu_met'] else 'NOT met'}).", "",
        "| fill | default | ground truth |", "|---|---:|---:|",
    ]
    for key, label in (("section_peak_min_m", "lowest section peak (m)"), ("section_peak_max_m",
                       "highest section peak (m)"), ("max_overfill_m", "max overfill (m)"),
                       ("profile_rmse_m", "profile RMSE (m)"), ("time_to_target_s", "time to target (s)"),
                       ("spill_kg", "spill (kg)"), ("mass_balance_relative_error", "mass balance, relative error")):
        cell = [("-" if d[key] is None else f"{d[key]:.4g}") for d in (pf, gf)]
        lines.append(f"| {label} | {cell[0]} | {cell[1]} |")
    lines += [
        "", f"LiDAR range error of the default run against the exact ray cast (evaluation: {re['evaluation']}; "
        f"{re['frames_evaluated']} frames): mean {_mm(re['mean_m'])} mm, median {_mm(re['median_m'])} mm, p99 "
        f"{_mm(re['p99_m'])} mm, max {_mm(re['max_m'])} mm; in 2-15 m: p99 {_mm(re['working_p99_m'])} mm, "
        f"{above} % of beams above 5 cm.", "",
        f"Render + LiDAR step, {st['renderer']}, {st['frames']} sample frames interleaved: beam_native "
        f"{st['beam_native_cpu_ms']:.2f} ms CPU against camera_rig {st['camera_rig_cpu_ms']:.2f} ms: "
        f"**{st['ratio_cpu']:.2f}x**.", "",
    ]
    return "\n".join(lines)


def kept_suite_section(results_md: Path) -> str:
    """The field-conditions suite's section of an existing ``results_md`` (written by bench/field_suite.py from
    its hours-long sweep, which this script does not rerun), or ""."""
    heading = "## Field-conditions suite"
    text = results_md.read_text() if results_md.exists() else ""
    return "\n" + heading + text.split(heading, 1)[1] if heading in text else ""


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="short runs, one round: checks the script only")
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--renderer", default="gl", choices=("gl", "mock"), help="of the default run and the step")
    ap.add_argument("--out", type=Path, default=ROOT / "bench", help="folder of results.json and results.md")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "bench"))                     # beam_native's methods for the step ratio
    cfg = QUICK if a.quick else FULL
    become_subreaper()
    res = measure(a.scenario, cfg["duration"], cfg["rounds"], cfg["frames"], a.renderer)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "results.json").write_text(json.dumps(res, indent=2) + "\n")
    md = render_markdown(res, a.quick)
    md += kept_suite_section(a.out / "results.md")
    (a.out / "results.md").write_text(md)
    print(md)
    return res


if __name__ == "__main__":
    main()
