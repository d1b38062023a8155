"""The sweep's results table: one row per run, rewritten atomically as runs finish (docs/sweeps.md).

Columns, in order: ``id``; the labels (a study's ``knob``, ``setting``); the varied parameters (dotted scenario
paths); ``seed``, ``completed``, ``error``, ``attempts``; ``outcome`` and ``outcome_reason`` (whether the job was
done: summary.json's ``outcome``, ``filled`` / ``stopped_safe`` / ``unfinished`` / ``job_failed``, and why); the metrics of :data:`METRICS` (from the run's
summary.json, empty where the run has none, e.g. perception metrics of a ground-truth run); ``worker`` (the
Dask worker's address, or ``local``) and ``run_dir`` (relative to the sweep's directory). ``results.csv``
always, ``results.parquet`` too where pyarrow is importable.
"""
from __future__ import annotations

import csv
import json
import logging
import math
from pathlib import Path

from cosim.runtime.files import atomic_replace

__all__ = ["METRICS", "OUTCOME_COLUMNS", "metrics_of", "outcome_of", "read_summary", "read_table", "ResultsTable"]

log = logging.getLogger("cosim.studies.results")

#: table column -> key path in a run's summary.json (docs/architecture.md); units in the names
METRICS: dict[str, tuple[str, ...]] = {
    "spill_kg": ("spill", "mass_kg"),
    "max_overfill_m": ("fill", "max_overfill_m"),
    "profile_rmse_m": ("fill", "profile_rmse_m"),
    "fill_fraction": ("fill", "fill_fraction"),
    "time_to_target_s": ("fill", "time_to_target_s"),
    "coverage": ("perception", "coverage"),
    "range_error_m": ("perception", "range_error", "mean_m"),
    "heightmap_rmse_m": ("perception", "heightmap_rmse_m"),
    "real_time_factor": ("real_time_factor",),
    "sim_time_s": ("sim_time_s",),
    "wall_time_s": ("wall_time_s",),
}


#: table column -> key of summary.json's ``outcome`` (cosim.runtime.outcome)
OUTCOME_COLUMNS: dict[str, str] = {"outcome": "status", "outcome_reason": "reason"}


def outcome_of(summary: dict) -> dict:
    """The :data:`OUTCOME_COLUMNS` of one summary (None where the run wrote no outcome)."""
    out = summary.get("outcome") if isinstance(summary.get("outcome"), dict) else {}
    return {col: out.get(key) for col, key in OUTCOME_COLUMNS.items()}


def metrics_of(summary: dict) -> dict:
    """The :data:`METRICS` of one summary (None where absent)."""
    out = {}
    for col, keys in METRICS.items():
        node = summary
        for k in keys:
            node = node.get(k) if isinstance(node, dict) else None
        out[col] = node if isinstance(node, (int, float)) and not isinstance(node, bool) else None
    return out


def read_summary(run_dir: Path) -> dict | None:
    """A run directory's summary.json, or None when there is none (yet) or it cannot be read."""
    try:
        return json.loads((Path(run_dir) / "summary.json").read_text())
    except (OSError, ValueError):
        return None


def read_table(out: Path) -> dict[str, dict]:
    """An existing results.csv as id -> row of strings (empty when there is none)."""
    try:
        with open(Path(out) / "results.csv", newline="") as f:
            return {row["id"]: row for row in csv.DictReader(f)}
    except (OSError, KeyError, csv.Error):
        return {}


def _cell(value):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return value


class ResultsTable:
    """Rows by run id, written in the sweep's order (``order``: the run ids); :meth:`write` replaces the files
    atomically."""

    def __init__(self, out: Path, labels: tuple[str, ...], parameters: tuple[str, ...], order: list[str]):
        self.out = Path(out)
        self.rank = {rid: i for i, rid in enumerate(order)}
        self.columns = ["id", *labels, *parameters, "seed", "completed", "error", "attempts", *OUTCOME_COLUMNS,
                        *METRICS, "worker", "run_dir"]
        self.rows: dict[str, dict] = {}

    def set(self, run, *, summary: dict | None, error: str, attempts: int, worker: str) -> dict:
        """Record run ``run`` (a RunSpec) with its summary (None if it produced none)."""
        row = {"id": run.id, **run.labels, **run.params, "seed": run.seed,
               "completed": bool(summary and summary.get("completed")), "error": error, "attempts": attempts,
               **outcome_of(summary or {}), **metrics_of(summary or {}), "worker": worker, "run_dir": f"runs/{run.id}"}
        self.rows[run.id] = row
        self.rows = dict(sorted(self.rows.items(), key=lambda kv: self.rank.get(kv[0], len(self.rank))))
        return row

    def write(self) -> Path:
        """Write results.csv (and results.parquet where pyarrow is present); returns the CSV's path."""
        self.out.mkdir(parents=True, exist_ok=True)
        path = self.out / "results.csv"
        with atomic_replace(path) as tmp, open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=self.columns, extrasaction="ignore")
            w.writeheader()
            for row in self.rows.values():
                w.writerow({k: _cell(row.get(k)) for k in self.columns})
        self._write_parquet()
        return path

    def _write_parquet(self) -> None:
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            return
        path = self.out / "results.parquet"
        try:
            rows = [{k: (json.dumps(v) if isinstance(v, (list, dict)) else v) for k, v in r.items()}
                    for r in self.rows.values()]
            table = pa.Table.from_pylist(rows)
            with atomic_replace(path) as tmp:
                pq.write_table(table, tmp)
        except (pa.ArrowException, ValueError, TypeError) as exc:  # mixed types in a column: the CSV has it all
            log.warning("results.parquet not written: %s", exc)
