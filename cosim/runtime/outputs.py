"""The run directory (docs/architecture.md): scenario.yaml, log.txt, summary.json, timeseries.csv, timing.csv,
final maps.

Written by the launcher from what the recorder holds, so a failed or stopped run still writes everything up to
its last completed frame, with ``completed: false`` and the error; during the run the summary says ``status:
running`` and the rows are appended as frames complete (cosim.runtime.stream). Every file that replaces another
is written atomically (cosim.runtime.files); a write error (a full disk) is named with its path and kept in the
summary, which was reserved at the start so that it can always be written.
"""
from __future__ import annotations

import io
import logging
import math
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Sequence

import numpy as np

from cosim.errors import OutputError, RunError, RunInterrupted
from cosim.scenario.config import Scenario

from .files import atomic_write
from .outcome import judge
from .recorder import Recorder
from .specs import ParticipantSpec, load_callable

__all__ = ["default_run_dir", "write_scenario", "compose_summary", "error_entry", "fail_summary", "write_outputs",
           "finish_outputs", "saved_maps", "run_data", "clean_json", "run_status", "STAGE_KEYS", "SAVED_MAPS"]

log = logging.getLogger("cosim.runtime.outputs")

#: participant name -> timing_ms key in summary.json
STAGE_KEYS = {"dynamics": "dynamics", "renderer": "render", "perception": "perception"}
#: final array blocks written to the run directory as ``<name>.npy``
SAVED_MAPS = ("heightmap_truth", "heightmap_perceived")


def default_run_dir(scenario: Scenario, root: Path = Path("runs")) -> Path:
    """``runs/<scenario>-<UTC timestamp>``, made unique with a counter if needed."""
    stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
    base = root / f"{scenario.name}-{stamp}"
    path, n = base, 1
    while path.exists():
        n += 1
        path = base.with_name(f"{base.name}-{n}")
    return path


def write_scenario(run_dir: Path, scenario: Scenario) -> None:
    """scenario.yaml: the fully resolved scenario (every field, defaults included)."""
    from cosim.scenario.loader import dump_resolved

    atomic_write(run_dir / "scenario.yaml", dump_resolved(scenario))


