"""A run's figures (``outputs.figures``): drawn after a completed run, never after a failed or stopped one, and
drawable at any time later with ``python launch.py report RUN_DIR`` (docs/reliability.md).

Drawing the four figures takes 0.5-0.7 s of CPU, and the launcher returns within 2 s of a fault, so a run that
failed or was stopped writes its data, says in its summary how to draw the figures, and returns. summary.json's
``figures`` entry says what happened to them (:data:`STATES`):

* ``drawn``: drawn (``files`` lists them), by the launcher after a completed run or by ``report``;
* ``pending``: the summary written just before the launcher draws them (a launcher killed meanwhile leaves it);
* ``not_drawn``: the run failed or was stopped, or a stop signal cut the drawing short (``reason``); ``command``
  draws them;
* ``off``: ``outputs.figures`` is false, or the run has nothing to draw (no dynamics record, no frame);
* ``failed``: drawing failed (``error``). A write error (a full disk) is also the run's error (exit 1); each
  figure is written whole or not at all, so those written before it are whole and the one it hit is absent.
"""
from __future__ import annotations

import contextlib
import json
import logging
import shlex
from pathlib import Path
from typing import Callable, ContextManager

from cosim.errors import OutputError, RunError, RunInterrupted
from cosim.scenario.config import Scenario

from .outputs import clean_json, fail_summary, run_data
from .recorder import Recorder
from .stream import write_final_summary

__all__ = ["STATES", "DRAWN", "PENDING", "NOT_DRAWN", "OFF", "FAILED", "report_command", "figures_plan",
           "draw_figures", "report"]

log = logging.getLogger("cosim.runtime.figures")

DRAWN, PENDING, NOT_DRAWN, OFF, FAILED = "drawn", "pending", "not_drawn", "off", "failed"
#: the values of summary.json's ``figures.status``
STATES = (DRAWN, PENDING, NOT_DRAWN, OFF, FAILED)
#: the block the figures are drawn from (dynamics' record)
NEEDED_BLOCK = "dyn_state"


def report_command(run_dir: Path) -> str:
    """The command that draws a run directory's figures later."""
    return f"python launch.py report {shlex.quote(str(run_dir))}"


def figures_plan(run_dir: Path, scenario: Scenario, recorder: Recorder | None, error: RunError | None) -> dict:
    """summary.json's ``figures`` entry before any is drawn: ``pending`` when the launcher will draw them now,
    else why not (``off``, or ``not_drawn`` for a failed or stopped run, with the command that draws them)."""
    if not scenario.outputs.figures:
        return {"status": OFF, "reason": "outputs.figures is false"}
    if recorder is None or not recorder.frames or NEEDED_BLOCK not in recorder.blocks:
        return {"status": OFF, "reason": "the run recorded no dynamics frame to draw"}
    if error is not None:
        why = str(error) if isinstance(error, RunInterrupted) else "the run failed"
        return {"status": NOT_DRAWN, "reason": why, "command": report_command(run_dir)}
    return {"status": PENDING}


def draw_figures(run_dir: Path, scenario: Scenario, summary: dict, recorder: Recorder,
                 interruptible: Callable[[], ContextManager] = contextlib.nullcontext) -> tuple[dict, OutputError | None]:
    """Draw the figures of a completed run from memory and rewrite summary.json with the outcome. Returns (the
    summary written, the write error that is now the run's error, or None). ``interruptible()`` is entered
    around the drawing only: a stop signal meanwhile (:class:`RunInterrupted`, raised by
    :meth:`cosim.runtime.signals.StopSignals.raising`) leaves the figures drawn so far, and the summary says so."""
    from cosim.report import write_run_figures

    failure: OutputError | None = None
    try:
        with interruptible():
            files = write_run_figures(run_data(run_dir, scenario, summary, recorder))
        entry = {"status": DRAWN, "files": [p.name for p in files]}
    except RunInterrupted as exc:
        log.warning("figures not drawn: %s while drawing them", exc)
        entry = {"status": NOT_DRAWN, "reason": f"{exc} while drawing them", "command": report_command(run_dir)}
    except OutputError as exc:
        failure = exc
        entry = {"status": FAILED, "error": str(exc)}
    except Exception as exc:  # noqa: BLE001 - a drawing bug: the run's data is written; logged with its traceback
        log.exception("drawing the run's figures failed")
        entry = {"status": FAILED, "error": f"{type(exc).__name__}: {exc}"}
    summary = {**(fail_summary(summary, failure) if failure is not None else summary), "figures": entry}
    try:
        write_final_summary(run_dir, clean_json(summary))
    except OutputError as exc:
        failure = failure or exc
    return summary, failure


def report(run_dir: Path) -> dict:
    """Draw the figures of run directory ``run_dir`` (any run that recorded dynamics frames: completed, failed or
    stopped) and record them in its summary.json. Returns the ``figures`` entry. Raises FileNotFoundError (not a
    run directory), :class:`OutputError` (a write error: the figures before it are whole, the summary unchanged)
    and ValueError (nothing to draw)."""
    from cosim.report import load_run, write_run_figures

    run_dir = Path(run_dir)
    for name in ("scenario.yaml", "summary.json", "timeseries.csv"):
        if not (run_dir / name).is_file():
            raise FileNotFoundError(f"{run_dir}: no {name}: not a run directory (or the run wrote nothing yet)")
    run = load_run(run_dir)
    if run.col(f"{NEEDED_BLOCK}.t_s") is None or not len(run.series.get("frame", ())):
        raise ValueError(f"{run_dir}: the run recorded no dynamics frame to draw")
    files = write_run_figures(run)
    entry = {"status": DRAWN, "files": [p.name for p in files]}
    summary = json.loads((run_dir / "summary.json").read_text())
    write_final_summary(run_dir, {**summary, "figures": entry})
    return entry
