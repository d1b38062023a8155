"""Start-up and teardown of a run, step by step: the perception run against the ground-truth run.

Each round launches ``python launch.py run SCENARIO --duration D --out TMP --quiet`` (a short run: the default
0.1 s is frames 0 and 1, so nearly all of it is start-up and teardown) once as the default perception run and once
as the ground-truth run (``--feedback ground_truth --renderer none``), the order alternating, optionally for
several source trees (``--tree name=PATH``, interleaved). Per run:

* wall time of the whole process and CPU time of its whole process tree (this script is the subreaper of its
  descendants and reaps every one, so processes that outlive their parent are counted);
* from log.txt: the launcher's own start (process start to its first log line: interpreter, command line,
  scenario), the start-up to frame 0 and the set-up before the children start, each child's start (``started
  ... after its spawn``: interpreter and imports, create, start: the renderer's GL context and shaders are its
  start), and the shut-down (children, outputs, figures);
* the start-up target: the perception run's wall no more than the ground-truth run's plus the renderer's start
  (the GL context).

Prints Markdown, medians over the rounds (min-max). Usage::

    python bench/startup.py --rounds 5
    python bench/startup.py --tree base=/tmp/base --tree new=. --rounds 4
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
sys.path.insert(0, str(ROOT / "bench"))

from proctree import become_subreaper, reap, tree_cpu_s  # noqa: E402

#: the two runs compared: label -> extra launch.py arguments
RUNS = {"perception": [], "ground_truth": ["--feedback", "ground_truth", "--renderer", "none"]}
_STAMP = re.compile(r"^(\d\d):(\d\d):(\d\d\.\d+) ")
_CHILD = re.compile(r"cosim\.(\w+): started \(pid \d+\) ([\d.]+) s after its spawn: interpreter and imports ([\d.]+) s, "
                    r"create ([\d.]+) s, start ([\d.]+) s")
_LAUNCH = re.compile(r"start-up ([\d.]+) s to the first frame \(set-up before spawning ([\d.]+) s\), shut-down "
                     r"([\d.]+) s \(children ([\d.]+) s, outputs ([\d.]+) s, figures ([\d.]+) s\)")


def _seconds_of_day(line: str) -> float | None:
    m = _STAMP.match(line)
    return None if m is None else int(m.group(1)) * 3600 + int(m.group(2)) * 60 + float(m.group(3))


def one_run(tree: Path, scenario: str, duration: float, extra: list[str]) -> dict:
    """One launched run from ``tree``: wall, tree CPU and the log's steps (s)."""
    with tempfile.TemporaryDirectory(prefix="startup-") as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "launch.py", "run", scenario, "--duration", str(duration), "--out", str(out),
               "--quiet", *extra]
        env = dict(os.environ, PYTHONPATH=str(tree))
        reap(0.0)
        c0, t0 = tree_cpu_s(), time.time()
        proc = subprocess.run(cmd, cwd=tree, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        wall = time.time() - t0
        reap()
        cpu = tree_cpu_s() - c0
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr[-2000:]}")
        log = (out / "log.txt").read_text().splitlines()
    res = {"wall_s": wall, "cpu_s": cpu}
    first = next((s for s in map(_seconds_of_day, log) if s is not None), None)
    if first is not None:
        start = time.localtime(t0)
        res["launcher_s"] = first - (start.tm_hour * 3600 + start.tm_min * 60 + start.tm_sec + t0 % 1.0)
    for line in log:
        m = _CHILD.search(line)
        if m:
            name = m.group(1)
            for key, v in zip(("ready", "imports", "create", "start"), m.groups()[1:]):
                res[f"{name}.{key}_s"] = float(v)
        m = _LAUNCH.search(line)
        if m:
            res.update(zip(("first_frame_s", "setup_s", "shutdown_s", "children_s", "outputs_s", "figures_s"),
                           map(float, m.groups())))
    return res


def _cell(values: list[float]) -> str:
    return f"{statistics.median(values):.2f} ({min(values):.2f}-{max(values):.2f})" if values else "-"


def report(tree: str, runs: dict[str, list[dict]]) -> dict:
    keys = sorted({k for rs in runs.values() for r in rs for k in r}, key=lambda k: (("." in k), k))
    print(f"\n### {tree}\n\n| step (s) | " + " | ".join(runs) + " |\n|---|" + "---:|" * len(runs))
    for k in keys:
        print(f"| {k} | " + " | ".join(_cell([r[k] for r in rs if k in r]) for rs in runs.values()) + " |")
    p, g = runs["perception"], runs["ground_truth"]
    wall = [a["wall_s"] - b["wall_s"] for a, b in zip(p, g)]
    gl = [r.get("renderer.start_s", 0.0) for r in p]
    excess = [w - s for w, s in zip(wall, gl)]
    print(f"\nperception run minus ground-truth run: wall {_cell(wall)} s, CPU "
          f"{_cell([a['cpu_s'] - b['cpu_s'] for a, b in zip(p, g)])} s; minus the renderer's start (GL context): "
          f"{_cell(excess)} s (target: at most 0)")
    return {"wall_excess_s": statistics.median(excess)}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=0.1, help="simulated seconds per run")
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--tree", action="append", default=[], metavar="NAME=PATH", help="source trees (A/B)")
    a = ap.parse_args(argv)
    trees = dict(t.split("=", 1) for t in a.tree) or {"this tree": str(ROOT)}
    become_subreaper()
    runs = {t: {lab: [] for lab in RUNS} for t in trees}
    arms = [(t, lab) for t in trees for lab in RUNS]
    for r in range(a.rounds):
        for t, lab in (arms if r % 2 == 0 else arms[::-1]):
            runs[t][lab].append(one_run(Path(trees[t]).resolve(), a.scenario, a.duration, RUNS[lab]))
            print(f"round {r + 1} {t} {lab}: {runs[t][lab][-1]['wall_s']:.2f} s", file=sys.stderr, flush=True)
    print(f"Start-up and teardown, `{a.scenario}`, {a.duration:g} s simulated, {a.rounds} interleaved rounds; "
          f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}, {datetime.now():%Y-%m-%d %H:%M}; medians (min-max).")
    out = {t: report(t, rs) for t, rs in runs.items()}
    print("\n" + json.dumps(out))
    return out


if __name__ == "__main__":
    main()