def clean_json(obj):
    """JSON-safe copy: numpy scalars to Python, NaN/inf to None."""
    if isinstance(obj, dict):
        return {k: clean_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return clean_json(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def compose_summary(scenario: Scenario, recorder: Recorder | None, ring: Sequence[ParticipantSpec], *,
                    wall_time_s: float, error: RunError | None) -> dict:
    """summary.json's content (docs/architecture.md) from what the recorder holds, with the job's ``outcome``
    (cosim.runtime.outcome)."""
    completed_frames = len(recorder.frames) if recorder else 0
    last = recorder.frames[-1] if recorder and recorder.frames else -1
    sim_time = max(0, last) * scenario.timing.sensor_period_s
    members = [s.name for s in ring]
    summary: dict = {
        "scenario": scenario.name,
        "feedback": scenario.feedback,
        "renderer": scenario.renderer if "renderer" in members else "none",
        "participants": members,
        "seed": scenario.seed,
        "latency_frames": scenario.timing.latency_frames,
        "sensor_period_s": scenario.timing.sensor_period_s,
        "sim_time_s": sim_time,
        "wall_time_s": wall_time_s,
        "real_time_factor": sim_time / wall_time_s if wall_time_s > 0 else None,
        "frames": completed_frames,
        "frames_planned": scenario.frames + 1,
        "completed": error is None and last == scenario.frames,
        "status": run_status(error),
        "written_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    if error is not None:
        summary["error"] = error_entry(error)
    if recorder is None:
        summary["outcome"] = judge(scenario, summary, {})
        return summary
    med = recorder.timing_medians_ms()
    summary["timing_ms"] = {STAGE_KEYS.get(m, m): med[m] for m in members}
    if not recorder.deferred:
        summary["timing_ms"]["handoff"] = med["handoff"]
    summary["timing_ms"]["frame"] = med["frame"]
    if recorder.turn_ms:
        turns = np.asarray(recorder.turn_ms)
        summary["ring"] = {"turn_median_ms": float(np.median(turns)),
                           "turn_p99_ms": float(np.percentile(turns, 99)),
                           "overlapped": recorder.deferred, "schedule": recorder.schedule}
        if not recorder.deferred:
            summary["ring"]["handoff_median_ms"] = med["handoff"]
    series = recorder.series() if recorder.frames else {}
    if recorder.frames:
        for spec in ring:
            if not spec.summary:
                continue
            try:
                t0 = time.perf_counter()
                summary.update(_summarize(spec, scenario, series, recorder))
                log.info("%s summary in %.1f ms", spec.name, (time.perf_counter() - t0) * 1e3)
            except Exception as exc:  # noqa: BLE001 - a summary bug must not lose the run's other outputs
                log.exception("summary of %s failed", spec.name)
                summary.setdefault("summary_errors", {})[spec.name] = f"{type(exc).__name__}: {exc}"
    summary["outcome"] = judge(scenario, summary, series)
    return summary


def error_entry(error: RunError) -> dict:
    """summary.json's ``error``: type, message, the process that failed, the frame and the traceback; for a hung
    member, what its threads were doing (``threads``, one line each)."""
    entry = {"type": type(error).__name__, "message": str(error), "process": error.process, "frame": error.frame,
             "traceback": error.detail}
    if getattr(error, "threads", None):
        entry["threads"] = list(error.threads)
    return entry


def fail_summary(summary: dict, error: RunError) -> dict:
    """``summary`` of a run whose last step (its figures) failed with ``error``: not completed, with the error."""
    return {**summary, "completed": False, "status": run_status(error), "error": error_entry(error)}


def run_status(error: RunError | None) -> str:
    """summary.json's ``status``: completed, interrupted (SIGINT/SIGTERM), failed (``running`` while it runs)."""
    return "completed" if error is None else "interrupted" if isinstance(error, RunInterrupted) else "failed"


def saved_maps(recorder: Recorder) -> dict[str, np.ndarray]:
    """The final height maps a run directory keeps (``<name>.npy``): those of SAVED_MAPS the run wrote."""
    return {n: recorder.arrays[n] for n in SAVED_MAPS if n in recorder.arrays and recorder.array_frames.get(n, -1) >= 0}


def run_data(run_dir: Path, scenario: Scenario, summary: dict, recorder: Recorder):
    """The :class:`~cosim.report.RunData` that ``load_run(run_dir)`` reads back after :func:`write_outputs`, taken
    from memory (no re-reading of timeseries.csv, scenario.yaml and the maps before the figures)."""
    from cosim.report.rundata import RunData

    maps = saved_maps(recorder)
    return RunData(Path(run_dir), scenario, clean_json(summary), recorder.series(), maps.get("heightmap_truth"),
                   maps.get("heightmap_perceived"))


def write_outputs(run_dir: Path, scenario: Scenario, recorder: Recorder | None, ring: Sequence[ParticipantSpec],
                  *, wall_time_s: float, error: RunError | None, extra: dict | None = None) -> dict:
    """Write timeseries.csv, timing.csv, the final arrays and summary.json whole (with ``extra``'s keys added);
    return the summary. Raises
    :class:`OutputError` after writing what it could (the summary names the failure)."""
    summary, failure = finish_outputs(run_dir, scenario, recorder, ring, wall_time_s=wall_time_s, error=error,
                                      extra=extra)
    if failure is not None:
        raise failure
    return summary


def finish_outputs(run_dir: Path, scenario: Scenario, recorder: Recorder | None, ring: Sequence[ParticipantSpec],
                   *, wall_time_s: float, error: RunError | None, files=None, extra: dict | None = None,
                   reserve: bool = False) -> tuple[dict, OutputError | None]:
    """The run's last writes: the rows not yet appended (``files``, a :class:`cosim.runtime.stream.RunFiles`; None:
    write both CSV files whole), the final maps, then summary.json (atomically; over the reserved one on a full
    disk; ``reserve``: padded again, for a later rewrite after the figures). Returns (summary, the first write
    error or None); a write error becomes the run's error when it had none, and the files after it are still
    tried."""
    from .stream import write_final_summary

    failure: OutputError | None = None
    if recorder is not None:
        try:
            if files is not None:
                files.finish()
            else:
                series, timing = recorder.csv_rows(0, len(recorder.frames), {})
                atomic_write(run_dir / "timeseries.csv", recorder.csv_header(recorder.series_columns) + series)
                if len(recorder.timing_columns) > 1:
                    atomic_write(run_dir / "timing.csv", recorder.csv_header(recorder.timing_columns) + timing)
        except OutputError as exc:
            failure = exc
        for name, a in saved_maps(recorder).items():
            try:
                atomic_write(run_dir / f"{name}.npy", _npy_bytes(a))
            except OutputError as exc:
                failure = failure or exc
    if files is not None and files.failed is not None:
        failure = failure or files.failed
    if error is None and failure is not None:
        error = failure
    summary = compose_summary(scenario, recorder, ring, wall_time_s=wall_time_s, error=error)
    summary.update(extra or {})
    try:
        write_final_summary(run_dir, clean_json(summary), reserve=reserve)
    except OutputError as exc:
        failure = failure or exc
    return summary, failure


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _summarize(spec: ParticipantSpec, scenario: Scenario, series: dict, recorder: Recorder) -> dict:
    fn = load_callable(spec.summary)
    truth = recorder.arrays.get("heightmap_truth")
    if spec.name == "perception":
        return fn(scenario, series, truth, recorder.arrays.get("heightmap_perceived"))
    return fn(scenario, series, truth)
