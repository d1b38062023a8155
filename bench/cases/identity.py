"""Bit-identity of a source tree's results (for changes that must not change them): every arm records its runs, and
the digests are compared across arms (``same`` / ``differs`` in the A/B table) or, with ``ref``, every column and
map against a recorded directory, listing the first differences.

An arm records into ``bench/out/identity/<arm>/`` (kept for a later ``ref``):

* ``gt/``: the run directory of ``python launch.py run default --feedback ground_truth --renderer none`` (the launched
  process ring); ``gt-<scenario>/``: the same for the other packaged scenarios and for the default scenario with the
  RK4 integrator, without figures;
* ``perception.npz``: an in-process run (``cosim.runtime.inprocess.simulate``) of the default scenario with
  perception feedback (``renderer``): every timeseries column and the final array blocks;
* ``perc-<scenario>/``: a launched run of a camera or field-conditions scenario as packaged (perception feedback,
  its own renderer) for ``perception_duration`` s simulated, without figures: what the renderer's camera passes,
  the depth camera's noise, the stereo matcher and the atmosphere give the loop.

Compared bit for bit (NaN equal to NaN): every timeseries column except the wall-clock ``*_ms`` ones, and the final
height maps.

    python bench/run.py identity --tree base=/path/to/base --tree new=.
    python bench/run.py identity --opt ref=bench/out/identity/base         # this tree against a recorded base
"""
from __future__ import annotations

import csv
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

from harness import Context, case
from harness.arms import shown_path

__all__ = ["GT_RUNS", "PERC_RUNS", "differences", "digest", "identity", "record"]

#: final array blocks compared bit for bit
MAPS = ("heightmap_truth", "heightmap_perceived")
#: columns whose values are wall-clock times (never reproducible)
WALL_SUFFIX = "_ms"
#: the ground-truth runs: directory name -> launch.py arguments after ``run``
GT_RUNS = {"gt": ["default"],
           **{f"gt-{n}": [n, "--set", "outputs.figures=false"] for n in (
               "back_to_front", "curved_pass", "fast_harvest", "grazing_sensor", "heavy_noise", "high_flow",
               "lowest_first", "misaligned_start", "near_alpha", "soybeans", "stiff_drivetrain")},
           "gt-default-rk4": ["default", "--set", "integrator.method=rk4", "--set", "outputs.figures=false"]}
#: the perception-feedback runs of the camera and field-conditions scenarios: directory name -> scenario
PERC_RUNS = {f"perc-{n}": n for n in ("tof_mast", "stereo_spout", "lidar_and_stereo", "dusty", "dense_dust",
                                      "rough_terrain")}
OUT = Path(__file__).resolve().parents[1] / "out" / "identity"
#: what the perception run saves (run in the arm's tree)
_PERCEPTION = (
    "import sys, numpy as np\n"
    "from cosim.scenario.loader import load_scenario, resolve_scenario_arg\n"
    "from cosim.runtime.inprocess import simulate\n"
    "extra = {'renderer': sys.argv[2]}\n"
    "if sys.argv[3] != 'None': extra['duration_s'] = float(sys.argv[3])\n"
    "r = simulate(load_scenario(resolve_scenario_arg('default'), extra=extra))\n"
    "d = {'series.' + k: v for k, v in r.recorder.series().items()}\n"
    "d.update({'array.' + k: v for k, v in r.recorder.arrays.items()})\n"
    "np.savez(sys.argv[1], **d)\n")


