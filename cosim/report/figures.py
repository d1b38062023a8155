"""The paper's figures from run data (matplotlib, Agg): Fig 7 fullness, Fig 8 height maps, Fig 9 auger, Fig 10
profile. Each function takes one or more :class:`RunData` and returns a Figure; nothing is shown on screen.

Figures are plain :class:`matplotlib.figure.Figure` objects (no pyplot state; ``savefig`` renders with Agg). The
stacked figures have fixed margins in inches (:data:`MARGINS_IN`) rather than ``tight_layout``, which measured
every tick label in an extra layout pass: 470 M of the 2.1 G instructions of a run's four figures.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from .rundata import RunData

__all__ = ["fig_auger", "fig_profile", "fig_heightmaps", "fig_fullness", "write_run_figures", "section_profile",
           "DPI", "MARGINS_IN"]

DPI = 110
#: space around the axes of the stacked figures, inches: left (tick labels and y label), right, bottom (tick
#: labels and x label), top (title), and between rows (the next row's title)
MARGINS_IN = {"left": 0.8, "right": 0.2, "bottom": 0.55, "top": 0.35, "between": 0.4}


def _stacked(rows: int, row_height_in: float, width_in: float = 9.0) -> tuple[Figure, np.ndarray]:
    """A figure of ``rows`` axes stacked with a shared x axis, (rows, 1) array of axes, margins MARGINS_IN."""
    m = MARGINS_IN
    height = row_height_in * rows
    fig = Figure(figsize=(width_in, height))
    axes = fig.subplots(rows, 1, squeeze=False, sharex=True)
    axes_h = (height - m["bottom"] - m["top"] - m["between"] * (rows - 1)) / rows
    fig.subplots_adjust(left=m["left"] / width_in, right=1.0 - m["right"] / width_in, bottom=m["bottom"] / height,
                        top=1.0 - m["top"] / height, hspace=m["between"] / axes_h)
    return fig, axes


def _label(run: RunData) -> str:
    est = run.scenario.controller.estimator
    return f"{run.scenario.feedback.replace('_', ' ')}" + (f" ({est} estimator)" if run.scenario.feedback ==
                                                             "perception" else "")


def fig_auger(runs: Sequence[RunData]):
    """Fig 9: desired auger location (dashed), control effort, nudge signal and actual auger location (cart x)."""
    fig, axes = _stacked(len(runs), 3.2)
    for ax, run in zip(axes[:, 0], runs):
        t = run.t
        for name, style, label in (("desired_auger_x_m", dict(color="k", ls="--"), "desired"),
                                   ("control_effort_m", dict(color="tab:red"), "control effort"),
                                   ("nudge_m", dict(color="k", lw=0.8), "nudge (actuating)"),
                                   ("actual_auger_x_m", dict(color="tab:blue"), "actual")):
            y = run.col(name)
            if y is not None:
                ax.plot(t, y, label=label, **style)
        ax.set_ylabel("auger x in cart (m)")
        ax.set_title(_label(run))
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    return fig


def section_profile(run: RunData) -> tuple[np.ndarray, np.ndarray] | None:
    """Longitudinal profile of the final truth height map: (x (nx,), max over the width (nx,)), m."""
    hm = run.heightmap_truth
    if hm is None:
        return None
    cell = run.scenario.grain.cell_m
    x = (np.arange(hm.shape[0]) + 0.5) * cell
    return x, np.nanmax(hm, axis=1)


def fig_profile(runs: Sequence[RunData]):
    """Fig 10: final longitudinal grain profile against the target level and the cart top."""
    fig, axes = _stacked(len(runs), 2.8)
    for ax, run in zip(axes[:, 0], runs):
        prof = section_profile(run)
        cart = run.scenario.cart
        if prof is not None:
            ax.plot(*prof, color="tab:blue", label="grain profile (max across width)")
        ax.axhline(cart.interior_depth_m, color="k", label="cart top")
        ax.axhline(run.scenario.controller.target_fill_m, color="tab:red", ls="--", label="target")
        n = run.scenario.controller.sections
        for k in range(1, n):
            ax.axvline(k * cart.interior_length_m / n, color="0.85", lw=0.6)
        ax.set_ylim(0, cart.interior_depth_m * 1.15)
        ax.set_ylabel("height (m)")
        ax.set_title(_label(run))
        ax.legend(loc="lower right", fontsize=8)
    axes[-1, 0].set_xlabel("x from the front wall (m)")
    return fig


def fig_heightmaps(run: RunData):
    """Fig 8: ground-truth height map beside the perceived one (NaN cells black)."""
    maps = [("ground truth", run.heightmap_truth, run.scenario.grain.cell_m),
            ("perceived", run.heightmap_perceived, run.scenario.controller.grid_cell_m)]
    maps = [m for m in maps if m[1] is not None]
    fig = Figure(figsize=(5 * max(len(maps), 1), 3.2))
    axes = fig.subplots(1, max(len(maps), 1), squeeze=False)
    cmap = matplotlib.colormaps["gray"].with_extremes(bad="black")
    depth = run.scenario.cart.interior_depth_m
    for ax, (title, hm, cell) in zip(axes[0], maps):
        ext = (0, hm.shape[0] * cell, hm.shape[1] * cell, 0)
        im = ax.imshow(np.ma.masked_invalid(hm.T), cmap=cmap, vmin=0, vmax=depth, extent=ext, interpolation="nearest")
        ax.set_title(title)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    if maps:
        fig.colorbar(im, ax=axes[0].tolist(), label="height above floor (m)", shrink=0.8)
    return fig


def fig_fullness(runs: Sequence[RunData]):
    """Fig 7: fullness status per section over time (0 empty .. 1 at target)."""
    fig, axes = _stacked(len(runs), 2.8)
    for ax, run in zip(axes[:, 0], runs):
        n = run.scenario.controller.sections
        cols = [run.col(f"section{k}_fullness") for k in range(1, n + 1)]
        if all(c is None for c in cols):
            cols = [run.col(f"section{k}_fullness") for k in range(n)]
        data = np.array([c if c is not None else np.full(len(run.t), np.nan) for c in cols])
        t = run.t
        if len(t):
            ax.imshow(data, aspect="auto", origin="lower", cmap="viridis", vmin=0, vmax=1,
                      extent=(t[0], t[-1], 0.5, n + 0.5), interpolation="nearest")
        ax.set_ylabel("section (front = 1)")
        ax.set_title(_label(run))
    axes[-1, 0].set_xlabel("time (s)")
    return fig


def write_run_figures(run: RunData, out: Path | None = None) -> list[Path]:
    """Write fig7_fullness.png, fig8_heightmaps.png, fig9_auger.png and fig10_profile.png for one run."""
    out = Path(out) if out is not None else run.path
    made = []
    for name, fig in (("fig7_fullness", fig_fullness([run])), ("fig8_heightmaps", fig_heightmaps(run)),
                      ("fig9_auger", fig_auger([run])), ("fig10_profile", fig_profile([run]))):
        p = out / f"{name}.png"
        fig.savefig(p, dpi=DPI)
        made.append(p)
    return made
