"""End to end: launched runs as a user makes them; real-time factor, start-up and shut-down, per-stage
medians, and the CPU per frame of every process, for one source tree or several interleaved (A/B).

Run from the repository root::

    python bench/e2e.py --rounds 3 --duration 120                    # this tree: where the time goes
    python bench/e2e.py --tree main=/work/main --tree new=. --rounds 6 --duration 30    # A/B, interleaved
    python bench/e2e.py --variant rig=sensor.method=camera_rig --variant beams=sensor.method=beam_native
                                                                     # A/B of settings, this tree, interleaved
    python bench/e2e.py --variant perception=feedback=perception --variant gt=feedback=ground_truth \
        --variant gt=renderer=none                                   # an arm with two settings

Each round launches ``python launch.py run SCENARIO --duration D --out TMP --quiet`` once per tree, the order
alternating every round (A B, B A, ...) so that a noisy host's load falls on both alike. While a run goes, its
segment is attached read-only (the name is in the run directory's ``run.json``) for the ring members' pids
(the supervisor is the launcher) and the supervisor's frame counter, and ``/proc/<pid>/stat`` is sampled every
:data:`POLL_S`. A process's CPU per frame is the CPU (user + system) it used between the first sample at or
after frame :data:`SKIP_FRAMES` and the last sample, over the frames completed in between: steady state, with
start-up and teardown left out. Their sum divided by the core count is the shortest frame the machine allows
however well the stages overlap. Start-up (launch to the first frame) and shut-down (children, outputs,
figures) come from the launcher's last log line. Prints one Markdown table per tree: medians over the rounds
(min-max).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from shm_schema import Segment  # noqa: E402

#: sampling period of /proc and of the frame counter, s
POLL_S = 0.05
#: frames left out at the start of the CPU window (start-up transients)
SKIP_FRAMES = 20
#: processes whose CPU is reported: the ring members and the supervisor (the launcher process)
MEMBERS = ("dynamics", "renderer", "perception", "supervisor")
_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")
_PHASES = re.compile(r"start-up ([\d.]+) s to the first frame .* shut-down ([\d.]+) s \(children ([\d.]+) s, "
                     r"outputs ([\d.]+) s, figures ([\d.]+) s\)")


def process_cpu_s(pid: int) -> float | None:
    """User + system CPU of ``pid`` so far, s (None once it has gone)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) * _TICK_S             # utime, stime (fields 14, 15)


def one_run(tree: Path, scenario: str, duration: float, extra: list[str]) -> dict:
    """Launch one run from ``tree``; returns its figures (see the module docstring)."""
    with tempfile.TemporaryDirectory(prefix="e2e-") as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "launch.py", "run", scenario, "--duration", str(duration), "--out", str(out),
               "--quiet", *extra]
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        seg, pids, first, last, seen = None, {}, {}, {}, -1
        while proc.poll() is None:
            time.sleep(POLL_S)
            if seg is None:
                try:
                    seg = Segment.attach(json.loads((out / "run.json").read_text())["segment"])
                except (OSError, ValueError, KeyError):
                    continue
            if len(pids) < len(MEMBERS):                           # children fill their slots as they start
                pids = {m: int(seg.slot(m)["pid"]) for m in MEMBERS if m in seg.schema.participants}
                pids = {m: p for m, p in pids.items() if p > 0}
                continue
            frame = int(seg.slot("supervisor")["frame"])
            if frame < SKIP_FRAMES or frame <= seen:               # before the window, or the ring is done
                continue
            seen = frame
            for m, pid in pids.items():
                cpu = process_cpu_s(pid)
                if cpu is not None:
                    first.setdefault(m, (frame, cpu))
                    last[m] = (frame, cpu)
        wall = time.perf_counter() - t0
        if seg is not None:
            seg.close()
        err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
        summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
        log = (out / "log.txt").read_text() if (out / "log.txt").exists() else ""
    if proc.returncode != 0 or not summary.get("completed"):
        raise RuntimeError(f"run from {tree} failed ({proc.returncode}): {err[-2000:]}")
    res = {"wall_s": wall, "rtf_process": summary["sim_time_s"] / wall, "rtf": summary["real_time_factor"],
           "frames": summary["frames"], "period_s": summary["sim_time_s"] / max(summary["frames"] - 1, 1),
           "timing_ms": summary.get("timing_ms", {}),
           "range_error": summary.get("perception", {}).get("range_error", {}),
           "cpu_ms": {m: 1e3 * (last[m][1] - first[m][1]) / max(last[m][0] - first[m][0], 1) for m in last}}
    m = _PHASES.search(log)
    if m:
        res.update(zip(("startup_s", "shutdown_s", "join_s", "outputs_s", "figures_s"), map(float, m.groups())))
    return res