def record(tree: Path, out: Path, runs: list[str], renderer: str, duration: float | None,
           perception_duration: float = 3.0) -> None:
    """Record ``runs`` (names of :data:`GT_RUNS`, :data:`PERC_RUNS` and ``perception``) from ``tree`` into
    ``out``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    dur = ["--duration", f"{duration:g}"] if duration else []
    for name in runs:
        if name in PERC_RUNS:
            subprocess.run([sys.executable, "launch.py", "run", PERC_RUNS[name], "--duration",
                            f"{duration or perception_duration:g}", "--set", "outputs.figures=false", "--quiet",
                            "--out", str(out / name)], cwd=tree, env=env, check=True, stdout=subprocess.DEVNULL)
            continue
        if name == "perception":
            subprocess.run([sys.executable, "-c", _PERCEPTION, str(out / "perception.npz"), renderer, str(duration)],
                           cwd=tree, env=env, check=True)
            continue
        scenario, *rest = GT_RUNS[name]
        subprocess.run([sys.executable, "launch.py", "run", scenario, *rest, *dur, "--feedback", "ground_truth",
                        "--renderer", "none", "--quiet", "--out", str(out / name)], cwd=tree, env=env, check=True,
                       stdout=subprocess.DEVNULL)


def _csv_columns(path: Path) -> dict[str, list[str]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return {h: [r[i] for r in rows[1:]] for i, h in enumerate(rows[0])}


def _same(a, b) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def digest(out: Path, name: str) -> dict:
    """Columns compared and a digest of everything compared in one recorded run."""
    import numpy as np

    h = hashlib.sha256()
    if name == "perception":
        z = np.load(out / "perception.npz")
        keys = sorted(k for k in z.files if not k.endswith(WALL_SUFFIX))
        for k in keys:
            h.update(k.encode() + z[k].tobytes())
        return {"columns and arrays": len(keys), "digest": h.hexdigest()[:16]}
    cols = _csv_columns(out / name / "timeseries.csv")
    keys = [k for k in cols if not k.endswith(WALL_SUFFIX)]
    for k in keys:
        h.update(k.encode() + "\n".join(cols[k]).encode())
    for m in MAPS:
        if (out / name / f"{m}.npy").exists():
            h.update(m.encode() + np.load(out / name / f"{m}.npy").tobytes())
    return {"columns and arrays": len(keys), "digest": h.hexdigest()[:16]}


def differences(a: Path, b: Path, name: str) -> list[str]:
    """The first differences between run ``name`` recorded in ``a`` and in ``b`` (empty when bit-identical)."""
    import numpy as np

    if name == "perception":
        za, zb = np.load(a / "perception.npz"), np.load(b / "perception.npz")
        diffs = [f"keys differ: {sorted(set(za.files) ^ set(zb.files))}"] if set(za.files) != set(zb.files) else []
        return diffs + [f"{k} differs" for k in sorted(set(za.files) & set(zb.files))
                        if not k.endswith(WALL_SUFFIX) and not _same(za[k], zb[k])]
    if not (a / name).exists() or not (b / name).exists():
        return [f"missing in {a if not (a / name).exists() else b}"]
    ca, cb = _csv_columns(a / name / "timeseries.csv"), _csv_columns(b / name / "timeseries.csv")
    diffs = [f"columns differ: {sorted(set(ca) ^ set(cb))}"] if list(ca) != list(cb) else []
    for k in ca:
        if not k.endswith(WALL_SUFFIX) and k in cb and ca[k] != cb[k]:
            i = next((i for i, (x, y) in enumerate(zip(ca[k], cb[k])) if x != y), min(len(ca[k]), len(cb[k])))
            diffs.append(f"{k} differs first at row {i}")
    for m in MAPS:
        pa, pb = a / name / f"{m}.npy", b / name / f"{m}.npy"
        if pa.exists() != pb.exists() or (pa.exists() and not _same(np.load(pa), np.load(pb))):
            diffs.append(f"{m}.npy differs")
    return diffs


@case("identity", "bit-identity of each tree's results (every packaged scenario's ground-truth run, a perception "
      "run) across the arms or against a recorded reference",
      options={"runs": ",".join([*GT_RUNS, "perception", *PERC_RUNS]), "renderer": "gl", "duration": None,
               "perception_duration": 3.0, "ref": ""},
      quick={"runs": "gt,perception,perc-tof_mast", "renderer": "mock", "duration": 2.0},
      compare=("columns and arrays", "digest", "differences"))
def identity(ctx: Context) -> dict:
    """Record ``runs`` (module docstring); ``duration``: cut every run short (a check); ``perception_duration``:
    simulated s of each ``perc-*`` run; ``ref``: a directory recorded by an earlier sample to compare with in
    detail."""
    runs = ctx["runs"].split(",")
    known = [*GT_RUNS, "perception", *PERC_RUNS]
    unknown = set(runs) - set(known)
    if unknown:
        raise ValueError(f"unknown runs {sorted(unknown)}; choose from {', '.join(known)}")
    out = OUT / ctx.arm
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    record(ctx.tree, out, runs, ctx["renderer"], ctx["duration"], float(ctx["perception_duration"]))
    res = {"recorded runs": {name: {**digest(out, name), "recorded in": shown_path(out)} for name in runs}}
    if ctx["ref"]:
        ref = ctx.path(ctx["ref"])
        res["against the reference"] = {name: {"reference": shown_path(ref), "differences": len(d := differences(ref, out, name)),
                                        "first": "; ".join(d[:5]) or "bit-identical"} for name in runs}
    return res
