"""The figures of a run, of compare and of a study, read back as structure (no image goldens): axis labels, a
colour bar with units on every map, cells without a value drawn apart from 0 m and named in the legend, zero
errors shown as zero, labels that do not overlap, and the renderer actually used in the titles."""
from __future__ import annotations

import itertools
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from cosim.report.figures import NO_VALUE, fig_study, run_figures
from cosim.report.html import comparison_figures, write_comparison_report
from cosim.report.rundata import RunData
from cosim.scenario.loader import load_scenario, resolve_scenario_arg

FRAMES = 40


def synthetic_run(tmp: Path, name: str, feedback: str, renderer: str = "mock") -> RunData:
    """A run's data made by hand: fullness ramps, section 3 without estimate for the first half, a perceived map
    with its rear half unseen."""
    sc = load_scenario(resolve_scenario_arg("default"), extra={"renderer": renderer, "feedback": feedback})
    n = sc.controller.sections
    t = np.arange(FRAMES) * sc.timing.sensor_period_s
    series = {"frame": np.arange(FRAMES, dtype=float), "dyn_state.t_s": t,
              "dyn_state.desired_auger_x_m": np.full(FRAMES, 2.0), "dyn_state.actual_auger_x_m": np.linspace(1, 2, FRAMES),
              "dyn_state.control_effort_m": np.zeros(FRAMES), "dyn_state.nudge_m": np.zeros(FRAMES)}
    for k in range(1, n + 1):
        col = np.linspace(0, 1.0 / k, FRAMES)
        if k == 3:
            col[:FRAMES // 2] = np.nan
        series[f"dyn_state.section{k}_fullness"] = col
    nx = round(sc.cart.interior_length_m / sc.grain.cell_m)
    ny = round(sc.cart.interior_width_m / sc.grain.cell_m)
    truth = np.full((nx, ny), 1.0, np.float32)
    truth[: nx // 4] = 0.0  # an empty front quarter: 0 m, which must not look like "no value"
    gx = round(sc.cart.interior_length_m / sc.controller.grid_cell_m)
    gy = round(sc.cart.interior_width_m / sc.controller.grid_cell_m)
    perceived = np.full((gx, gy), 0.9, np.float32)
    perceived[gx // 2:] = np.nan
    path = tmp / name
    path.mkdir()
    return RunData(path, sc, {"completed": True}, series, truth,
                   perceived if feedback == "perception" else None)


def colourbars(fig: Figure) -> list:
    """The colour bar axes of ``fig`` (matplotlib marks them with a ``_colorbar`` attribute)."""
    return [ax for ax in fig.axes if getattr(ax, "_colorbar", None) is not None]


def no_value_patches(ax) -> list:
    return [p for p in ax.patches if p.get_hatch() == NO_VALUE["hatch"]]


def render(fig: Figure):
    canvas = FigureCanvasAgg(fig)  # the text extents below are those of the saved image
    canvas.draw()
    return canvas.get_renderer()


def overlaps(texts, renderer) -> list[tuple[str, str]]:
    boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in texts if t.get_text()]
    return [(a, b) for i, (a, ba) in enumerate(boxes) for b, bb in boxes[i + 1:] if ba.overlaps(bb)]


@pytest.fixture
def run(tmp_path):
    return synthetic_run(tmp_path, "perception_paper", "perception")


def test_a_runs_figures_have_labelled_axes_and_colour_bars_with_units(run):
    figs = dict(run_figures(run))
    assert set(figs) == {"fig7_fullness", "fig8_heightmaps", "fig9_auger", "fig10_profile"}
    for name, fig in figs.items():
        plots = [ax for ax in fig.axes if ax not in colourbars(fig)]
        assert all(ax.get_ylabel() for ax in plots), name
        assert plots[-1].get_xlabel(), name
    for name in ("fig7_fullness", "fig8_heightmaps"):  # the maps
        (bar,) = colourbars(figs[name])
        label = bar.get_ylabel()
        assert label and ("(m)" in label or "fullness" in label), (name, label)
    assert "(m)" in colourbars(figs["fig8_heightmaps"])[0].get_ylabel()


def test_height_maps_are_seen_from_above(run):
    """Fig 8 as the dashboard draws the maps: the front-left cell (grid (0, 0)) at the lower left, y up."""
    fig = dict(run_figures(run))["fig8_heightmaps"]
    for ax in (ax for ax in fig.axes if ax not in colourbars(fig)):
        (im,) = ax.get_images()
        left, right, bottom, top = im.get_extent()
        assert im.origin == "lower" and left < right and bottom < top and ax.get_ylim()[0] < ax.get_ylim()[1]
        assert ax.get_ylabel() == "y from the left wall (m)"


def test_no_value_cells_are_hatched_grey_and_named_not_black(run):
    fig = dict(run_figures(run))["fig8_heightmaps"]
    truth_ax, perc_ax = [ax for ax in fig.axes if ax not in colourbars(fig)]
    (im,) = perc_ax.get_images()
    # masked (NaN) cells are transparent, so the hatched grey patch under them shows; 0 m is a viridis colour
    assert im.cmap.get_bad()[3] == 0.0
    assert no_value_patches(perc_ax) and matplotlib.colors.to_rgb(NO_VALUE["facecolor"]) != (0, 0, 0)
    zero_colour = im.cmap(im.norm(0.0))
    assert zero_colour[:3] != matplotlib.colors.to_rgb(NO_VALUE["facecolor"])
    (legend_text,) = [t.get_text() for t in perc_ax.get_legend().get_texts()]
    assert legend_text == "no return / no value (50 % of cells)"
    assert truth_ax.get_legend().get_texts()[0].get_text().endswith("(0 % of cells)")
    fig7 = dict(run_figures(run))["fig7_fullness"]
    ax7 = [ax for ax in fig7.axes if ax not in colourbars(fig7)][0]
    assert no_value_patches(ax7) and [t.get_text() for t in fig7.legends[0].get_texts()] == ["no estimate"]


def test_titles_name_the_renderer_actually_used(tmp_path):
    runs = [synthetic_run(tmp_path, "ground_truth", "ground_truth"),
            synthetic_run(tmp_path, "perception_paper", "perception", renderer="mock")]
    assert "GL renderer" in runs[1].scenario.description, "the default's description names GL: the trap"
    figs = comparison_figures(runs)
    titles = [ax.get_title() for _, _, f in figs for ax in f.axes]
    assert any("mock renderer" in t for t in titles) and not any("GL" in t for t in titles)
    captions = [c for _, c, _ in figs]
    assert any("Fig 8" in c and "mock renderer" in c for c in captions)
    for _, caption, fig in figs:
        for bar in colourbars(fig):
            assert bar.get_ylabel(), caption
    report = write_comparison_report(runs, tmp_path / "report").read_text()
    h1 = report.split("<h1>")[1].split("</h1>")[0]
    assert "mock renderer" in h1 and "GL" not in h1
    assert '<b id="renderer">mock renderer (numpy ray cast)</b>' in report


def test_study_plot_shows_zero_errors_as_zero_and_labels_do_not_overlap():
    pts = [("rk4 dt=0.01", 0.010, 0.0), ("rk4 dt=0.02", 0.011, 2e-4), ("euler dt=0.01", 0.0105, 3e-3),
           ("euler dt=0.02", 0.0102, 5e-3), ("radau", 0.2, 1e-6)]
    fig = fig_study([("dynamics", "cart track error (m)", pts, "rk4 dt=0.02")])
    (ax,) = fig.axes
    labels = [t for t in ax.texts]
    assert "rk4 dt=0.01 (0)" in [t.get_text() for t in labels]
    assert "error 0 (exact)" in [t.get_text() for t in ax.get_legend().get_texts()]
    lo, _ = ax.get_ylim()
    zero_pt = [ln for ln in ax.lines if ln.get_marker() == "v"][0]
    assert zero_pt.get_ydata()[0] > lo and zero_pt.get_ydata()[0] < 1e-6, "0 drawn on the floor, below every error"
    assert ax.get_xlabel() and ax.get_ylabel() == "cart track error (m)"
    renderer = render(fig)
    assert overlaps(labels, renderer) == []
    frame = ax.get_window_extent(renderer)
    outside = [t.get_text() for t in labels if not frame.contains(*t.get_window_extent(renderer).min)
               or not frame.contains(*t.get_window_extent(renderer).max)]
    assert outside == [], "labels drawn outside their axes"


def _texts(fig) -> list:
    """(axes index, text, window extent) of every visible axis label, title and tick label inside its view."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    out = []
    for i, ax in enumerate(fig.axes):
        found = [ax.xaxis.label, ax.yaxis.label, ax.title]
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            found += [t.label1 for t in axis.get_major_ticks() + axis.get_minor_ticks()
                      if lo <= t.get_loc() <= hi and t.label1.get_visible() and t.label1.get_text()]
        out += [(i, t.get_text(), t.get_window_extent(renderer)) for t in found if t.get_text()]
    return out


def test_study_figure_axis_labels_never_overlap():
    """Narrow and wide cost ranges on log axes, long error labels, three knobs side by side: no two axis labels,
    titles or tick labels overlap, and all lie inside the figure."""
    panels = [
        ("dynamics", "cart track error vs radau dt=0.001 (m)",
         [("exponential dt=0.01", 0.02, 1e-4), ("radau dt=0.01", 0.05, 2e-5), ("radau dt=0.001", 0.4, 0.0)],
         "exponential dt=0.01"),
        ("grain_cell", "section mean height error vs 0.025 m (m)",
         [("0.1", 0.01, 0.02), ("0.05", 0.03, 0.004), ("0.025", 0.2, 0.0)], "0.05"),
        ("resample", "heightmap RMSE vs the exact ray cast (m)", [("nearest", 0.1, 0.003), ("bilinear", 0.12, 0.002)],
         "bilinear"),
    ]
    for n in (1, 3):
        fig = fig_study(panels[:n])
        texts = _texts(fig)
        clash = [(a[:2], b[:2]) for a, b in itertools.combinations(texts, 2) if a[2].overlaps(b[2])]
        assert clash == []
        w, h = fig.bbox.width, fig.bbox.height
        assert [t[:2] for t in texts if t[2].x0 < 0 or t[2].y0 < 0 or t[2].x1 > w or t[2].y1 > h] == []
        assert sum(1 for t in texts if t[0] == n - 1 and "10^" in t[1]) >= 2      # labelled ticks on each axis
