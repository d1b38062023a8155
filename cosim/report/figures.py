"""The paper's figures from run data (matplotlib, Agg): Fig 7 fullness, Fig 8 height maps, Fig 9 auger, Fig 10
profile. Each function takes one or more :class:`RunData` and returns a Figure; nothing is shown on screen.

Figures are plain :class:`matplotlib.figure.Figure` objects (no pyplot state; ``savefig`` renders with Agg). The
stacked figures have fixed margins in inches (:data:`MARGINS_IN`) rather than ``tight_layout``, which measured
every tick label in an extra layout pass: 470 M of the 2.1 G instructions of a run's four figures.
"""
from __future__ import annotations

import io
from pathlib import Path
from typing import Sequence

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch, Rectangle
from matplotlib.ticker import NullFormatter

from cosim.runtime.files import atomic_write

from .rundata import RunData

__all__ = ["fig_auger", "fig_profile", "fig_heightmaps", "fig_fullness", "fig_study", "run_figures",
           "write_run_figures", "section_profile", "renderer_label", "DPI", "MARGINS_IN", "NO_VALUE", "RUN_FIGURES"]

#: the file stems of one run's figures (``<stem>.png`` in the run directory), in the order they are drawn
RUN_FIGURES = ("fig7_fullness", "fig8_heightmaps", "fig9_auger", "fig10_profile")

DPI = 110
#: space around the axes of the stacked figures, inches: left (tick labels and y label), right, bottom (tick
#: labels and x label), top (title), and between rows (the next row's title)
MARGINS_IN = {"left": 0.8, "right": 0.2, "bottom": 0.55, "top": 0.35, "between": 0.4}
#: right margin of the stacked figures that carry a colour bar, inches
BAR_MARGIN_IN = 1.3
#: how cells without a value (no LiDAR return, no estimate) are drawn: light grey, hatched; never a colour of
#: the scale (Fig 8 drew them black, the colour of 0 m, so a 53 % coverage map looked like an empty floor)
NO_VALUE = {"facecolor": "0.85", "edgecolor": "0.55", "hatch": "///", "linewidth": 0.0}
#: where a study plot's point label may go, offset points from its point, tried in order
#: (negative x: the label ends there, right-aligned)
LABEL_OFFSETS_PT = ((5, 5), (5, -12), (-5, 5), (-5, -12), (5, 16), (5, -24), (-5, 16), (-5, -24), (5, 28),
                    (5, -36))
#: renderer setting -> what the figures call it
RENDERERS = {"gl": "GL renderer (moderngl, EGL)", "mock": "mock renderer (numpy ray cast)", "none": "no renderer"}


def _stacked(rows: int, row_height_in: float, width_in: float = 9.0,
             right_in: float | None = None) -> tuple[Figure, np.ndarray]:
    """A figure of ``rows`` axes stacked with a shared x axis, (rows, 1) array of axes, margins MARGINS_IN
    (``right_in``: a wider right margin, for a colour bar)."""
    m = dict(MARGINS_IN, **({} if right_in is None else {"right": right_in}))
    height = row_height_in * rows
    fig = Figure(figsize=(width_in, height))
    axes = fig.subplots(rows, 1, squeeze=False, sharex=True)
    axes_h = (height - m["bottom"] - m["top"] - m["between"] * (rows - 1)) / rows
    fig.subplots_adjust(left=m["left"] / width_in, right=1.0 - m["right"] / width_in, bottom=m["bottom"] / height,
                        top=1.0 - m["top"] / height, hspace=m["between"] / axes_h)
    return fig, axes


def renderer_label(run: RunData) -> str:
    """The renderer the run actually used (its resolved scenario), as the figures and the report name it."""
    return RENDERERS.get(run.scenario.renderer, f"{run.scenario.renderer} renderer")


def _label(run: RunData) -> str:
    """Title of a run's axes: feedback (estimator), and the renderer where perception saw its images."""
    est = run.scenario.controller.estimator
    if run.scenario.feedback != "perception":
        return run.scenario.feedback.replace("_", " ")
    return f"perception ({est} estimator), {renderer_label(run)}"


