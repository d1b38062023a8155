"""Interleaved A/B of whole launched runs: real-time factor, start-up and shut-down, CPU per process from /proc.

``python bench/ab_launch.py A=TREE_A B=TREE_B [--rounds 4] [--duration 30] [-- extra launch.py arguments]``
runs ``python launch.py run default --duration D --quiet --out TMP`` from each source tree in turn, the order
alternating every round (ABBA...), so that the load of a shared machine falls on both alike. For each run:

* process wall time (start of the launcher process to its exit) and the summary's ``wall_time_s`` (ring only);
* real-time factors: simulated s over the process wall time, and the summary's (over ``wall_time_s``);
* CPU seconds (user + system) of the launcher and of each participant process, sampled from /proc every
  POLL_S while it lives (the last sample, so up to POLL_S of a process's last CPU time can be missed), and of the
  whole process tree from wait4;
* where the tree logs them (this branch), the start-up and shut-down phases of the launcher's final log line.

Prints one Markdown table of medians per tree, and the per-round figures.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: seconds between /proc samples of the run's processes
POLL_S = 0.05
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")
_STARTED = re.compile(r"cosim\.(\w+): started \(pid (\d+)\)")
_PHASES = re.compile(r"start-up ([\d.]+) s to the first frame .* shut-down ([\d.]+) s \(children ([\d.]+) s, "
                     r"outputs ([\d.]+) s, figures ([\d.]+) s\)")


def _stat(pid: int) -> tuple[int, float] | None:
    """(parent pid, CPU s) of ``pid`` from /proc, or None once it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    fields = text.rsplit(")", 1)[1].split()
    return int(fields[1]), (int(fields[11]) + int(fields[12])) / CLOCK_TICKS


def _descendants(root: int) -> list[int]:
    kids: dict[int, list[int]] = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            st = _stat(int(d))
            if st is not None:
                kids.setdefault(st[0], []).append(int(d))
    out, todo = [], [root]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(kids.get(p, []))
    return out


def run_once(tree: Path, duration: float, extra: list[str]) -> dict:
    """One launched run from ``tree``; its figures (see the module docstring)."""
    out = Path(tempfile.mkdtemp(prefix="ab-"))
    cmd = [sys.executable, "launch.py", "run", "default", "--duration", str(duration), "--quiet", "--out",
           str(out / "run"), *extra]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=tree, stdout=subprocess.DEVNULL)
    cpu: dict[int, float] = {}
    while True:
        pid, status, ru = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        for pid in _descendants(proc.pid):
            st = _stat(pid)
            if st is not None:
                cpu[pid] = st[1]
        time.sleep(POLL_S)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} in {tree} exited with {proc.returncode}")
    summary = json.loads((out / "run" / "summary.json").read_text())
    log = (out / "run" / "log.txt").read_text()
    names = {int(pid): name for name, pid in _STARTED.findall(log)}
    res = {"wall_s": wall, "ring_wall_s": summary["wall_time_s"], "sim_s": summary["sim_time_s"],
           "rtf_process": summary["sim_time_s"] / wall, "rtf_summary": summary["real_time_factor"],
           "cpu_launcher_s": cpu.get(proc.pid, float("nan")),
           # the tree's total (the launcher and every process it waited for), the kernel's accounting at exit
           "cpu_tree_s": ru.ru_utime + ru.ru_stime}
    for pid, name in names.items():
        res[f"cpu_{name}_s"] = cpu.get(pid, float("nan"))
    res["cpu_others_s"] = sum(v for p, v in cpu.items() if p != proc.pid and p not in names)
    m = _PHASES.search(log)
    if m:
        for k, v in zip(("startup_s", "shutdown_s", "join_s", "outputs_s", "figures_s"), m.groups()):
            res[k] = float(v)
    shutil.rmtree(out, ignore_errors=True)
    return res


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("trees", nargs=2, metavar="NAME=TREE")
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--duration", type=float, default=30.0)
    args, extra = p.parse_known_args(argv)       # what is left (after --) goes to launch.py
    trees = [(n, Path(t).resolve()) for n, t in (a.split("=", 1) for a in args.trees)]
    extra = [a for a in extra if a != "--"]
    results: dict[str, list[dict]] = {n: [] for n, _ in trees}
    for r in range(args.rounds):
        order = trees if r % 2 == 0 else trees[::-1]
        for name, tree in order:
            res = run_once(tree, args.duration, extra)
            results[name].append(res)
            print(f"round {r + 1} {name}: " + ", ".join(f"{k} {v:.3f}" for k, v in res.items()), flush=True)
    keys = sorted({k for rs in results.values() for r in rs for k in r})
    print("\n| median | " + " | ".join(n for n, _ in trees) + " |")
    print("|---|" + "---:|" * len(trees))
    for k in keys:
        cells = []
        for n, _ in trees:
            vals = [r[k] for r in results[n] if k in r]
            cells.append(f"{statistics.median(vals):.3f}" if vals else "")
        print(f"| {k} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
