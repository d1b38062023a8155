"""Standalone accuracy report of the perception stage: Markdown and JSON with the distance-band table.

From a run directory (its summary.json, ``perception`` section): ``python -m perception_proc.accuracy.report
RUN_DIR`` writes ``RUN_DIR/perception_accuracy.md`` and ``RUN_DIR/perception_accuracy.json``. The same writer
takes a section dict directly (:func:`write_report`), e.g. from a study script.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

__all__ = ["render_markdown", "write_report", "main", "TARGET_MEAN_M", "TARGET_ABOVE_FRAC", "PUBLISHED_MEAN_M"]

#: accuracy target inside the 2-15 m working range: mean range error, m
TARGET_MEAN_M = 0.01
#: accuracy target: share of beams above 5 cm
TARGET_ABOVE_FRAC = 0.01
#: published depth-buffer LiDAR figure (Hossny et al. 2020), mean error over 2-120 m, m
PUBLISHED_MEAN_M = 0.0428


def _mm(x) -> str:
    return "-" if x is None else f"{1e3 * x:.2f}"


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.2f}"


def render_markdown(section: dict, title: str = "Perception accuracy") -> str:
    """Markdown text of a ``perception`` summary section (values in m are shown in mm)."""
    re = section.get("range_error", {})
    wm, wf = re.get("working_mean_m"), re.get("working_frac_above_5cm")
    meets = (wm is not None and wf is not None and wm <= TARGET_MEAN_M and wf <= TARGET_ABOVE_FRAC)
    lines = [
        f"# {title}", "",
        f"Sampler: `{section.get('sampler', '?')}`; accuracy evaluation: {re.get('evaluation', '?')}; "
        f"frames evaluated against an exact ray cast: "
        f"{re.get('frames_evaluated', 0)}; beams compared: {re.get('beams', 0):.0f} (per evaluated frame: "
        f"{re.get('beams_per_frame', 'all')}, a stratified random sample of the pattern unless all).", "",
        "## LiDAR range error (noise-free ranges vs exact ray cast of the same beams)", "",
        "| band (m) | beams | mean (mm) | p99 (mm) | > 5 cm (%) |", "|---|---:|---:|---:|---:|",
    ]
    for b in re.get("bands", []):
        lines.append(f"| {b['lo_m']:g}-{b['hi_m']:g} | {b['beams']:.0f} | {_mm(b['mean_m'])} | {_mm(b['p99_m'])} "
                     f"| {_pct(b['frac_above_5cm'])} |")
    lines += [
        f"| **all** | {re.get('beams', 0):.0f} | {_mm(re.get('mean_m'))} | {_mm(re.get('p99_m'))} "
        f"| {_pct(re.get('frac_above_5cm'))} |", "",
        f"Median {_mm(re.get('median_m'))} mm, largest {_mm(re.get('max_m'))} mm; beams with an exact hit but no "
        f"return: {_pct(re.get('beam_missing_frac'))} %.", "",
        f"Working range 2-15 m: mean {_mm(wm)} mm, above 5 cm {_pct(wf)} % "
        f"(target <= {1e3 * TARGET_MEAN_M:g} mm and <= {100 * TARGET_ABOVE_FRAC:g} %: "
        f"{'met' if meets else 'NOT met'}; published depth-buffer LiDAR: {1e3 * PUBLISHED_MEAN_M:g} mm mean "
        "over 2-120 m).", "",
        "## Offloading perception", "",
        "| measure | value |", "|---|---:|",
        f"| height map RMSE, final (mm) | {_mm(section.get('heightmap_rmse_m'))} |",
        f"| height map bias, final (mm) | {_mm(section.get('heightmap_bias_m'))} |",
        f"| height map coverage, final (%) | {_pct(section.get('coverage'))} |",
        f"| height map RMSE, median over frames (mm) | {_mm(section.get('heightmap_rmse_median_m'))} |",
        f"| rim corner error, median (mm) | {_mm(section.get('corner_error_m'))} |",
        f"| impact error, median, horizontal (mm) | {_mm(section.get('impact_error_m'))} |",
        f"| frames with the cart found (%) | {_pct(section.get('cart_found_fraction'))} |",
        f"| frames with an impact (%) | {_pct(section.get('impact_found_fraction'))} |", "",
    ]
    return "\n".join(lines)


def write_report(section: dict, out_dir: Path | str, stem: str = "perception_accuracy") -> tuple[Path, Path]:
    """Write ``<stem>.md`` and ``<stem>.json`` into ``out_dir``; returns both paths."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    md, js = d / f"{stem}.md", d / f"{stem}.json"
    md.write_text(render_markdown(section))
    js.write_text(json.dumps(section, indent=2, allow_nan=False))
    return md, js


def main(argv: list[str] | None = None) -> int:
    """CLI: ``python -m perception_proc.accuracy.report RUN_DIR``. Exit 2 when summary.json lacks perception."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m perception_proc.accuracy.report RUN_DIR", file=sys.stderr)
        return 2
    run = Path(args[0])
    try:
        summary = json.loads((run / "summary.json").read_text())
    except (OSError, json.JSONDecodeError) as exc:
        print(f"{run / 'summary.json'}: {exc}", file=sys.stderr)
        return 2
    section = summary.get("perception")
    if not section:
        print(f"{run / 'summary.json'}: no perception section (did perception run?)", file=sys.stderr)
        return 2
    md, _ = write_report(section, run)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
