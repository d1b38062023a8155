"""Bit-identity check of a source tree's results against a reference (for optimisations that must not change them).

``record OUT [--src TREE]`` writes into OUT, from the code in TREE (default: this checkout):

* ``gt/``: the run directory of ``python launch.py run default --feedback ground_truth --renderer none`` (1201
  frames over the launched process ring);
* ``gt-<scenario>/``: the same for every other packaged scenario (curved path, stiff drivetrain, other strategies
  and crops, ...) and for the default scenario with the RK4 integrator, without figures;
* ``perception.npz``: an in-process run (:func:`cosim.runtime.inprocess.simulate`) of the default scenario with perception
  feedback (renderer ``--renderer``, default gl; ``--duration`` s, default the scenario's 120 s): every
  timeseries column and the final array blocks.

``compare A B`` compares two such directories: every timeseries column except the wall-clock ``*_ms`` ones and the
final height maps must be equal bit for bit (NaN equal to NaN). Exit status 0 when identical, 1 otherwise, with
the first differences listed.

Run: ``python bench/identity.py record /tmp/ref --src /path/to/base`` before a change, ``python bench/identity.py
record /tmp/new`` after it, then ``python bench/identity.py compare /tmp/ref /tmp/new``.
"""
from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

#: final array blocks compared bit for bit
MAPS = ("heightmap_truth", "heightmap_perceived")
#: columns whose values are wall-clock times (never reproducible)
WALL_SUFFIX = "_ms"


#: extra ground-truth runs: directory name -> launch.py arguments after ``run``
EXTRA_GT = {
    **{f"gt-{n}": [n] for n in ("back_to_front", "curved_pass", "fast_harvest", "grazing_sensor", "heavy_noise",
                                "high_flow", "lowest_first", "misaligned_start", "near_alpha", "soybeans",
                                "stiff_drivetrain")},
    "gt-default-rk4": ["default", "--set", "integrator.method=rk4"],
}


#: every ground-truth run directory
GT_DIRS = ("gt", *sorted(EXTRA_GT))


def _record_gt(tree: Path, out: Path) -> None:
    subprocess.run([sys.executable, "launch.py", "run", "default", "--feedback", "ground_truth", "--renderer",
                    "none", "--quiet", "--out", str(out / "gt")], cwd=tree, check=True, stdout=subprocess.DEVNULL)
    for name, args in EXTRA_GT.items():
        subprocess.run([sys.executable, "launch.py", "run", *args, "--feedback", "ground_truth", "--renderer", "none",
                        "--set", "outputs.figures=false", "--quiet", "--out", str(out / name)], cwd=tree, check=True,
                       stdout=subprocess.DEVNULL)


def _record_perception(tree: Path, out: Path, renderer: str, duration: float | None) -> None:
    code = (
        "import sys, numpy as np\n"
        "from cosim.scenario.loader import load_scenario, resolve_scenario_arg\n"
        "from cosim.runtime.inprocess import simulate\n"
        "extra = {'renderer': sys.argv[2]}\n"
        "if sys.argv[3] != 'None': extra['duration_s'] = float(sys.argv[3])\n"
        "s = load_scenario(resolve_scenario_arg('default'), extra=extra)\n"
        "r = simulate(s)\n"
        "d = {'series.' + k: v for k, v in r.recorder.series().items()}\n"
        "d.update({'array.' + k: v for k, v in r.recorder.arrays.items()})\n"
        "np.savez(sys.argv[1], **d)\n"
    )
    env = dict(os.environ, PYTHONPATH=str(tree))
    subprocess.run([sys.executable, "-c", code, str(out / "perception.npz"), renderer, str(duration)], cwd=tree,
                   env=env, check=True)


def _csv_columns(path: Path) -> dict[str, list[str]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return {h: [r[i] for r in rows[1:]] for i, h in enumerate(rows[0])}


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def compare(a: Path, b: Path) -> list[str]:
    """Differences between two recorded directories (empty when bit-identical)."""
    diffs: list[str] = []
    checked = 0
    for run in GT_DIRS:
        if not (a / run).exists() or not (b / run).exists():
            diffs.append(f"{run}: missing in {a if not (a / run).exists() else b}")
            continue
        ca, cb = _csv_columns(a / run / "timeseries.csv"), _csv_columns(b / run / "timeseries.csv")
        checked += len(ca)
        if list(ca) != list(cb):
            diffs.append(f"{run}: columns differ: {sorted(set(ca) ^ set(cb))}")
        for k in ca:
            if k.endswith(WALL_SUFFIX) or k not in cb:
                continue
            if ca[k] != cb[k]:
                i = next((i for i, (x, y) in enumerate(zip(ca[k], cb[k])) if x != y), min(len(ca[k]), len(cb[k])))
                diffs.append(f"{run}: {k} differs first at row {i}")
        for m in MAPS:
            pa, pb = a / run / f"{m}.npy", b / run / f"{m}.npy"
            if pa.exists() != pb.exists() or (pa.exists() and not _same(np.load(pa), np.load(pb))):
                diffs.append(f"{run}: {m}.npy differs")
    za, zb = np.load(a / "perception.npz"), np.load(b / "perception.npz")
    if set(za.files) != set(zb.files):
        diffs.append(f"perception: keys differ: {sorted(set(za.files) ^ set(zb.files))}")
    for k in sorted(set(za.files) & set(zb.files)):
        if k.endswith(WALL_SUFFIX):
            continue
        if not _same(za[k], zb[k]):
            diffs.append(f"perception: {k} differs")
    checked += len(za.files)
    print(f"compared {checked} columns and arrays over {len(GT_DIRS) + 1} runs; {len(diffs)} differ")
    return diffs


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="verb", required=True)
    r = sub.add_parser("record")
    r.add_argument("out", type=Path)
    r.add_argument("--src", type=Path, default=Path(__file__).resolve().parents[1])
    r.add_argument("--renderer", default="gl", choices=("gl", "mock"))
    r.add_argument("--duration", type=float, default=None)
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = p.parse_args(argv)
    if args.verb == "record":
        args.out.mkdir(parents=True, exist_ok=True)
        tree = args.src.resolve()
        _record_gt(tree, args.out)
        _record_perception(tree, args.out, args.renderer, args.duration)
        return 0
    diffs = compare(args.a, args.b)
    for d in diffs[:40]:
        print(d)
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main())