def _hatch_missing(ax, extent) -> None:
    """Draw the no-value background (NO_VALUE) under an image with ``extent`` (left, right, bottom, top): masked
    cells of the image above it show it."""
    x0, x1, y0, y1 = extent
    ax.add_patch(Rectangle((min(x0, x1), min(y0, y1)), abs(x1 - x0), abs(y1 - y0), zorder=0, **NO_VALUE))


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
    """Fig 8: ground-truth height map beside the perceived one, seen from above (x from the front wall to the
    right, y from the left wall up, as the dashboard draws them), one colour scale (viridis, 0 .. cart depth)
    with its bar; cells without a value hatched grey and counted in the legend."""
    maps = [("ground truth", run.heightmap_truth, run.scenario.grain.cell_m),
            ("perceived", run.heightmap_perceived, run.scenario.controller.grid_cell_m)]
    maps = [m for m in maps if m[1] is not None]
    fig = Figure(figsize=(5.2 * max(len(maps), 1) + 1.2, 3.4))
    axes = fig.subplots(1, max(len(maps), 1), squeeze=False)
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad=(0, 0, 0, 0))  # masked: the hatch below shows
    depth = run.scenario.cart.interior_depth_m
    im = None
    for ax, (title, hm, cell) in zip(axes[0], maps):
        ext = (0, hm.shape[0] * cell, 0, hm.shape[1] * cell)   # seen from above: front wall left, left wall down
        _hatch_missing(ax, ext)
        im = ax.imshow(np.ma.masked_invalid(hm.T), cmap=cmap, vmin=0, vmax=depth, extent=ext, interpolation="nearest",
                       origin="lower", zorder=1)
        missing = float(np.mean(~np.isfinite(hm)))
        ax.set_title(f"{title} ({renderer_label(run)})" if title == "perceived" else title, fontsize=10)
        ax.set_xlabel("x from the front wall (m)")
        ax.set_ylabel("y from the left wall (m)")
        ax.legend(handles=[Patch(label=f"no return / no value ({100 * missing:.0f} % of cells)", **NO_VALUE)],
                  loc="upper center", bbox_to_anchor=(0.5, -0.22), fontsize=8, frameon=False)
    fig.subplots_adjust(bottom=0.3, top=0.88, left=0.07, right=0.86, wspace=0.25)
    if im is not None:
        cax = fig.add_axes((0.89, 0.3, 0.018, 0.58))
        fig.colorbar(im, cax=cax, label="grain height above the floor (m)")
    return fig


def fig_fullness(runs: Sequence[RunData]):
    """Fig 7: fullness status per section over time (0 empty .. 1 at target, colour bar), sections without an
    estimate hatched grey (legend)."""
    fig, axes = _stacked(len(runs), 2.8, width_in=10.0, right_in=BAR_MARGIN_IN)
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad=(0, 0, 0, 0))
    im, missing = None, False
    for ax, run in zip(axes[:, 0], runs):
        n = run.scenario.controller.sections
        cols = [run.col(f"section{k}_fullness") for k in range(1, n + 1)]
        if all(c is None for c in cols):
            cols = [run.col(f"section{k}_fullness") for k in range(n)]
        data = np.array([c if c is not None else np.full(len(run.t), np.nan) for c in cols])
        t = run.t
        if len(t):
            ext = (t[0], t[-1], 0.5, n + 0.5)
            _hatch_missing(ax, ext)
            im = ax.imshow(np.ma.masked_invalid(data), aspect="auto", origin="lower", cmap=cmap, vmin=0, vmax=1,
                           extent=ext, interpolation="nearest", zorder=1)
            missing |= not np.isfinite(data).all()
        ax.set_yticks(range(1, n + 1))
        ax.set_ylabel("section (front = 1)")
        ax.set_title(_label(run), fontsize=10)
    axes[-1, 0].set_xlabel("time (s)")
    if im is not None:
        m = MARGINS_IN
        w, h = fig.get_size_inches()
        cax = fig.add_axes((1 - (BAR_MARGIN_IN - 0.25) / w, m["bottom"] / h, 0.15 / w, 1 - (m["bottom"] + m["top"]) / h))
        fig.colorbar(im, cax=cax, label="fullness (1 = at the target level)", extend="max")
    if missing:  # in the bottom left corner, off the data
        fig.legend(handles=[Patch(label="no estimate", **NO_VALUE)], loc="lower left", fontsize=8, frameon=False)
    return fig


