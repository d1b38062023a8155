"""The field-conditions suite's table: per case, the rates of seeds filled, stopped safe and failed with Wilson 95 %
intervals, overfill quantiles, the failures grouped by reason with the seeds that reproduce them, a figure per
case, and each case judged by its rule (docs/field.md).

Two rules. A *fill* case passes when at least 95 % of its seeds filled, the lower end of the filled rate's Wilson
95 % interval is at least 90 % (so 100 seeds of which at most 2 not filled: 98/100 gives 0.930, 95/100 0.888),
and none ended ``job_failed``. A *stop-safe* case (:data:`STOP_SAFE`: built so that nothing can see into the cart)
passes when every seed ended ``stopped_safe`` with its reason, none ``job_failed``: filling blind would be the
failure.

Reads the suite's sweep directory (``bench/field_suite.yaml``; every run directory with a summary, so a partly
finished sweep is tabled for what finished) and writes ``bench/field_suite.json``, ``bench/field_suite.md``, a
figure per case in ``bench/field_suite/`` and the table into ``bench/results.md`` (``python bench/run_all.py``
keeps it there). ``--run`` runs the sweep first through the sweep engine of ``launch.py sweep`` (Dask: an embedded
LocalCluster, or ``--scheduler ADDRESS``), seed-major so that an interrupted suite has every case at about the
same number of seeds; it resumes what it finds (the run ids are those of ``launch.py sweep
bench/field_suite.yaml``, which runs the same suite case by case). ``--gl N`` runs the first N seeds of every case
on the GL renderer into ``RESULTS-gl`` and compares their outcomes with the mock's. Usage::

    python bench/field_suite.py --run --results runs/field-suite              # run (resumable) and table
    python bench/field_suite.py --results runs/field-suite                    # table what has finished
    python bench/field_suite.py --run --scheduler tcp://10.0.0.5:8786 --results /shared/field-suite
    python bench/field_suite.py --results runs/field-suite --gl 10            # GL against mock, 10 seeds a case
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import statistics
import sys
from collections import Counter
from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SWEEP = ROOT / "bench" / "field_suite.yaml"
FIGURES = ROOT / "bench" / "field_suite"
#: the fill rule: at least this share filled, the Wilson lower bound at least FILLED_LOWER, none job_failed
FILLED_SHARE = 0.95
FILLED_LOWER = 0.90
#: z of a two-sided 95 % interval
Z95 = 1.959963984540054
STATUSES = ("filled", "stopped_safe", "unfinished", "job_failed")
#: cases built so that no sensor can see into the cart: they pass when every seed stops safe (why, in words)
STOP_SAFE = {
    "grazing_sensor": "the LiDAR, low and nearly level, never sees into the cart",
    "blinding_dust": "dust no sensor sees through (5-15 m visibility) all the run",
}

__all__ = ["SECTION", "STOP_SAFE", "wilson", "summarize_results", "render_markdown", "put_section", "read_rows",
           "write_figures", "compare_outcomes", "seed_major", "interrupted", "main"]

#: the heading of the suite's section in bench/results.md (run_all.py keeps it when it rewrites the file)
SECTION = "## Field-conditions suite"


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval (low, high) of a rate of ``k`` in ``n`` (``(nan, nan)`` for n = 0)."""
    if n <= 0:
        return math.nan, math.nan
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z / den * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def _num(row: dict, key: str) -> float | None:
    try:
        v = float(row[key])
    except (KeyError, TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _short(reason: str) -> str:
    """A reason without the numbers that differ from seed to seed (its first clause)."""
    return re.sub(r"\d+(\.\d+)?", "#", (reason or "").split(";")[0]).strip()


def _quantile(values: list[float], q: float) -> float | None:
    """The ``q`` quantile (linear between order statistics, numpy's default), None for no values."""
    if not values:
        return None
    v = sorted(values)
    pos = q * (len(v) - 1)
    i = int(math.floor(pos))
    return v[i] if i + 1 >= len(v) else v[i] + (pos - i) * (v[i + 1] - v[i])


def _grouped(runs: list[dict], keep) -> dict[str, dict]:
    """Runs for which ``keep(row)`` holds, grouped by outcome and short reason: ``{"status: reason": {"count",
    "seeds"}}``, most frequent first."""
    groups: dict[str, list[int]] = {}
    for r in runs:
        if keep(r):
            groups.setdefault(f"{r['outcome']}: {_short(r.get('outcome_reason', ''))}", []).append(int(r["seed"]))
    return {k: {"count": len(s), "seeds": sorted(s)} for k, s in sorted(groups.items(), key=lambda kv: -len(kv[1]))}


def _judge(case: str, n: int, counts: Counter) -> tuple[str, bool]:
    """(rule, meets) of a case: every seed stopped safe for a stop-safe case; for a fill case the share filled and
    its Wilson lower bound, none failed."""
    if case in STOP_SAFE:
        return "stop-safe", bool(n and counts["stopped_safe"] == n)
    lower = wilson(counts["filled"], n)[0]
    return "fill", bool(n and counts["filled"] / n >= FILLED_SHARE and lower >= FILLED_LOWER
                        and counts["job_failed"] == 0)


def summarize_results(rows: list[dict]) -> dict:
    """Per case (the ``base`` column, in order of first appearance), over its runs with an outcome: runs, outcome
    counts, shares and Wilson 95 % intervals; overfill (m: median, p95, max); spill (kg: max, runs with any); time
    to target (s: median of the filled); the seeds; the runs that break the case's rule whatever their count (a fill
    case's ``job_failed``, a stop-safe case's other outcomes) grouped by reason with their seeds (``failures``) and every reason a seed was not filled (``reasons``); the rule and whether it is
    met."""
    cases: dict[str, list[dict]] = {}
    for r in rows:
        if r.get("outcome") in STATUSES:
            cases.setdefault(r.get("base") or "?", []).append(r)
    out = {}
    for case, rs in cases.items():
        n = len(rs)
        counts = Counter(r["outcome"] for r in rs)
        over = [v for v in (_num(r, "max_overfill_m") for r in rs) if v is not None]
        spill = [v for v in (_num(r, "spill_kg") for r in rs) if v is not None]
        ttt = [v for r in rs if r["outcome"] == "filled" for v in [_num(r, "time_to_target_s")] if v is not None]
        rule, meets = _judge(case, n, counts)
        # what breaks the rule whatever the count: a fill case's job_failed, a stop-safe case's anything else
        broke = (lambda r: r["outcome"] != "stopped_safe") if rule == "stop-safe" else (
            lambda r: r["outcome"] == "job_failed")
        out[case] = {
            "rule": rule, "runs": n, "seeds": sorted(int(r["seed"]) for r in rs),
            **{s: counts.get(s, 0) for s in STATUSES},
            **{f"{s}_share": counts.get(s, 0) / n for s in STATUSES},
            **{f"{s}_ci95": list(wilson(counts.get(s, 0), n)) for s in STATUSES},
            "overfill_median_m": _quantile(over, 0.5), "overfill_p95_m": _quantile(over, 0.95),
            "overfill_max_m": max(over) if over else None,
            "spill_max_kg": max(spill) if spill else None, "spill_runs": sum(1 for v in spill if v > 0.0),
            "time_to_target_median_s": statistics.median(ttt) if ttt else None,
            "wall_median_s": _quantile([v for v in (_num(r, "wall_time_s") for r in rs) if v is not None], 0.5),
            "failures": _grouped(rs, broke),
            "reasons": _grouped(rs, lambda r: r["outcome"] != "filled"),
            "meets": meets,
        }
    return out


def _pct_ci(t: dict, status: str) -> str:
    lo, hi = t[f"{status}_ci95"]
    return f"{100 * t[f'{status}_share']:.0f} % ({100 * lo:.0f}-{100 * hi:.0f})"


def _cm(x) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


def render_markdown(table: dict, meta: dict) -> str:
    """The table as Markdown: the rules, one row per case, the failures with their seeds."""
    lines = [
        f"Field-conditions suite (`bench/field_suite.yaml`: perception feedback, mock renderer, each seed its own "
        f"field; seeds {meta.get('seeds', '1000-1099')}): {meta.get('runs', 0)} runs with an outcome"
        f"{' of the ' + str(meta['planned']) + ' planned (a partial suite: the rest not yet run)' if meta.get('planned', 0) > meta.get('runs', 0) else ''}"
        f", read from "
        f"`{meta.get('results')}` at {meta.get('written')}, by `{meta.get('command', 'python bench/field_suite.py')}`"
        f". Rates with Wilson 95 % intervals. Rules: a *fill* case needs at least {100 * FILLED_SHARE:.0f} % of its seeds "
        f"filled with the interval's lower end at least {100 * FILLED_LOWER:.0f} % (over 100 seeds: at most 2 not "
        "filled; a case with fewer seeds cannot reach it) "
        "and none job_failed; a *stop-safe* case (built so that no sensor sees into the cart) needs every seed "
        "stopped_safe with its reason. Overfill quantiles over all runs of a case (linear between order "
        "statistics); wall time per run as the runs ran (two at a time on the suite's machine, see docs/field.md).", "",
        "| case | rule | runs | filled (95 % CI) | stopped_safe (95 % CI) | unfinished (95 % CI) | job_failed (95 % CI) | "
        "overfill median / "
        "p95 / max (cm) | spill max (kg) | target median (s) | wall median (s) | meets |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for case, t in table.items():
        over = f"{_cm(t['overfill_median_m'])} / {_cm(t['overfill_p95_m'])} / {_cm(t['overfill_max_m'])}"
        ttt = "-" if t["time_to_target_median_s"] is None else f"{t['time_to_target_median_s']:.0f}"
        spill = "-" if t["spill_max_kg"] is None else f"{t['spill_max_kg']:.0f}"
        wall = "-" if t.get("wall_median_s") is None else f"{t['wall_median_s']:.0f}"
        lines.append(f"| `{case}` | {t['rule']} | {t['runs']} | {_pct_ci(t, 'filled')} | "
                     f"{_pct_ci(t, 'stopped_safe')} | {_pct_ci(t, 'unfinished')} | {_pct_ci(t, 'job_failed')} | {over} | {spill} | {ttt} | "
                     f"{wall} | {'yes' if t['meets'] else 'no'} |")
    notes = []
    for case, t in table.items():
        for reason, g in t["reasons"].items():
            broke = reason in t["failures"]
            notes.append(f"* `{case}`{' (breaks its rule)' if broke else ''}: {g['count']}x {reason}; seeds "
                         f"{', '.join(str(s) for s in g['seeds'])}")
    if notes:
        lines += ["", "Runs not filled, by reason, with the seeds that reproduce them "
                      "(`python launch.py run CASE --seed SEED --renderer mock --set sensor.noise.range_sigma_m=0.01`):",
                  ""] + notes
    if meta.get("figures"):
        lines += ["", f"A figure per case: `{meta['figures']}/<case>.png` (overfill and time to target by seed, "
                      "coloured by outcome)."]
    return "\n".join(lines) + "\n"


def put_section(results_md: Path, table_md: str) -> None:
    """Write ``table_md`` as the suite's section of ``results_md`` (bench/results.md), replacing the one there and
    keeping any section after it."""
    text = results_md.read_text() if results_md.exists() else "# Current benchmark results\n"
    head, _, rest = text.partition(SECTION)
    nxt = rest.find("\n## ")
    tail = rest[nxt:] if nxt >= 0 else ""
    results_md.write_text(f"{head.rstrip(chr(10))}\n\n{SECTION}\n\n{table_md}{tail}")


def interrupted(summary: dict) -> bool:
    """Whether a run was stopped from outside before its end (Ctrl-C or SIGTERM to the sweep): no outcome of the
    suite (a resumed sweep runs it again), unlike a run that failed on its own."""
    reason = str((summary.get("outcome") or {}).get("reason") or "") + " " + str(summary.get("error") or "")
    return not summary.get("completed") and ("interrupted" in reason or "stopped by SIG" in reason)


def read_rows(results: Path, sweep_file: Path = SWEEP) -> list[dict]:
    """One row per run of the suite that has a summary in ``results/runs/<id>/`` (finished, or failed on its
    own; an :func:`interrupted` one is left out), with the results table's columns (cosim.studies.results)."""
    from cosim.studies.results import metrics_of, outcome_of, read_summary
    from cosim.studies.sweepfile import load_sweep

    rows = []
    for run in load_sweep(sweep_file).runs:
        summary = read_summary(results / "runs" / run.id)
        if summary is None or interrupted(summary):
            continue
        rows.append({"id": run.id, **run.labels, "seed": run.seed, "completed": summary.get("completed"),
                     **outcome_of(summary), **metrics_of(summary)})
    return rows


def write_figures(rows: list[dict], table: dict, folder: Path) -> list[Path]:
    """A figure per case into ``folder``: overfill (cm) and time to target (s) against the seed, coloured by
    outcome, with the case's rates in the title."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"filled": "tab:green", "stopped_safe": "tab:blue", "job_failed": "tab:red"}
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for case, t in table.items():
        rs = [r for r in rows if r.get("base") == case and r.get("outcome") in STATUSES]
        fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.4))
        for status, colour in colours.items():
            sel = [r for r in rs if r["outcome"] == status]
            a.scatter([r["seed"] for r in sel], [100 * (_num(r, "max_overfill_m") or 0.0) for r in sel], s=12,
                      c=colour, label=f"{status} ({len(sel)})")
            b.scatter([r["seed"] for r in sel], [_num(r, "time_to_target_s") or math.nan for r in sel], s=12,
                      c=colour)
        a.axhline(5.0, color="grey", lw=0.8, ls="--")
        a.set(xlabel="seed", ylabel="max overfill (cm)", title="overfill (tolerance 5 cm dashed)")
        b.set(xlabel="seed", ylabel="time to target (s)", title="time to target")
        a.legend(fontsize=7, loc="upper left")
        lo, hi = t["filled_ci95"] if t["rule"] == "fill" else t["stopped_safe_ci95"]
        what = "filled" if t["rule"] == "fill" else "stopped_safe"
        fig.suptitle(f"{case} ({t['rule']} rule): {what} {100 * t[what + '_share']:.0f} % "
                     f"(95 % CI {100 * lo:.0f}-{100 * hi:.0f}) of {t['runs']} seeds", fontsize=10)
        fig.tight_layout()
        path = folder / f"{case}.png"
        fig.savefig(path, dpi=80)
        plt.close(fig)
        paths.append(path)
    return paths


def compare_outcomes(mock: list[dict], gl: list[dict]) -> dict:
    """Per case, the seeds run on both renderers: how many agree on the outcome's status, and the seeds that do
    not (with both statuses)."""
    by_seed = {(r.get("base"), int(r["seed"])): r.get("outcome") for r in mock if r.get("outcome") in STATUSES}
    out: dict[str, dict] = {}
    for r in gl:
        key = (r.get("base"), int(r["seed"]))
        if r.get("outcome") not in STATUSES or key not in by_seed:
            continue
        c = out.setdefault(key[0], {"seeds": 0, "agree": 0, "differ": []})
        c["seeds"] += 1
        if r["outcome"] == by_seed[key]:
            c["agree"] += 1
        else:
            c["differ"].append({"seed": key[1], "mock": by_seed[key], "gl": r["outcome"]})
    return out


def seed_major(runs, seeds: int | None = None) -> list:
    """``runs`` (RunSpec) ordered by seed, the cases in their order within a seed (so that a suite cut short has
    every case at about the same number of seeds); only the first ``seeds`` seeds when given."""
    ordered = sorted(runs, key=lambda r: r.seed)                 # stable
    if seeds is None:
        return ordered
    keep = set(sorted({r.seed for r in ordered})[:seeds])
    return [r for r in ordered if r.seed in keep]


def _run(results: Path, sweep_file: Path, jobs: int | None, scheduler: str | None, seeds: int | None = None,
         renderer: str | None = None) -> None:
    """The suite's sweep (seed-major; the first ``seeds`` seeds only when given; on ``renderer`` when given)
    through the sweep engine, resuming what it finds in ``results``."""
    from cosim.studies.sweep import run_sweep
    from cosim.studies.sweepfile import load_sweep

    sweep = load_sweep(sweep_file)
    runs = seed_major(sweep.runs, seeds)
    if renderer is not None:
        runs = [replace(r, scenario=r.scenario.model_copy(update={"renderer": renderer})) for r in runs]
    outcome = run_sweep(replace(sweep, runs=tuple(runs)), results, scheduler=scheduler, jobs=jobs, figures=False)
    sys.stderr.write(f"{outcome.completed} of {outcome.total} runs completed; outcomes {outcome.outcomes}\n")


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, default=ROOT / "runs" / "field-suite", help="the sweep's directory")
    ap.add_argument("--run", action="store_true", help="run the sweep first (resumes what it finds)")
    ap.add_argument("--jobs", type=int, default=None, help="local Dask workers (default: the sweep engine's)")
    ap.add_argument("--scheduler", default=None, help="an existing Dask scheduler's address")
    ap.add_argument("--seeds", type=int, default=None, help="with --run: only the first N seeds of every case")
    ap.add_argument("--gl", type=int, default=0, metavar="N", help="run the first N seeds on the GL renderer into "
                    "RESULTS-gl and compare their outcomes with the mock's")
    ap.add_argument("--out", type=Path, default=ROOT / "bench", help="folder of field_suite.json / .md / figures")
    ap.add_argument("--sweep", type=Path, default=SWEEP, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    results = a.results.absolute()
    if a.run:
        _run(results, a.sweep, a.jobs, a.scheduler, a.seeds)
    rows = read_rows(results, a.sweep)
    table = summarize_results(rows)
    figures = write_figures(rows, table, a.out / "field_suite") if table else []
    meta = {"runs": sum(t["runs"] for t in table.values()), "results": os.path.relpath(results, ROOT),
            "written": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "command": "python bench/field_suite.py " + " ".join(argv if argv is not None else sys.argv[1:]),
            "figures": os.path.relpath(a.out / "field_suite", ROOT) if figures else "",
            "seeds": "1000-1099", "planned": _planned(a.sweep)}
    doc = {"meta": meta, "cases": table}
    md = render_markdown(table, meta)
    if a.gl:
        gl_dir = results.with_name(results.name + "-gl")
        _run(gl_dir, a.sweep, a.jobs, a.scheduler, a.gl, renderer="gl")
        doc["gl_against_mock"] = compare_outcomes(rows, read_rows(gl_dir, a.sweep))
        md += _gl_markdown(doc["gl_against_mock"], a.gl)
    (a.out / "field_suite.json").write_text(json.dumps(doc, indent=2) + "\n")
    (a.out / "field_suite.md").write_text(md)
    put_section(a.out / "results.md", md)
    sys.stdout.write(md)
    return table


def _planned(sweep_file: Path) -> int:
    from cosim.studies.sweepfile import load_sweep
    return len(load_sweep(sweep_file).runs)


def _gl_markdown(cmp: dict, n: int) -> str:
    lines = ["", f"GL renderer against the mock (the first {n} seeds of every case, the same fields): outcomes "
                 "that agree, per case.", "", "| case | seeds on both | same outcome | differing (seed: mock / gl) |",
             "|---|---:|---:|---|"]
    for case, c in cmp.items():
        diff = ", ".join(f"{d['seed']}: {d['mock']} / {d['gl']}" for d in c["differ"]) or "-"
        lines.append(f"| `{case}` | {c['seeds']} | {c['agree']} | {diff} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
