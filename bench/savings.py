"""What each leave-out saves: the default scenario run with and without it, wall time and per-stage medians.

Leave-outs:

* a ground-truth run without a viewer starts no renderer and no perception process (against the same run with
  ``viewer: true`` set and no viewer attached: renderer, perception and the RGB image all run for nobody);
* no RGB image is rendered without a consumer (``render.rgb: auto`` against ``on``);
* only the pixels the LiDAR pattern needs are rendered (the planned rig, 2 x 336 x 958 at the 0.1 deg bound,
  against the same two cameras at twice the resolution each way, 2 x 672 x 1916: a rig sized like a
  1080p-class render, not by the pattern);
* perception's accuracy evaluation against the exact ray cast, which the controller does not need
  (``perception.accuracy_every_frames`` 10 against 0);
* not a leave-out but the same kind of saving: perception off the critical path, overlapping the next frame
  (``timing.overlap_perception`` true against false; same numbers, cosim.runtime.participant).

Each pair runs interleaved ``--reps`` times through the real launcher (OS processes, GL renderer) for
``--duration`` simulated seconds; prints a Markdown table of medians. Usage:
``python bench/savings.py --duration 20 --reps 2``.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.runtime.launcher import launch  # noqa: E402
from cosim.scenario.loader import load_scenario, packaged_scenarios  # noqa: E402

#: saving -> (config with the leave-out, config without it), each a scenario overlay on the default
PAIRS = {
    "renderer + perception left out of a ground-truth run": (
        {"feedback": "ground_truth", "renderer": "none"},
        {"feedback": "ground_truth", "renderer": "gl", "viewer": True}),
    "RGB image left out (no consumer)": (
        {"render": {"rgb": "auto"}},
        {"render": {"rgb": "on"}}),
    "only the pixels the pattern needs": (
        {},
        {"render": {"rig": "fixed", "cameras": 2, "width_px": 672, "height_px": 1916, "hfov_deg": 45.0}}),
    "accuracy evaluation left out": (
        {"perception": {"accuracy_every_frames": 0}},
        {"perception": {"accuracy_every_frames": 10}}),
    "perception overlapping the next frame": (
        {"timing": {"overlap_perception": True}},
        {"timing": {"overlap_perception": False}}),
}


def run_once(overlay: dict, duration: float, out: Path) -> dict:
    sc = load_scenario(packaged_scenarios()["default"], extra={**overlay, "duration_s": duration})
    res = launch(sc, out, console_log=False)
    if not res.completed:
        raise RuntimeError(f"run failed: {res.error}")
    s = res.summary
    return {"wall": s["wall_time_s"], "rtf": s["real_time_factor"], **{k: v for k, v in s["timing_ms"].items()}}


def median_of(rows: list[dict], key: str) -> float:
    """Median of ``key`` over the runs that have it (a stage absent from the ring: NaN)."""
    values = [r[key] for r in rows if r.get(key) is not None]
    return statistics.median(values) if values else float("nan")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0, help="simulated seconds per run")
    ap.add_argument("--reps", type=int, default=2, help="interleaved repetitions of each pair")
    ap.add_argument("--only", default="", help="substring of the savings to run (default all)")
    args = ap.parse_args(argv)
    print("| saving | config | wall s (median) | real-time factor | render ms | perception ms | frame ms | wall saved |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, (on, off) in PAIRS.items():
            if args.only not in name:
                continue
            got: dict[str, list[dict]] = {"with": [], "without": []}
            for rep in range(args.reps):
                for label, overlay in (("with", on), ("without", off)):
                    got[label].append(run_once(overlay, args.duration, Path(tmp) / f"{label}{rep}"))
            med = {label: {k: median_of(rows, k) for k in ("wall", "rtf", "render", "perception", "frame")}
                   for label, rows in got.items()}
            saved = 1.0 - med["with"]["wall"] / med["without"]["wall"]
            for label in ("with", "without"):
                m = med[label]
                print(f"| {name if label == 'with' else ''} | {label} the leave-out | {m['wall']:.1f} | "
                      f"{m['rtf']:.2f} | {m['render']:.1f} | {m['perception']:.1f} | {m['frame']:.1f} | "
                      f"{f'{saved * 100:.0f} %' if label == 'with' else ''} |", flush=True)


if __name__ == "__main__":
    main()
