"""A session as Markdown (what ``bench/run.py`` prints) and as JSON (``--json FILE``)."""
from __future__ import annotations

import json
import math
from pathlib import Path

from .arms import shown_path
from .machine import describe
from .rounds import Stat
from .session import Result, Session

__all__ = ["case_markdown", "fmt", "markdown", "put_results_section", "table", "to_json", "write_json"]


def fmt(v) -> str:
    """A number with about four significant figures (thousands grouped), a string as is, None and NaN as ``-``."""
    if v is None:
        return "-"
    if isinstance(v, str):
        return v
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    if not math.isfinite(v):
        return "-"
    a = abs(v)
    if a >= 1000:
        return f"{v:,.0f}"
    if a >= 100:
        return f"{v:.1f}"
    if a >= 10:
        return f"{v:.2f}"
    if a >= 0.01 or a == 0:
        return f"{v:.3f}"
    return f"{v:.3g}"


def _cell(v, ratio: bool = False) -> str:
    if isinstance(v, Stat):
        show = (lambda x: f"{x:.3f}x") if ratio else fmt
        if v.n > 1 and v.lo != v.hi:
            return f"{show(v.median)} ({show(v.lo)}-{show(v.hi)})"
        return show(v.median)
    return fmt(v)


def table(per_arm: dict[str, dict], title: str, ratio: bool = False) -> list[str]:
    """Markdown lines of one table of every arm (an ``arm`` column where there are several)."""
    arms = [a for a in per_arm if title in per_arm[a]]
    rows = {r: None for a in arms for r in per_arm[a][title]}
    cols = list({c: None for a in arms for r in per_arm[a][title].values() for c in r})
    lead = (["arm"] if len(per_arm) > 1 else []) + [""]
    lines = ["| " + " | ".join(lead + cols) + " |", "|" + "---|" * len(lead) + "---:|" * len(cols)]
    for a in arms:
        for r in rows:
            cells = per_arm[a][title].get(r)
            if cells is None:
                continue
            head = ([a] if len(per_arm) > 1 else []) + [r]
            lines.append("| " + " | ".join(head + [_cell(cells.get(c), ratio) for c in cols]) + " |")
    return lines


def _titles(per_arm: dict[str, dict]) -> list[str]:
    return list({t: None for agg in per_arm.values() for t in agg})


def case_markdown(res: Result, commits: dict[str, str | None]) -> list[str]:
    c = res.case
    arms = "; ".join(f"`{a.label}`: {shown_path(a.tree)}" + (f" at {commits.get(a.label)}" if commits.get(a.label) else "")
                     + (f", `--set {' --set '.join(a.settings)}`" if a.settings else "") for a in res.arms)
    opts = ", ".join(f"{k}={v}" for k, v in res.opts.items()) or "none"
    lines = [f"## {c.name}: {c.summary}", "",
             f"{res.rounds} round(s), arms interleaved ({arms}); options: {opts}."
             + (" Medians over the rounds (min-max)." if res.rounds > 1 else ""), ""]
    for f in res.failures:
        lines += [f"**FAILED**: {f}", ""]
    med = res.median()
    for title in _titles(med):
        if title:
            lines += [f"### {title}", ""]
        lines += table(med, title) + [""]
    for label, ratios in res.paired().items():
        for title in _titles({label: ratios}):
            lines += [f"### {label} / {res.arms[0].label}{': ' + title if title else ''} (each round's own ratio)", ""]
            lines += table({label: ratios}, title, ratio=True) + [""]
    return lines


def markdown(s: Session) -> str:
    """The whole session: the command, the machine and its load, then every case's tables."""
    lines = [f"`{s.command}`", "",
             f"{describe(s.machine)}; load average {s.load_before:.1f} before and {s.load_after:.1f} after; "
             f"{s.written_utc}.", ""]
    if s.quick:
        lines += ["**Quick mode: a check of the cases, not their figures.**", ""]
    for res in s.results:
        lines += case_markdown(res, s.commits)
    return "\n".join(lines)


def _plain(v):
    if isinstance(v, Stat):
        return v.as_dict()
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def to_json(s: Session) -> dict:
    """Everything of the session: per case its options, arms, every sample, the medians and the paired ratios."""
    cases = {}
    for res in s.results:
        cases[res.case.name] = {
            "summary": res.case.summary, "options": res.opts, "rounds": res.rounds,
            "arms": [{"label": a.label, "tree": shown_path(a.tree), "settings": list(a.settings),
                      "commit": s.commits.get(a.label)} for a in res.arms],
            "failures": res.failures, "samples": _plain(res.samples), "median": _plain(res.median()), "paired": _plain(res.paired())}
    return {"command": s.command, "written_utc": s.written_utc, "machine": s.machine, "quick": s.quick,
            "load_average": [s.load_before, s.load_after], "cases": cases}


def write_json(s: Session, path: Path) -> None:
    path.write_text(json.dumps(to_json(s), indent=1, allow_nan=False) + "\n")


def put_results_section(results_md: Path, heading: str, intro: list[str], tables: dict[str, dict],
                        cell=lambda v: f"{v:.2f}" if isinstance(v, float) else str(v)) -> None:
    """Write ``tables`` ({title: {row: {column: value}}}) under ``heading`` (a second-level heading) with the
    ``intro`` lines as that section of ``results_md`` (bench/results.md), replacing the one there and keeping
    the rest of the file; ``cell(value) -> str`` formats a value."""
    lines = [heading, "", *intro]
    for title, rows in tables.items():
        cols = list(next(iter(rows.values())))
        lines += [f"**{title}**", "", "| | " + " | ".join(cols) + " |", "|---|" + "---:|" * len(cols)]
        lines += [f"| {name} | " + " | ".join(cell(v) for v in row.values()) + " |" for name, row in rows.items()]
        lines.append("")
    text = results_md.read_text() if results_md.exists() else "# Current benchmark results\n"
    head, _, rest = text.partition(heading)
    nxt = rest.find("\n## ")
    tail = rest[nxt:] if rest and nxt >= 0 else ""
    results_md.write_text(head.rstrip("\n") + "\n\n" + "\n".join(lines) + tail)
