"""One run launched as a user launches it (``python launch.py run SCENARIO ...`` from a source tree): wall time of
the whole process, CPU time of its whole process tree, its summary and log, and optionally the steady-state CPU
per frame of every ring member.

While a run goes, its segment can be attached read-only (the name is in the run directory's ``run.json``) for the
ring members' pids (the supervisor is the launcher) and the supervisor's frame counter, and ``/proc/<pid>/stat``
is sampled every :data:`POLL_S`. A process's CPU per frame is the CPU (user + system) it used between the first
sample at or after frame :data:`SKIP_FRAMES` and the last sample, over the frames completed in between: steady
state, with start-up and teardown left out."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

from .proctree import become_subreaper, process_cpu_s, reap, tree_cpu_s

__all__ = ["MEMBERS", "POLL_S", "SKIP_FRAMES", "launch_run"]

#: sampling period of /proc and of the frame counter, s
POLL_S = 0.05
#: frames left out at the start of the CPU window (start-up transients)
SKIP_FRAMES = 20
#: processes whose CPU per frame is sampled: the ring members and the supervisor (the launcher process)
MEMBERS = ("dynamics", "renderer", "perception", "supervisor")


def _sample_members(proc: subprocess.Popen, out: Path) -> dict[str, float]:
    """Poll the run until it ends; CPU ms per frame of each member in steady state (see the module docstring)."""
    from shm_schema import Segment

    seg, pids, first, last, seen = None, {}, {}, {}, -1
    try:
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
    finally:
        if seg is not None:
            seg.close()
    return {m: 1e3 * (last[m][1] - first[m][1]) / max(last[m][0] - first[m][0], 1) for m in last}


def launch_run(tree: Path, scenario: str, args: Sequence[str] = (), *, duration: float | None = None,
               members: bool = False) -> dict:
    """Launch ``python launch.py run SCENARIO [--duration D] --out TMP --quiet ARGS`` from ``tree`` (its code first
    on PYTHONPATH) and wait for it. Returns ``wall_s`` (whole process), ``cpu_s`` (the CPU of its whole process
    tree, orphans included: this process is made the subreaper of its descendants), ``summary`` (summary.json),
    ``log`` (log.txt), ``started`` (time.time() at the launch) and, with ``members``, ``cpu_ms`` (member -> CPU ms
    per frame in steady state). Raises RuntimeError when the run fails or does not complete."""
    become_subreaper()
    with tempfile.TemporaryDirectory(prefix="bench-run-") as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "launch.py", "run", scenario, "--out", str(out), "--quiet", *args]
        if duration is not None:
            cmd[4:4] = ["--duration", f"{duration:g}"]
        env = dict(os.environ, PYTHONPATH=str(tree))
        reap(0.0)
        c0, started, t0 = tree_cpu_s(), time.time(), time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        cpu_ms = _sample_members(proc, out) if members else {}
        _, err = proc.communicate()
        wall = time.perf_counter() - t0
        reap()
        cpu = tree_cpu_s() - c0
        summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
        log = (out / "log.txt").read_text() if (out / "log.txt").exists() else ""
    if proc.returncode != 0 or not summary.get("completed"):
        raise RuntimeError(f"{' '.join(cmd)} in {tree} failed ({proc.returncode}): {(err or '')[-2000:]}")
    return {"wall_s": wall, "cpu_s": cpu, "summary": summary, "log": log, "started": started, "cpu_ms": cpu_ms}
