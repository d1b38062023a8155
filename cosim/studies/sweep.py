"""The sweep engine: a sweep's runs on Dask distributed (docs/sweeps.md).

Each run is an ordinary launched run (``launch()``, its own OS processes) executed by a Dask worker into
``OUT/runs/<id>/``. Locally an embedded ``LocalCluster`` is started (one single-threaded worker process per
job; jobs = cores // cores per run unless given); with ``scheduler`` the runs go to an existing cluster, GL runs
only to workers that declare the ``EGL`` resource. A run with a completed summary.json is never run again
(resume); a failed one is retried ``retries`` times, then recorded with its error. A worker that dies costs
only its run: Dask reschedules it, and if the scheduler gives up the run counts as a failed attempt. The
results table is rewritten as each run finishes; Ctrl-C cancels what is queued and keeps what finished.
"""
from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

from cosim.runtime.rundir import make_out_dir
from cosim.runtime.signals import request_stop, sigint_blocked_in_new_threads
from cosim.scenario.config import Scenario

from .results import ResultsTable, read_summary, read_table
from .sweepfile import RunSpec, Sweep

__all__ = ["EGL", "SweepOutcome", "execute_run", "local_jobs", "open_client", "run_sweep"]

log = logging.getLogger("cosim.studies.sweep")

#: the Dask worker resource a GL run asks for (``dask worker ... --resources EGL=1``)
EGL = "EGL"
LOCAL = "local"
LOOPBACK_ANY_PORT = "127.0.0.1:0"
#: how long an interrupted sweep waits for the runs in progress on the workers to end (each stops within ~0.5 s
#: of being asked, and writes its outputs), s
STOP_WAIT_S = 10.0
#: Dask settings of the embedded cluster: its idle work competes with the runs for the cores. No statistical
#: profiler (it samples every thread of a worker every 10 ms, the run's supervisor included); event-loop health
#: ticks, system and memory monitors at 1-2 s instead of 20-500 ms
QUIET_CLUSTER = {"distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "1s",
                 "distributed.admin.system-monitor.interval": "2s",
                 "distributed.worker.memory.monitor-interval": "1s"}
#: the embedded cluster's patience: its scheduler, workers and client are this machine's own processes, so a
#: silent connection is a starved process on a busy machine (a laptop with other work, a sweep run at nice 19),
#: not a lost host. Dask's defaults (30 s for a TCP comm, 5 min of worker heartbeats) cut the client off the
#: scheduler at a load of 40 on 2 cores and cancelled every run. A worker process that dies is still seen at once
#: by its nanny; a run that fails is retried (``retries``)
PATIENT_CLUSTER = {"distributed.comm.timeouts.tcp": "900s", "distributed.comm.timeouts.connect": "300s",
                   "distributed.scheduler.worker-ttl": "1h"}


@dataclass(frozen=True)
class SweepOutcome:
    """How a sweep ended: counts of runs, the results table's path, whether Ctrl-C stopped it."""

    total: int
    completed: int
    failed: int
    skipped: int
    interrupted: bool
    results: Path
    #: runs per job outcome (``filled``, ``stopped_safe``, ``unfinished``, ``job_failed``; summary.json ``outcome``)
    outcomes: dict = field(default_factory=dict)


def execute_run(run_dir: str, scenario_json: str) -> dict:
    """Run one scenario into ``run_dir`` (on a Dask worker, or anywhere): summary, error text and worker."""
    from cosim.runtime.launcher import launch

    try:
        from distributed import get_worker

        worker = get_worker().address
    except (ImportError, ValueError):
        worker = LOCAL
    # overwrite: an earlier attempt's files (a failed run, a run cut short) are removed first, so that they do
    # not mix with this one's; the run directory's parent is the sweep's runs/ (never created here: a worker that
    # does not see it has no shared file system with the sweep, which the error then says)
    result = launch(Scenario.model_validate_json(scenario_json), Path(run_dir), console_log=False, overwrite=True)
    return {"summary": result.summary, "error": "" if result.error is None else str(result.error),
            "worker": worker}


def local_jobs(runs: tuple[RunSpec, ...] | list[RunSpec], cores: int | None = None) -> int:
    """Workers for a local sweep: the cores over the most cores one run keeps busy, at least 1."""
    cores = cores or len(os.sched_getaffinity(0))
    need = max((r.cores for r in runs), default=1)
    return max(1, min(len(runs) or 1, cores // need))


@contextlib.contextmanager
def open_client(scheduler: str | None, jobs: int, gl: bool) -> Iterator:
    """A Dask client: on ``scheduler`` when given, else on an embedded LocalCluster of ``jobs`` workers."""
    from distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler, timeout="30s") as client:
            yield client
        return
    import dask

    resources = {EGL: 1} if gl else None
    # no dashboard; Dask's HTTP routes (health, metrics) on a free loopback port, not 0.0.0.0:8787. The cluster's
    # threads are born with SIGINT blocked, and so are the worker processes they start (restarts included) and
    # the runs' children: a Ctrl-C on the terminal reaches this process alone, which stops the sweep
    with dask.config.set(PATIENT_CLUSTER):      # for the client too, as long as it is used
        with dask.config.set(QUIET_CLUSTER), sigint_blocked_in_new_threads():
            cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address=LOOPBACK_ANY_PORT, scheduler_kwargs={"dashboard": False},
                                   worker_dashboard_address=LOOPBACK_ANY_PORT, resources=resources,
                                   silence_logs=logging.ERROR)
        with cluster, Client(cluster) as client:
            yield client


