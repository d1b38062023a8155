"""Table and figure of the camera placement study (docs/placement.md) from a finished sweep directory:

    python docs/examples/placement/table.py runs/sweep-placement

Per placement (one row of OUT/results.csv and its run's summary.json): the profile (the sweep's base), the mount,
the outcome, the camera's fill-height error (mean |h - h_true| / h_true over the cells its own map gives, on the
evaluated frames), the share of the cart it sees (the median share of the controller's cells its own map gives),
its expected 1-sigma of a cell's height at the cart (perception.fitness) and its cost per frame (the sensor
model's median time per image, and the run's median frame). Writes OUT/placement.md and OUT/placement.png.
"""
from __future__ import annotations

import csv
import json
import math
import sys
from pathlib import Path

import numpy as np

__all__ = ["rows", "markdown", "figure", "main"]

MOUNT_XYZ, MOUNT_RPY = "sensors.cam.mount.xyz_m", "sensors.cam.mount.rpy_deg"


def _num(x) -> float:
    return float(x) if isinstance(x, (int, float)) and x is not None else math.nan


def rows(out: Path) -> list[dict]:
    """One dict per placement of the sweep in ``out``."""
    table = []
    for r in csv.DictReader((out / "results.csv").open()):
        run = out / r["run_dir"]
        s = json.loads((run / "summary.json").read_text()) if (run / "summary.json").exists() else {}
        p = s.get("perception") or {}
        cam = (p.get("sensors") or {}).get("cam") or {}
        cells = np.load(run / "heightmap_perceived.npy").size if (run / "heightmap_perceived.npy").exists() else 0
        fill = cam.get("fill_height") or {}
        table.append({
            "profile": r.get("base", "").removeprefix("base_").removesuffix(".yaml"),
            "mount xyz m": r.get(MOUNT_XYZ, ""), "mount rpy deg": r.get(MOUNT_RPY, ""),
            "outcome": r.get("outcome") or ("failed" if r.get("completed") != "True" else ""),
            "fill-height error %": 100 * _num(fill.get("mean_rel_error")),
            "cart seen %": 100 * _num(fill.get("cells")) / cells if cells else math.nan,
            "expected sigma cm": 100 * _num((p.get("fitness") or {}).get("height_sigma_m")),
            "model ms per image": _num(cam.get("measure_ms")),
            "frame ms": _num((s.get("timing_ms") or {}).get("frame")),
            "reason": r.get("outcome_reason", "")})
    return table


def markdown(table: list[dict]) -> str:
    """The table in Markdown."""
    keys = [k for k in table[0] if k != "reason"] if table else []
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in table:
        lines.append("| " + " | ".join(f"{v:.1f}" if isinstance(v, float) else str(v) for k, v in row.items()
                                       if k != "reason") + " |")
    return "\n".join(lines) + "\n"


def figure(table: list[dict], path: Path) -> None:
    """Fill-height error against cost per frame, one marker per placement (colour: profile; filled: the run
    filled the cart)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, prof in enumerate(sorted({r["profile"] for r in table})):
        sel = [r for r in table if r["profile"] == prof]
        x = [r["frame ms"] for r in sel]
        y = [r["fill-height error %"] for r in sel]
        face = [f"C{k}" if r["outcome"] == "filled" else "none" for r in sel]
        ax.scatter(x, y, facecolors=face, edgecolors=f"C{k}", label=prof, s=40)
    ax.set_xlabel("frame, ms (median)")
    ax.set_ylabel("fill-height mean relative error, %")
    ax.set_title("camera placements (filled marker: the run filled the cart)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: table.py SWEEP_DIR", file=sys.stderr)
        return 2
    out = Path(args[0])
    table = rows(out)
    (out / "placement.md").write_text(markdown(table))
    figure(table, out / "placement.png")
    print(markdown(table), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
