"""Interleaved A/B of the perception stages of two or more source trees on one replayed recording.

Each round runs ``python bench/perception_replay.py replay RECORDING --stages`` once in every tree (its own
harness on its own code: ``run_stages`` times each stage over all recorded frames after a warm-up call), the
order alternating from round to round (A B, B A, ...) so that a noisy host's load falls on all alike. Prints per
stage the median over the rounds of the CPU ms per call (process time, which another process's load disturbs
less than wall time), with the range, and for each tree after the first the ratio of the medians of the
``--sum`` stages to the first tree's.

Run from the repository root, e.g. (record the workload first: ``bench/perception_replay.py``)::

    python bench/perception_ab.py bench/out/replay/default.npz --tree main=/work/main --tree new=. --rounds 8
"""
from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
from pathlib import Path

#: one row of perception_replay's stage table: | stage | calls | wall ms per call | CPU ms per call |
_ROW = re.compile(r"^\| (\w+) \| (\d+) \| ([\d.]+) \| ([\d.]+) \|$", re.M)


def replay_stages(tree: Path, recording: Path, repeat: int) -> dict[str, float]:
    """CPU ms per call of every stage, from one replay in ``tree`` (run with the tree as working directory)."""
    cmd = [sys.executable, str(tree / "bench" / "perception_replay.py"), "replay", str(recording), "--stages",
           "--repeat", str(repeat)]
    out = subprocess.run(cmd, cwd=tree, capture_output=True, text=True, check=True).stdout
    rows = {m.group(1): float(m.group(4)) for m in _ROW.finditer(out)}
    if not rows:
        raise RuntimeError(f"no stage table in the output of {' '.join(cmd)}:\n{out}")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recording", type=Path)
    ap.add_argument("--tree", action="append", required=True, metavar="NAME=PATH",
                    help="a source tree to measure (two or more; the first is the baseline)")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=2, help="passes over the recording per replay")
    ap.add_argument("--sum", default="cart,heightmap", help="stages whose summed cost is compared")
    a = ap.parse_args()
    trees = [(n, Path(p).resolve()) for n, _, p in (t.partition("=") for t in a.tree)]
    recording = a.recording.resolve()
    got: dict[str, list[dict[str, float]]] = {n: [] for n, _ in trees}
    for r in range(a.rounds):
        for name, path in (trees if r % 2 == 0 else trees[::-1]):
            got[name].append(replay_stages(path, recording, a.repeat))
        print(f"round {r + 1}/{a.rounds} done", file=sys.stderr)
    summed = a.sum.split(",")
    stages = list(got[trees[0][0]][0])
    print(f"CPU ms per call, median over {a.rounds} interleaved rounds (min-max); {recording.name}")
    print("| stage | " + " | ".join(n for n, _ in trees) + " |")
    print("|---|" + "---:|" * len(trees))
    for s in stages + ["+".join(summed)]:
        cells = []
        for n, _ in trees:
            v = [sum(row[k] for k in summed) if "+" in s else row[s] for row in got[n]]
            cells.append(f"{statistics.median(v):.3f} ({min(v):.3f}-{max(v):.3f})")
        print(f"| {s} | " + " | ".join(cells) + " |")
    base = statistics.median(sum(row[k] for k in summed) for row in got[trees[0][0]])
    for n, _ in trees[1:]:
        m = statistics.median(sum(row[k] for k in summed) for row in got[n])
        print(f"{n}: {'+'.join(summed)} {m:.3f} ms against {base:.3f} ms, {100 * (m / base - 1):+.1f} %")


if __name__ == "__main__":
    main()
