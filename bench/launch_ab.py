"""Interleaved A/B of launched runs: wall time and per-process CPU per frame, for two (or more) source trees.

Run: ``python bench/launch_ab.py --tree main=/work/main --tree branch=. --rounds 4 --duration 30`` (from the
repository root). Each round launches ``python launch.py run <scenario> --duration D --quiet`` once per tree, in
turn (A, B, A, B, ...), so that load from other jobs spreads over both sides. While a run is going, the
launcher's segment is attached read-only (its name is in the run directory's ``run.json``) for the ring
members' pids and frame counters, and ``/proc/<pid>/stat`` is sampled every :data:`POLL_S`: a process's CPU per
frame is the CPU it used (user + system) between the first sample at or after frame :data:`SKIP_FRAMES` and the
last sample, divided by the frames the ring completed in between (start-up, imports and GL context creation
are left out, so are the flush and teardown). Prints a Markdown table of medians over the rounds (and the
range), then every round's figures. ``OPENBLAS_NUM_THREADS`` is left as the launcher sets it.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from shm_schema import Segment  # noqa: E402

#: sampling period of /proc, s
POLL_S = 0.05
#: frames left out at the start (start-up transients), frames
SKIP_FRAMES = 20
#: ring members whose CPU is reported (the supervisor is the launcher process itself)
MEMBERS = ("dynamics", "renderer", "perception", "supervisor")
_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def _cpu_s(pid: int) -> float | None:
    """User + system CPU of ``pid`` so far, s (None once it has gone)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) * _TICK_S             # utime, stime (fields 14, 15)


def one_run(tree: Path, scenario: str, duration: float, extra: list[str]) -> dict:
    """Launch one run from ``tree``; returns wall time, frames and CPU ms per frame by member."""
    with tempfile.TemporaryDirectory(prefix="ab-") as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "launch.py", "run", scenario, "--duration", str(duration), "--out", str(out),
               "--quiet", *extra]
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
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
                cpu = _cpu_s(pid)
                if cpu is not None:
                    first.setdefault(m, (frame, cpu))
                    last[m] = (frame, cpu)
        wall = time.perf_counter() - t0
        if seg is not None:
            seg.close()
        err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
        summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
    if proc.returncode != 0 or not summary.get("completed"):
        raise RuntimeError(f"run from {tree} failed ({proc.returncode}): {err[-2000:]}")
    cpu = {m: 1e3 * (last[m][1] - first[m][1]) / max(last[m][0] - first[m][0], 1) for m in last}
    return {"wall_s": wall, "run_wall_s": summary.get("wall_time_s"), "frames": summary.get("frames"),
            "rtf": summary.get("real_time_factor"), "cpu_ms": cpu, "timing_ms": summary.get("timing_ms", {}),
            "perception_ms": summary.get("perception", {}).get("timing_ms", {})}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", action="append", required=True, metavar="LABEL=PATH",
                    help="a source tree to launch from (repeat; two or more)")
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--set", action="append", default=[], metavar="PATH=VALUE", help="passed to launch.py")
    a = ap.parse_args()
    trees = [(lab, Path(p).resolve()) for lab, _, p in (t.partition("=") for t in a.tree)]
    extra = [x for s in a.set for x in ("--set", s)]
    runs: dict[str, list[dict]] = {lab: [] for lab, _ in trees}
    for r in range(a.rounds):
        for lab, path in (trees if r % 2 == 0 else trees[::-1]):
            res = one_run(path, a.scenario, a.duration, extra)
            runs[lab].append(res)
            print(f"round {r + 1} {lab}: " + json.dumps({k: res[k] for k in ("run_wall_s", "rtf", "cpu_ms")}),
                  file=sys.stderr)
    cols = [("real-time factor", lambda x: x["rtf"]), ("run wall s", lambda x: x["run_wall_s"])]
    cols += [(f"{m} CPU ms/frame", lambda x, m=m: x["cpu_ms"].get(m)) for m in MEMBERS]
    print(f"{a.scenario}, {a.duration:g} s simulated, {a.rounds} interleaved rounds: median (range)\n")
    print("| tree | " + " | ".join(c for c, _ in cols) + " |")
    print("|---|" + "---:|" * len(cols))
    for lab, _ in trees:
        cells = []
        for _, get in cols:
            v = [get(x) for x in runs[lab] if get(x) is not None]
            cells.append(f"{statistics.median(v):.2f} ({min(v):.2f}-{max(v):.2f})" if v else "")
        print(f"| {lab} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
