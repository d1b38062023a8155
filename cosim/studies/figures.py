"""Sweep figures: each metric against each varied parameter, seeds (and the other parameters) as spread.

One PNG per metric, ``OUT/sweep_<metric>.png``, one panel per varied parameter (the seed when nothing else
varies): every completed run as a small point, and per parameter value the mean with a min-max bar. Numeric
parameters are placed at their values, others in file order. Metrics no run has (e.g. perception metrics of
ground-truth runs) get no figure.
"""
from __future__ import annotations

import math
from pathlib import Path

from .results import METRICS

__all__ = ["write_sweep_figures", "spread"]

PANEL_IN = 3.6  # width of one panel, inches


def _num(v) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def spread(rows: list[dict], param: str, metric: str) -> list[tuple[object, float, float, float, list[float]]]:
    """Per value of ``param`` (first-seen order): (value, mean, min, max, values) of ``metric`` over the
    completed runs that have it. The mean is kept inside [min, max]: a float sum can round it just outside (three
    runs of 0.1 have the mean 0.10000000000000002), which made its error bar negative."""
    groups: dict = {}
    for r in rows:
        y = _num(r.get(metric))
        if r.get("completed") and y is not None:
            groups.setdefault(_key(r.get(param)), (r.get(param), []))[1].append(y)
    return [(v, min(max(math.fsum(ys) / len(ys), min(ys)), max(ys)), min(ys), max(ys), ys) for v, ys in groups.values()]


def _key(v):
    return repr(v)


def write_sweep_figures(out: Path, rows: list[dict], parameters: tuple[str, ...]) -> list[Path]:
    """Write the figures into ``out``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = list(parameters) or ["seed"]
    written = []
    for metric in METRICS:
        if metric in ("sim_time_s",) or not any(r.get("completed") and _num(r.get(metric)) is not None
                                                for r in rows):
            continue
        fig, axes = plt.subplots(1, len(params), figsize=(PANEL_IN * len(params), 3.2), squeeze=False)
        for ax, param in zip(axes[0], params):
            groups = spread(rows, param, metric)
            numeric = all(_num(g[0]) is not None for g in groups)
            xs = [float(g[0]) if numeric else i for i, g in enumerate(groups)]
            for x, (_, mean, lo, hi, ys) in zip(xs, groups):
                ax.plot([x] * len(ys), ys, ".", color="0.6", ms=4)
                ax.errorbar([x], [mean], yerr=[[mean - lo], [hi - mean]], fmt="o", color="tab:blue", capsize=3)
            if not numeric:
                ax.set_xticks(xs, [str(g[0]) for g in groups], rotation=20, fontsize=7)
            ax.set_xlabel(param, fontsize=8)
            ax.set_ylabel(metric, fontsize=8)
            ax.grid(alpha=0.3)
        fig.suptitle(f"{metric}: runs (points), mean and min-max per value", fontsize=9)
        fig.tight_layout()
        path = Path(out) / f"sweep_{metric}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        written.append(path)
    return written