def _cell(values: list[float]) -> str:
    return f"{statistics.median(values):.2f} ({min(values):.2f}-{max(values):.2f})" if values else ""


def report(label: str, runs: list[dict]) -> None:
    """Print one tree's Markdown tables (medians over its runs, min-max)."""
    cols = [("real-time factor, whole process", lambda r: r["rtf_process"]),
            ("real-time factor, ring (summary)", lambda r: r["rtf"]), ("wall s", lambda r: r["wall_s"]),
            ("start-up s", lambda r: r.get("startup_s")), ("shut-down s", lambda r: r.get("shutdown_s")),
            ("of which figures s", lambda r: r.get("figures_s"))]
    stages = list(runs[0]["timing_ms"])
    cols += [(f"{k} ms (median)", lambda r, k=k: r["timing_ms"].get(k)) for k in stages]
    print(f"**{label}**\n")
    print("| " + " | ".join(c for c, _ in cols) + " |")
    print("|" + "---:|" * len(cols))
    print("| " + " | ".join(_cell([v for r in runs if (v := get(r)) is not None]) for _, get in cols) + " |")
    errs = [r["range_error"] for r in runs if r.get("range_error")]
    if errs:
        keys = ("mean_m", "p99_m", "max_m", "working_p99_m")
        print("\n| range error (mm) | " + " | ".join(k[:-2] for k in keys) + " | working share above 5 cm (%) |")
        print("|---|" + "---:|" * (len(keys) + 1))
        cells = [_cell([1e3 * e[k] for e in errs if e.get(k) is not None]) for k in keys]
        cells.append(_cell([100.0 * e["working_frac_above_5cm"] for e in errs
                            if e.get("working_frac_above_5cm") is not None]))
        print("| median over runs | " + " | ".join(cells) + " |")
    print("\n| process | CPU ms per frame (steady state) |")
    print("|---|---:|")
    total = []
    for m in MEMBERS:
        v = [r["cpu_ms"][m] for r in runs if m in r["cpu_ms"]]
        if v:
            print(f"| {m} | {_cell(v)} |")
    for r in runs:
        total.append(sum(r["cpu_ms"].values()))
    cores = os.cpu_count() or 1
    bound = statistics.median(total) / cores
    print(f"| all | {_cell(total)} |\n")
    if bound <= 0.0:                                         # no member process was sampled (in-process run)
        return
    print(f"{statistics.median(total):.2f} ms of CPU per frame on {cores} cores: no frame shorter than {bound:.2f} ms "
          f"({1e3 * runs[0]['period_s'] / bound:.1f}x real time at {runs[0]['period_s']:g} s frames) however the "
          "stages overlap.\n")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", action="append", metavar="LABEL=PATH",
                    help="a source tree to launch from (repeatable; default: this repository)")
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--duration", type=float, default=120.0, help="simulated seconds per run")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--set", action="append", default=[], metavar="PATH=VALUE", help="passed to launch.py")
    ap.add_argument("--variant", action="append", default=[], metavar="LABEL=PATH=VALUE",
                    help="this tree with one more --set PATH=VALUE, as one arm of the A/B (repeatable; a label "
                         "given again adds its setting to that arm)")
    a = ap.parse_args(argv)
    trees = [(lab, Path(p).resolve(), []) for lab, _, p in (t.partition("=") for t in (a.tree or []))]
    variants: dict[str, list[str]] = {}                         # a label given again adds its setting
    for lab, _, setting in (v.partition("=") for v in a.variant):
        variants.setdefault(lab, []).extend(["--set", setting])
    trees += [(lab, ROOT, own) for lab, own in variants.items()]
    trees = trees or [("this", ROOT, [])]
    extra = [x for s in a.set for x in ("--set", s)]
    runs: dict[str, list[dict]] = {lab: [] for lab, _, _ in trees}
    for r in range(a.rounds):
        for lab, path, own in (trees if r % 2 == 0 else trees[::-1]):
            res = one_run(path, a.scenario, a.duration, extra + own)
            runs[lab].append(res)
            print(f"round {r + 1} {lab}: {res['rtf_process']:.2f}x real time (whole process), load "
                  f"{os.getloadavg()[0]:.2f}", file=sys.stderr, flush=True)
    print(f"Scenario `{a.scenario}` {' '.join('--set ' + s for s in a.set)}, {a.duration:g} s simulated, "
          f"{a.rounds} interleaved rounds, {os.cpu_count()} cores, {datetime.now():%Y-%m-%d %H:%M}: median "
          "(min-max)\n")
    for lab, _, own in trees:
        if own:
            print(f"**{lab}**: {' '.join(own)}\n")
        report(lab, runs[lab])


if __name__ == "__main__":
    main()
