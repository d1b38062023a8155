"""End to end: real-time factor, per-stage medians and where the CPU goes, process by process (issue 6).

Runs ``python launch.py run SCENARIO --duration D --out DIR --quiet`` as a user would, ``--rounds`` times,
each round alternating a whole run with a short one (``--short`` simulated seconds: start-up and shut-down,
i.e. imports, GL context and shaders, beam tables, the run directory and figures). While a run lives the bench
samples the CPU time (user + system, from /proc, every :data:`POLL_S`) of the launcher and of every process
it starts, and names the ring members by the pids they log at start (``cosim.<name>: started (pid N)``).

Per process it reports the fixed cost (CPU of the short run) and the CPU per frame in steady state,
``(cpu_long - cpu_short) / (frames_long - frames_short)``; their sum over processes divided by the core count is
the lower bound that the machine puts on the frame time however well the stages overlap. The wall time splits
the same way into start-up (launch to the last "started" line), frames and shut-down (last frame to exit).
Medians over the rounds; the host is noisy, so compare rounds run interleaved, not runs from different hours.

Usage: ``python bench/e2e.py [--scenario default] [--duration 120] [--short 1] [--rounds 3] [--set PATH=VALUE]``.
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
#: sampling period of the /proc CPU counters, s (a process's last POLL_S of CPU before it exits is missed)
POLL_S = 0.02
_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")
_STARTED = re.compile(r"^(\d\d):(\d\d):(\d\d\.\d+) \S+\s+INFO\s+cosim\.(\w+): started \(pid (\d+)\)")
_FINISHED = re.compile(r"^(\d\d):(\d\d):(\d\d\.\d+) \S+\s+INFO\s+cosim\.(\w+): finished")
_LAUNCHED = re.compile(r"^(\d\d):(\d\d):(\d\d\.\d+) \S+\s+INFO\s+cosim\.launcher: run ")


def _cpu_s(pid: int) -> float | None:
    """User + system CPU time of ``pid`` so far, s (None once it is gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            s = f.read()
    except OSError:
        return None
    rest = s[s.rindex(")") + 2:].split()
    return (int(rest[11]) + int(rest[12])) * _TICK_S


def _children(pid: int) -> list[int]:
    out: list[int] = []
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as f:
                out += [int(x) for x in f.read().split()]
    except OSError:
        pass
    return out


def _cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _clock_s(m: re.Match) -> float:
    return int(m.group(1)) * 3600 + int(m.group(2)) * 60 + float(m.group(3))


def run_once(scenario: str, duration: float, sets: list[str], out: Path) -> dict:
    """One launched run: summary figures, CPU s per named process, wall split (s)."""
    cmd = [sys.executable, "launch.py", "run", scenario, "--duration", str(duration), "--out", str(out), "--quiet"]
    for s in sets:
        cmd += ["--set", s]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL)
    cpu: dict[int, float] = {}
    cmds: dict[int, str] = {}
    while proc.poll() is None:
        stack = [proc.pid]
        while stack:
            pid = stack.pop()
            c = _cpu_s(pid)
            if c is not None:
                cpu[pid] = c
                if pid not in cmds:
                    cmds[pid] = _cmdline(pid)
            stack += _children(pid)
        time.sleep(POLL_S)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with {proc.returncode}; see {out / 'log.txt'}")
    names = {proc.pid: "launcher"}
    started, finished, launched = [], [], None
    for line in (out / "log.txt").read_text().splitlines():
        if (m := _STARTED.match(line)):
            names[int(m.group(5))] = m.group(4)
            started.append(_clock_s(m))
        elif (m := _FINISHED.match(line)):
            finished.append(_clock_s(m))
        elif launched is None and (m := _LAUNCHED.match(line)):
            launched = _clock_s(m)
    by_name: dict[str, float] = {}
    for pid, c in cpu.items():
        name = names.get(pid) or ("resource tracker" if "resource_tracker" in cmds.get(pid, "") else "other")
        by_name[name] = by_name.get(name, 0.0) + c
    s = json.loads((out / "summary.json").read_text())
    split = {}
    if launched is not None and started and finished:
        split = {"start_s": max(started) - launched, "frames_s": max(finished) - max(started),
                 "end_s": (launched + wall) - max(finished)}     # launcher's first log line ~ process start
    return {"frames": s["frames"], "period_s": s["sim_time_s"] / max(s["frames"] - 1, 1), "rtf": s["real_time_factor"], "wall": wall, "timing": s["timing_ms"],
            "cpu": by_name, "split": split}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--duration", type=float, default=120.0, help="simulated seconds of the whole run")
    ap.add_argument("--short", type=float, default=1.0, help="simulated seconds of the start-up run")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="PATH=VALUE")
    args = ap.parse_args(argv)
    longs, shorts = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            shorts.append(run_once(args.scenario, args.short, args.sets, Path(tmp) / f"short{r}"))
            longs.append(run_once(args.scenario, args.duration, args.sets, Path(tmp) / f"long{r}"))
            print(f"round {r + 1}: {longs[-1]['rtf']:.2f}x real time, wall {longs[-1]['wall']:.1f} s, "
                  f"load {os.getloadavg()[0]:.2f}", file=sys.stderr, flush=True)
    med = statistics.median
    print(f"Scenario `{args.scenario}` {' '.join('--set ' + s for s in args.sets)}, {args.duration:g} s simulated "
          f"({longs[0]['frames']} frames), {args.rounds} rounds, {os.cpu_count()} cores, "
          f"{datetime.now():%Y-%m-%d %H:%M}\n")
    print("| real-time factor | wall s | start-up s | frames s | shut-down s | ms per frame | "
          + " | ".join(f"{k} ms (median)" for k in longs[0]["timing"]) + " |")
    print("|" + "---:|" * (6 + len(longs[0]["timing"])))
    sp = {k: med([r["split"].get(k, float("nan")) for r in longs]) for k in ("start_s", "frames_s", "end_s")}
    frame_ms = 1e3 * sp["frames_s"] / longs[0]["frames"]
    print(f"| {med([r['rtf'] for r in longs]):.2f} | {med([r['wall'] for r in longs]):.1f} | {sp['start_s']:.2f} | "
          f"{sp['frames_s']:.1f} | {sp['end_s']:.2f} | {frame_ms:.2f} | "
          + " | ".join(f"{med([r['timing'][k] for r in longs]):.2f}" for k in longs[0]["timing"]) + " |")
    names = sorted({n for r in longs + shorts for n, c in r["cpu"].items() if c > 0.0},
                   key=lambda n: -med([r["cpu"].get(n, 0.0) for r in longs]))
    dn = longs[0]["frames"] - shorts[0]["frames"]
    print("\n| process | CPU s, short run (fixed cost) | CPU s, whole run | CPU ms per frame (steady state) |")
    print("|---|---:|---:|---:|")
    total = 0.0
    for n in names:
        lo, hi = med([r["cpu"].get(n, 0.0) for r in shorts]), med([r["cpu"].get(n, 0.0) for r in longs])
        per = 1e3 * (hi - lo) / dn
        total += per
        print(f"| {n} | {lo:.2f} | {hi:.2f} | {per:.2f} |")
    cores = os.cpu_count() or 1
    print(f"| all | | | {total:.2f} |")
    print(f"\nCPU per frame {total:.2f} ms on {cores} cores: the frames cannot run faster than {total / cores:.2f} ms "
          f"each ({1e3 * longs[0]['period_s'] / (total / cores) if total else float('nan'):.1f}x real time at "
          f"{longs[0]['period_s']:g} s frames); measured "
          f"{frame_ms:.2f} ms per frame between the last start-up and the last finish.")


if __name__ == "__main__":
    main()