def _check_egl(client, runs: list[RunSpec]) -> None:
    if any(r.needs_gl for r in runs):
        workers = client.scheduler_info().get("workers", {}).values()
        if not any((w.get("resources") or {}).get(EGL) for w in workers):
            raise RuntimeError(f"{sum(r.needs_gl for r in runs)} runs render with GL but no worker of the cluster "
                               f"declares the {EGL} resource: start GL-capable workers with "
                               f"'dask worker SCHEDULER --resources {EGL}=1' (docs/sweeps.md)")


def _progress(total: int, done: int, quiet: bool):
    from tqdm import tqdm

    return tqdm(total=total, initial=done, unit="run", disable=quiet, file=sys.stderr, dynamic_ncols=True,
                desc="sweep")


def run_sweep(sweep: Sweep, out: Path, *, scheduler: str | None = None, jobs: int | None = None,
              quiet: bool = False, retries: int = 1, runner: Callable[[str, str], dict] = execute_run,
              figures: bool = True, parents: bool = True) -> SweepOutcome:
    """Run ``sweep`` into ``out`` (runs/<id>/, results.csv, figures); see the module docstring.

    ``runner(run_dir, scenario_json) -> {"summary", "error", "worker"}`` executes one run on a worker
    (default :func:`execute_run`) and is given the run directory as an absolute path: a worker's working
    directory is its own. ``parents``: create ``out``'s missing parents too (cosim.runtime.rundir). Never raises
    for a run's failure; raises RuntimeError when a GL run has nowhere to go and
    :class:`cosim.runtime.rundir.RunDirError` when ``out`` cannot be made.
    """
    out = Path(out).absolute()
    make_out_dir(out, parents)
    (out / "runs").mkdir(exist_ok=True)
    table = ResultsTable(out, sweep.labels, sweep.parameters, [r.id for r in sweep.runs])
    pending: list[RunSpec] = []
    before = read_table(out)
    for run in sweep.runs:
        summary = read_summary(out / "runs" / run.id)
        if summary is not None and summary.get("completed"):  # finished before: kept as is
            table.set(run, summary=summary, error="", attempts=0, worker=before.get(run.id, {}).get("worker", ""))
        else:
            pending.append(run)
    skipped = len(sweep.runs) - len(pending)
    table.write()
    failed, interrupted = 0, False
    if pending:
        jobs = jobs or local_jobs(pending)
        bar = _progress(len(sweep.runs), skipped, quiet)
        with open_client(scheduler, jobs, any(r.needs_gl for r in pending)) as client:
            failed, interrupted = _drive(client, pending, out, table, bar, retries, runner)
        bar.close()
    if figures:
        from .figures import write_sweep_figures

        write_sweep_figures(out, list(table.rows.values()), sweep.parameters)
    completed = sum(1 for r in table.rows.values() if r["completed"])
    outcomes = Counter(r["outcome"] for r in table.rows.values() if r.get("outcome"))
    return SweepOutcome(len(sweep.runs), completed, failed, skipped, interrupted, out / "results.csv",
                        dict(sorted(outcomes.items())))


def _drive(client, pending: list[RunSpec], out: Path, table: ResultsTable, bar, retries: int,
           runner) -> tuple[int, bool]:
    """Submit the runs, collect them as they finish, retry failures; returns (failed, interrupted)."""
    from distributed import as_completed

    _check_egl(client, pending)
    attempts: dict[str, int] = {}
    by_key: dict[str, RunSpec] = {}

    def submit(run: RunSpec):
        attempts[run.id] = attempts.get(run.id, 0) + 1
        fut = client.submit(runner, str(out / "runs" / run.id), run.scenario.model_dump_json(),
                            key=f"run-{run.id}-{attempts[run.id]}", pure=False,
                            resources={EGL: 1} if run.needs_gl else None)
        by_key[fut.key] = run
        return fut

    futures = [submit(r) for r in pending]
    failed = 0
    queue = as_completed(futures)
    try:
        for fut in queue:
            run = by_key.pop(fut.key)
            try:
                res = fut.result()
            except Exception as exc:  # noqa: BLE001 - the task itself failed (e.g. its worker died): one attempt
                res = {"summary": read_summary(out / "runs" / run.id), "worker": "",
                       "error": f"{type(exc).__name__}: {exc}"}
            ok = bool(res["summary"] and res["summary"].get("completed")) and not res["error"]
            if not ok and attempts[run.id] <= retries:
                log.warning("run %s failed (%s); retrying", run.id, res["error"])
                futures.append(submit(run))
                queue.add(futures[-1])
                continue
            table.set(run, summary=res["summary"], error=res["error"] or ("" if ok else "no summary"),
                      attempts=attempts[run.id], worker=res["worker"])
            table.write()
            failed += not ok
            bar.update(1)
            bar.set_postfix(failed=failed, refresh=False)
    except KeyboardInterrupt:
        client.cancel(futures)  # the queued runs never start; those running end now, as interrupted
        try:
            client.run(request_stop, [str(out / "runs" / r.id) for r in pending], signal.SIGINT, STOP_WAIT_S,
                       wait=True)
        except Exception as exc:  # noqa: BLE001 - a worker that is gone: its runs ended with it
            log.warning("could not stop the runs in progress on every worker: %s", exc)
        return failed, True
    return failed, False