def fig_study(panels: Sequence[tuple[str, str, Sequence[tuple[str, float, float]], str]]):
    """Study plot: per knob, error against wall time per simulated second, log-log, the default starred.

    ``panels``: (knob name, error label, [(setting label, wall s per sim s, error)], default label). An error of
    exactly 0 (the reference setting against itself, or an exact match) is drawn as an open marker on the
    axis's floor labelled "0 (exact)", not clamped to a made-up tiny number. Labels alternate above and below
    their points (sorted by x), so neighbours do not overlap."""
    fig = Figure(figsize=(5.2 * max(len(panels), 1), 4.2))
    axes = fig.subplots(1, max(len(panels), 1), squeeze=False)
    for ax, (name, error_label, pts, default) in zip(axes[0], panels):
        pts = sorted(pts, key=lambda p: p[1])
        nonzero = [p[2] for p in pts if p[2] > 0 and np.isfinite(p[2])]
        floor = min(nonzero) / 10 if nonzero else 1e-3
        ax.set_xscale("log")
        ax.set_yscale("log")
        zero_drawn = False
        for label, x, y in pts:
            zero = not y > 0
            yy = floor if zero else y
            ax.plot([x], [yy], "v" if zero else "o", color="tab:blue", mfc="none" if zero else "tab:blue",
                    label="error 0 (exact)" if zero and not zero_drawn else None)
            zero_drawn |= zero
            if label == default:
                ax.plot([x], [yy], "*", ms=16, color="tab:red", label="default", zorder=0)
            ax.annotate(label + (" (0)" if zero else ""), (x, yy), fontsize=7, textcoords="offset points",
                        xytext=LABEL_OFFSETS_PT[0])
        ax.set_ylim(floor / 2, (max(nonzero) if nonzero else 1.0) * 3)
        _decade_at_least(ax, [p[1] for p in pts])
        ax.set_xlabel("wall time per simulated second (s)")
        ax.set_ylabel(error_label)
        ax.set_title(name)
        ax.legend(fontsize=8, loc="best")
        ax.grid(alpha=0.3, which="both")
    fig.subplots_adjust(left=0.12 / max(len(panels), 1) + 0.05, right=0.98, bottom=0.14, top=0.92, wspace=0.35)
    _place_labels(fig)
    return fig


def _decade_at_least(ax, xs: Sequence[float]) -> None:
    """A log x axis over at least one decade around ``xs`` (so that a power of ten is on it), labelled at its
    powers of ten only: the minor ticks' labels (2 x 10^-2, 3 x 10^-2, ...) crowd into one another on a narrow
    range."""
    xs = [x for x in xs if x > 0 and np.isfinite(x)]
    if xs:
        lo, hi = min(xs) / 1.5, max(xs) * 1.5
        if hi / lo < 10.0:
            mid = np.sqrt(lo * hi)
            lo, hi = mid / np.sqrt(10.0), mid * np.sqrt(10.0)
        ax.set_xlim(lo, hi)
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())


def _place_labels(fig: Figure) -> None:
    """Move each point label to the first of LABEL_OFFSETS_PT where it overlaps no label placed before it and no
    marker and stays inside its axes (greedy, in drawing order; measured with the Agg renderer that saves the
    figure)."""
    renderer = FigureCanvasAgg(fig).get_renderer()
    for ax in fig.axes:
        taken = [ln.get_window_extent(renderer) for ln in ax.lines]
        taken = [b.expanded(1.0, 1.0) for b in taken if b.width < 40 and b.height < 40]  # markers, not lines
        frame = ax.get_window_extent(renderer)
        for ann in ax.texts:
            fits = []
            for off in LABEL_OFFSETS_PT:
                ann.set_position(off)
                ann.set_horizontalalignment("right" if off[0] < 0 else "left")
                box = ann.get_window_extent(renderer)
                free = not any(box.overlaps(b) for b in taken)
                inside = frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
                if free and inside:
                    break
                fits.append((not free, not inside, off))
            else:  # nowhere free inside the axes: the least bad place (free first, then inside)
                off = min(fits)[2]
                ann.set_position(off)
                ann.set_horizontalalignment("right" if off[0] < 0 else "left")
            taken.append(ann.get_window_extent(renderer))


def run_figures(run: RunData) -> list[tuple[str, Figure]]:
    """(file stem, Figure) of one run's figures: Figs 7, 8, 9 and 10 (the stems of :data:`RUN_FIGURES`)."""
    makers = {"fig7_fullness": lambda: fig_fullness([run]), "fig8_heightmaps": lambda: fig_heightmaps(run),
              "fig9_auger": lambda: fig_auger([run]), "fig10_profile": lambda: fig_profile([run])}
    return [(stem, makers[stem]()) for stem in RUN_FIGURES]


def write_run_figures(run: RunData, out: Path | None = None) -> list[Path]:
    """Write fig7_fullness.png, fig8_heightmaps.png, fig9_auger.png and fig10_profile.png for one run, each whole
    or not at all (rendered in memory, then written atomically). Raises :class:`cosim.errors.OutputError` naming
    the file on a write error (a full disk); the figures written before it stay."""
    out = Path(out) if out is not None else run.path
    made = []
    for name, fig in run_figures(run):
        p = out / f"{name}.png"
        buf = io.BytesIO()
        fig.savefig(buf, dpi=DPI, format="png")
        atomic_write(p, buf.getvalue())
        made.append(p)
    return made
