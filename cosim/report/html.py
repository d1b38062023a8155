"""The comparison report: one HTML page with the paper's figures for several runs and a metrics table."""
from __future__ import annotations

import html
from pathlib import Path
from typing import Sequence

from .figures import DPI, fig_auger, fig_fullness, fig_heightmaps, fig_profile, renderer_label
from .rundata import RunData

__all__ = ["METRICS", "metrics_row", "write_comparison_report", "comparison_figures", "renderers_used"]

#: (label, function of a summary dict -> value or None, format)
METRICS = (
    ("completed", lambda s: s.get("completed"), "{}"),
    ("spill (kg)", lambda s: (s.get("spill") or {}).get("mass_kg"), "{:.1f}"),
    ("max overfill above target (cm)", lambda s: _cm((s.get("fill") or {}).get("max_overfill_m")), "{:.1f}"),
    ("profile RMSE to target (cm)", lambda s: _cm((s.get("fill") or {}).get("profile_rmse_m")), "{:.1f}"),
    ("fill fraction (%)", lambda s: _pct((s.get("fill") or {}).get("fill_fraction")), "{:.1f}"),
    ("time to target (s)", lambda s: (s.get("fill") or {}).get("time_to_target_s"), "{:.1f}"),
    ("nudges", lambda s: (s.get("controller") or {}).get("nudges"), "{}"),
    ("mass balance rel. error", lambda s: (s.get("mass_balance") or {}).get("relative_error"), "{:.1e}"),
    ("perception coverage (%)", lambda s: _pct((s.get("perception") or {}).get("coverage")), "{:.1f}"),
    ("perceived height RMSE (cm)", lambda s: _cm((s.get("perception") or {}).get("heightmap_rmse_m")), "{:.1f}"),
    ("real-time factor", lambda s: s.get("real_time_factor"), "{:.1f}"),
)


def _cm(v):
    return None if v is None else 100.0 * v


def _pct(v):
    return None if v is None else 100.0 * v


def metrics_row(summary: dict) -> list[str]:
    out = []
    for _, fn, fmt in METRICS:
        v = fn(summary)
        out.append("n/a" if v is None else fmt.format(v))
    return out


def _section_table(runs: Sequence[RunData]) -> str:
    n = max(r.scenario.controller.sections for r in runs)
    head = "".join(f"<th>{k}</th>" for k in range(1, n + 1))
    rows = []
    for r in runs:
        peaks = (r.summary.get("fill") or {}).get("section_peak_height_m") or []
        cells = "".join(f"<td>{p:.2f}</td>" if p is not None else "<td>n/a</td>" for p in peaks)
        rows.append(f"<tr><th>{html.escape(r.path.name)}</th>{cells}</tr>")
    return f"<table><tr><th>section peak (m)</th>{head}</tr>{''.join(rows)}</table>"


def renderers_used(runs: Sequence[RunData]) -> str:
    """The renderers the perception runs actually used (from their resolved scenarios), e.g. "mock renderer
    (numpy ray cast)"; "no renderer" when no run perceived."""
    used = sorted({renderer_label(r) for r in runs if r.scenario.feedback == "perception"})
    return ", ".join(used) or "no renderer"


def comparison_figures(runs: Sequence[RunData]) -> list[tuple[str, str, object]]:
    """(file name, caption, Figure) of the comparison report."""
    figs = [("fig9_auger.png", "Fig 9: auger location against the desired location, control effort and nudges",
             fig_auger(runs)),
            ("fig10_profile.png", "Fig 10: final longitudinal fill profile against the target and the cart top",
             fig_profile(runs)),
            ("fig7_fullness.png", "Fig 7: fullness per section over time", fig_fullness(runs))]
    for r in runs:
        if r.heightmap_perceived is not None:
            figs.append((f"fig8_heightmaps_{r.path.name}.png",
                         f"Fig 8: ground-truth against perceived height map ({r.path.name}, "
                         f"{renderer_label(r)})", fig_heightmaps(r)))
    return figs


def write_comparison_report(runs: Sequence[RunData], out: Path, notes: str = "") -> Path:
    """Write figures and report.html for ``runs`` into ``out``; returns the report path. The title names the
    renderer the perception runs used (not the scenario's description, which may name another)."""
    out.mkdir(parents=True, exist_ok=True)
    figs = comparison_figures(runs)
    for name, _, fig in figs:
        fig.savefig(out / name, dpi=DPI)
    head = "".join(f"<th>{html.escape(r.path.name)}</th>" for r in runs)
    body = []
    rows = [metrics_row(r.summary) for r in runs]
    for i, (label, _, _) in enumerate(METRICS):
        body.append(f"<tr><th>{html.escape(label)}</th>" + "".join(f"<td>{row[i]}</td>" for row in rows) + "</tr>")
    images = "\n".join(f"<figure><img src='{n}' alt='{html.escape(c)}'><figcaption>{html.escape(c)}</figcaption>"
                       f"</figure>" for n, c, _ in figs)
    scen = runs[0].scenario
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Comparison: {html.escape(scen.name)} ({html.escape(renderers_used(runs))})</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #ccc;padding:4px 8px;text-align:right}}
th{{background:#f4f4f4}}figure{{margin:1.5em 0}}img{{max-width:100%}}figcaption{{color:#555}}</style></head>
<body><h1>Ground truth against perception feedback: {html.escape(scen.name)}, {html.escape(renderers_used(runs))}</h1>
<p>Renderer used for the perception runs: <b id="renderer">{html.escape(renderers_used(runs))}</b>.
Scenario description: {html.escape(scen.description)}</p>
<h2>Metrics</h2><table><tr><th></th>{head}</tr>{''.join(body)}</table>
{_section_table(runs)}
<h2>Notes</h2><p>{html.escape(notes)}</p>
<h2>Figures</h2>{images}
</body></html>
"""
    path = out / "report.html"
    path.write_text(page)
    return path
