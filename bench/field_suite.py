"""The field-conditions suite's table: per case, the share of seeds that filled, stopped safe or failed, with
spill and overfill (docs/field.md).

Reads a finished (or partly finished) run of ``bench/field_suite.yaml`` (``python launch.py sweep
bench/field_suite.yaml --out runs/field-suite``: its ``results.csv``) and writes ``bench/field_suite.json`` and
``bench/field_suite.md`` and puts the table in ``bench/results.md`` (``python bench/run_all.py`` keeps it there). ``--run`` runs the
sweep first (resumable; hours on 2 cores). Usage::

    python bench/field_suite.py --results runs/field-suite
    python bench/field_suite.py --run --out runs/field-suite --jobs 2
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import re
import statistics
import subprocess
import sys
from collections import Counter
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SWEEP = ROOT / "bench" / "field_suite.yaml"
#: the acceptance: at least this share of seeds filled, the rest stopped safe, none failed
FILLED_SHARE = 0.95
STATUSES = ("filled", "stopped_safe", "unfinished", "job_failed")

__all__ = ["SECTION", "summarize_results", "render_markdown", "put_section", "main"]

#: the heading of the suite's section in bench/results.md (run_all.py keeps it when it rewrites the file)
SECTION = "## Field-conditions suite"


def _num(row: dict, key: str) -> float | None:
    try:
        return float(row[key])
    except (KeyError, TypeError, ValueError):
        return None


def summarize_results(rows: list[dict]) -> dict:
    """Per case (the ``base`` column, in order of first appearance): runs, outcome counts and shares, spill (kg:
    max, runs with any), overfill (m: median, max), time to target (s: median of the filled), the reasons of the
    runs that were not filled (counted), and whether the case meets the acceptance."""
    cases: dict[str, list[dict]] = {}
    for r in rows:
        cases.setdefault(r.get("base") or "?", []).append(r)
    out = {}
    for case, rs in cases.items():
        done = [r for r in rs if r.get("outcome") in STATUSES]
        counts = Counter(r["outcome"] for r in done)
        spill = [v for v in (_num(r, "spill_kg") for r in done) if v is not None]
        over = [v for v in (_num(r, "max_overfill_m") for r in done) if v is not None]
        ttt = [v for r in done if r["outcome"] == "filled" for v in [_num(r, "time_to_target_s")] if v is not None]
        n = len(done)
        reasons = Counter(_short(r.get("outcome_reason", "")) for r in done if r["outcome"] != "filled")
        out[case] = {
            "runs": n, **{s: counts.get(s, 0) for s in STATUSES},
            **{f"{s}_share": (counts.get(s, 0) / n if n else None) for s in STATUSES},
            "spill_max_kg": max(spill) if spill else None, "spill_runs": sum(1 for v in spill if v > 0.0),
            "overfill_median_m": statistics.median(over) if over else None, "overfill_max_m": max(over) if over else None,
            "time_to_target_median_s": statistics.median(ttt) if ttt else None,
            "reasons": dict(reasons.most_common()),
            "meets": bool(n and counts.get("filled", 0) / n >= FILLED_SHARE and counts.get("job_failed", 0) == 0),
        }
    return out


def _short(reason: str) -> str:
    """A reason without the numbers that differ from seed to seed (its first clause)."""
    return re.sub(r"\d+(\.\d+)?", "#", reason.split(";")[0])


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def render_markdown(table: dict, meta: dict) -> str:
    """The table as Markdown."""
    lines = [f"Field-conditions suite (`bench/field_suite.yaml`, perception feedback, mock renderer): "
             f"{meta.get('runs', 0)} runs read from `{meta.get('results')}` at {meta.get('written')}; acceptance: at "
             f"least {FILLED_SHARE:.0%} of seeds filled with no spill and at most 5 cm overfill, the rest "
             "stopped_safe, none job_failed.", "",
             "| case | runs | filled | stopped_safe | job_failed | spill max (kg) | overfill median / max (cm) | "
             "target median (s) | meets |", "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for case, t in table.items():
        om, ox = t["overfill_median_m"], t["overfill_max_m"]
        over = "-" if om is None else f"{100 * om:.1f} / {100 * ox:.1f}"
        ttt = "-" if t["time_to_target_median_s"] is None else f"{t['time_to_target_median_s']:.0f}"
        spill = "-" if t["spill_max_kg"] is None else f"{t['spill_max_kg']:.0f}"
        lines.append(f"| `{case}` | {t['runs']} | {_pct(t['filled_share'])} | {_pct(t['stopped_safe_share'])} | "
                     f"{_pct(t['job_failed_share'])} | {spill} | {over} | {ttt} | {'yes' if t['meets'] else 'no'} |")
    notes = [f"* `{case}` not filled: " + "; ".join(f"{n}x {r}" for r, n in t["reasons"].items())
             for case, t in table.items() if t["reasons"]]
    return "\n".join(lines + ([""] + notes if notes else [])) + "\n"


def put_section(results_md: Path, table_md: str) -> None:
    """Write ``table_md`` as the suite's section of ``results_md`` (bench/results.md), replacing the one there."""
    text = results_md.read_text() if results_md.exists() else "# Current benchmark results\n"
    head = text.split(SECTION)[0].rstrip("\n")
    results_md.write_text(f"{head}\n\n{SECTION}\n\n{table_md}")


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, default=ROOT / "runs" / "field-suite", help="the sweep's directory")
    ap.add_argument("--run", action="store_true", help="run the sweep first (resumes what it finds)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "bench", help="folder of field_suite.json / .md")
    a = ap.parse_args(argv)
    if a.run:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        subprocess.run([sys.executable, str(ROOT / "launch.py"), "sweep", str(SWEEP), "--out", str(a.results),
                        "--jobs", str(a.jobs), "--quiet"], env=env, check=False)
    with open(a.results / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    table = summarize_results(rows)
    meta = {"runs": len(rows), "results": os.path.relpath(a.results, ROOT),
            "written": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    (a.out / "field_suite.json").write_text(json.dumps({"meta": meta, "cases": table}, indent=2) + "\n")
    md = render_markdown(table, meta)
    (a.out / "field_suite.md").write_text(md)
    put_section(a.out / "results.md", md)
    sys.stdout.write(md)
    return table


if __name__ == "__main__":
    main()
