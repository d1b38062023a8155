"""Launcher and supervisor of one run (docs/architecture.md): set-up, supervision, teardown.

:func:`launch` reads as the run's lifecycle. :func:`_set_up` locks the run directory, writes scenario.yaml and a
"running" summary, creates the segment and starts the observers (spawned), the sinks and one named process per
ring member (forked from a server that has imported their common modules, cosim.runtime.procstart). :func:`_supervise` closes the ring as the supervisor, recording each completed frame and
appending the rows to disk in blocks (cosim.runtime.stream). :func:`_tear_down` ends every process in bounded
time, writes the last rows, the maps and the final summary, and unlinks the segment.

Whatever happens the run ends cleanly: a child's exception comes back with its traceback; a dead child, or one
that stops beating (SIGSTOP, a deadlock: cosim.runtime.liveness), stops the run within 2 s naming the process,
the frame and the cause; a child that beats but does not finish its frame meets the hand-off timeout; any number
of SIGINT/SIGTERM at any moment stop it the same way (cosim.runtime.signals); a write error (a full disk) is
named with its path. Afterwards no child is left running and the segment is unlinked; the run directory holds
everything up to the last completed frame.
"""
from __future__ import annotations

import json
import logging
import multiprocessing as mp
import os
import secrets
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

from cosim.errors import OutputError, RunError, RunInterrupted
from cosim.scenario.config import Scenario
from shm_schema import Phase, Segment
from shm_schema.layout import SLOT_WORD

from .capacity import check_segment_fits
from .child import ChildArgs, child_main
from .daemonic import children_allowed
from .files import RunDirLock, atomic_write, open_run_dir
from .liveness import Watch, child_failure, stop_processes
from .lockstep import RingPlan, Token
from .logs import configure_logging
from .outcome import outcome_line
from .outputs import default_run_dir, finish_outputs, write_figures, write_scenario
from .pipeline import Gates, PipePlan, effective_schedule, supervise
from .procstart import ring_context
from .recorder import Recorder
from .signals import StopSignals, no_sigint_in_children
from .specs import SUPERVISOR, ParticipantSpec, build_schema, ring_specs
from .stream import RunFiles, write_running_summary
from .threadpools import single_threaded_pools

__all__ = ["RunResult", "ObserverSpec", "launch", "EXIT_OK", "EXIT_RUN_ERROR", "EXIT_INTERRUPTED", "JOIN_TIMEOUT_S"]

log = logging.getLogger("cosim.runtime.launcher")

EXIT_OK, EXIT_RUN_ERROR, EXIT_INTERRUPTED = 0, 1, 130
#: how long a child may take to close after the last frame (GL teardown) before it is terminated, s
JOIN_TIMEOUT_S = 10.0
#: how long a terminated child gets before SIGKILL, s
TERMINATE_GRACE_S = 0.5

Progress = Callable[[int, int, float, float], None]


@dataclass(frozen=True)
class ObserverSpec:
    """A process outside the ring that attaches read-only by segment name (a viewer).

    ``target`` is an import path ``"package.module:function"`` called as ``function(segment_name, **kwargs)``
    in a spawned process. It never takes part in the lockstep; if it dies the run logs a warning and goes on;
    it is terminated when the run ends.
    """

    name: str
    target: str
    kwargs: Mapping = field(default_factory=dict)


#: a per-frame sink, called by the supervisor after each completed frame as ``sink(segment, frame)``; created by
#: ``factory(scenario, run_dir, segment) -> sink`` with an optional ``close()``. Sinks run inside the ring turn
#: (they see every frame, consistently) so they must be cheap; a sink's exception ends the run. A block may hold
#: an earlier frame than the call's (a deferred member publishes one turn late): ``segment.frame_of(block)``
#: says which; when a member defers, one more call with frame = last frame + 1 follows the flush turn.
SinkFactory = Callable[..., Callable]


@dataclass
class RunResult:
    """What a run produced. ``exit_code`` is the process exit status the CLI returns."""

    run_dir: Path
    summary: dict
    error: RunError | None = None
    segment_name: str = ""
    exit_code: int = EXIT_OK
    children: dict[str, int | None] = field(default_factory=dict)
    #: last completed frame's copy of every recorded (non-image) array block (a block larger than
    #: cosim.runtime.recorder.FRAME_COPY_LIMIT that a writer touched after that frame is left out: zeros)
    arrays: dict = field(default_factory=dict)

    @property
    def completed(self) -> bool:
        return bool(self.summary.get("completed"))


@dataclass
class _Run:
    """One run's state: what set-up made, what supervision and teardown use. Teardown copes with any prefix of
    set-up having happened (a stop or a failure can come at any step)."""

    scenario: Scenario
    run_dir: Path
    lock: RunDirLock
    stop: StopSignals
    t_enter: float
    log_path: Path = Path()
    ring: list = field(default_factory=list)
    schema: object = None
    plan: RingPlan | PipePlan | None = None
    schedule_why: str = ""
    name: str = ""
    sems: dict = field(default_factory=dict)
    seg: Segment | None = None
    procs: dict[str, mp.process.BaseProcess] = field(default_factory=dict)
    watchers: dict[str, mp.process.BaseProcess] = field(default_factory=dict)
    frame_sinks: list = field(default_factory=list)
    recorder: Recorder | None = None
    files: RunFiles | None = None
    t_start: float = 0.0
    t_first: float = 0.0

    @property
    def frame(self) -> int:
        """The supervisor's last completed frame (-1 before frame 0)."""
        return int(self.seg.slot(SUPERVISOR)["frame"]) if self.seg is not None else -1


def launch(scenario: Scenario, out_dir: Path | None = None, *,
           specs: Mapping[str, ParticipantSpec] | None = None, progress: Progress | None = None,
           console_log: bool = True, observers: Sequence[ObserverSpec] = (),
           sinks: Sequence[SinkFactory] = ()) -> RunResult:
    """Run ``scenario`` over OS processes and write its run directory. Never raises for run failures.

    ``observers`` are started after the segment exists and stopped at the end; ``sinks`` are called with each
    completed frame (see :data:`SinkFactory`). The run directory's ``run.json`` names the segment while the run
    lives, so that ``python -m cosim.viewer --attach RUN_DIR`` can find it. Raises
    :class:`cosim.runtime.files.RunDirError` before anything starts when the run directory cannot be used (not a
    directory, not writable, another run writing there), and :class:`cosim.errors.RunRefused` when its shared
    memory would not fit (cosim.runtime.capacity).
    """
    t_enter = time.perf_counter()
    stop = StopSignals().install()
    try:
        ring = ring_specs(scenario, specs)
        schema = build_schema(scenario, ring)
        check_segment_fits(schema)
        run_dir = Path(out_dir) if out_dir is not None else default_run_dir(scenario)
        run = _Run(scenario, run_dir, open_run_dir(run_dir), stop, t_enter, ring=ring, schema=schema)
        try:
            error: RunError | None = None
            try:
                _set_up(run, console_log, observers, sinks)
                _supervise(run, progress)
            except RunError as exc:
                error = exc
            except BaseException as exc:  # noqa: BLE001 - a supervisor bug still ends the run cleanly
                error = RunError(f"supervisor failed: {type(exc).__name__}: {exc}", process=SUPERVISOR,
                                 frame=run.frame)
                log.exception("supervisor failure")
            return _tear_down(run, error)
        finally:
            run.lock.release()
    finally:
        stop.restore()


def _set_up(run: _Run, console_log: bool, observers: Sequence[ObserverSpec],
            sinks: Sequence[SinkFactory]) -> None:
    """Logging, scenario.yaml, the "running" summary, the segment, then observers, sinks and ring children.
    A stop signal is honoured between any two steps."""
    scenario, stop = run.scenario, run.stop
    run.log_path = run.run_dir / "log.txt"
    configure_logging(str(run.log_path), console=console_log)
    write_scenario(run.run_dir, scenario)
    schema = run.schema
    run.plan, run.schedule_why = _plan(scenario, run.ring, hold=bool(sinks))
    plan = run.plan
    run.name = name = f"cosim-{os.getpid()}-{secrets.token_hex(3)}"
    write_running_summary(run.run_dir, {"scenario": scenario.name, "participants": list(plan.members),
                                        "seed": scenario.seed, "frames_planned": scenario.frames + 1,
                                        "launcher_pid": os.getpid()})
    stop.check(-1)
    ctx, ring_ctx = mp.get_context("spawn"), ring_context()       # observers spawned, ring members forked
    pipelined = isinstance(plan, PipePlan)
    run.sems = {n: ring_ctx.Semaphore(0) for n in (plan.semaphore_names if pipelined else (*plan.members, SUPERVISOR))}
    run.seg = seg = Segment.create(name, schema, run_id=run.run_dir.name, frames=scenario.frames)
    run.t_start = run.t_first = time.perf_counter()
    log.info("run %s: segment %s (%d bytes, fingerprint %s), ring %s, %d frames, %s schedule (%s)", run.run_dir.name,
             name, schema.total_nbytes, schema.fingerprint[:12], " -> ".join(plan.members), scenario.frames + 1,
             "pipelined" if pipelined else "sequential", run.schedule_why)
    _write_run_json(run.run_dir, {"segment": name, "launcher_pid": os.getpid(), "fingerprint": schema.fingerprint,
                                  "participants": list(plan.members), "ended": False})
    seg.slot(SUPERVISOR)["pid"] = os.getpid()
    for obs in observers:
        stop.check(-1)
        w = ctx.Process(target=_observer_main, args=(obs, name, str(run.log_path)), name=f"cosim-{obs.name}",
                        daemon=True)
        with single_threaded_pools(), no_sigint_in_children(), children_allowed():
            w.start()
        run.watchers[obs.name] = w
    for make_sink in sinks:
        stop.check(-1)
        with no_sigint_in_children(), children_allowed():
            run.frame_sinks.append(make_sink(scenario, run.run_dir, seg))
    scenario_json = scenario.model_dump_json()
    for spec in run.ring:
        stop.check(-1)
        args = ChildArgs(spec, scenario_json, name, schema.fingerprint, plan, run.sems, str(run.log_path),
                         os.getpid(), scenario.timing.startup_timeout_s, scenario.timing.handoff_timeout_s + 5.0,
                         time.time())
        p = ring_ctx.Process(target=child_main, args=(args,), name=f"cosim-{spec.name}", daemon=True)
        with single_threaded_pools(), no_sigint_in_children(), children_allowed():
            p.start()
        run.procs[spec.name] = p
    run.recorder = Recorder(seg, plan.members, deferred=bool(plan.deferred) or pipelined,
                            schedule="pipelined" if pipelined else "sequential")
    # the token ring records a deferred member's row one turn late; the pipelined one records whole frames
    run.files = RunFiles(run.run_dir, run.recorder, lag=1 if plan.deferred and not pipelined else 0)


def _plan(scenario: Scenario, ring: list[ParticipantSpec], *, hold: bool) -> tuple[RingPlan | PipePlan, str]:
    """(plan, why) of the run's schedule (cosim.runtime.pipeline.effective_schedule): a token ring or a pipeline
    plan; ``hold``: sinks read the segment at each completed frame, so the pipeline keeps it until they have."""
    deferred = tuple(s.name for s in ring if s.defers_outputs(scenario))
    reads = {s.name: s.reads_of(scenario) for s in ring}
    schedule, why = effective_schedule(scenario, reads)
    if schedule == "pipelined":
        return PipePlan.build(reads, scenario.frames, supervisor=SUPERVISOR, deferred=deferred, hold=hold), why
    return RingPlan(tuple(s.name for s in ring), scenario.frames, SUPERVISOR, deferred), why


def _supervise(run: _Run, progress: Progress | None) -> None:
    """Close the ring for every frame (and the flush turn): record, feed the sinks, append rows, report progress.

    Between wait slices it checks, in this order: a stop signal, a child that stopped beating or is stopped
    (named within ~1.5 s, cosim.runtime.liveness), a child that exited. Raises the RunError that ends the run."""
    scenario, seg, plan, recorder, stop = run.scenario, run.seg, run.plan, run.recorder, run.stop
    sup = seg.slot(SUPERVISOR)
    watch = Watch(seg, run.procs)
    finished: set[str] = set()
    warned: set[str] = set()

    def check() -> None:
        stop.check(int(sup["frame"]))
        watch.check()
        for n, p in run.procs.items():
            if p.exitcode is None or n in finished:
                continue
            if p.exitcode == 0 and int(seg.slot(n)["phase"]) in (Phase.DONE, Phase.CLOSED):
                finished.add(n)
                continue
            raise child_failure(n, p, seg)

    if isinstance(plan, PipePlan):
        _supervise_pipelined(run, progress, check)
        return
    token = Token(seg, run.sems)
    first = plan.members[0]
    t_turn = time.monotonic_ns()
    token.give(first, 0)
    sw = seg.slot_words(SUPERVISOR)
    phase, frame_word, heartbeat = SLOT_WORD["phase"], SLOT_WORD["frame"], SLOT_WORD["heartbeat_ns"]
    for frame in range(plan.frames + 1):
        sw[phase] = Phase.WAITING
        timeout = scenario.timing.handoff_timeout_s
        if frame == 0:
            timeout += scenario.timing.startup_timeout_s
        token.take(SUPERVISOR, frame, timeout, check)
        turn = time.monotonic_ns() - t_turn
        if frame == 0:
            run.t_first = time.perf_counter()
        sw[frame_word] = frame
        sw[phase] = Phase.STEPPING
        recorder.record(frame, turn if frame > 0 else None)
        for sink in run.frame_sinks:
            sink(seg, frame)
        stop.check(frame)
        sw[heartbeat] = time.monotonic_ns()
        if frame < plan.frames:
            t_turn = time.monotonic_ns()
            token.give(first, frame + 1)
        # what does not read the blocks runs while the next frame does
        run.files.maybe_append()
        _warn_dead_observers(run.watchers, warned)
        if progress is not None:
            progress(frame, plan.frames, frame * scenario.timing.sensor_period_s, time.perf_counter() - run.t_start)
    if plan.flush_frame is not None:
        # the deferred members publish their last frame's outputs
        sw[phase] = Phase.WAITING
        token.give(plan.flush_next_of(SUPERVISOR), plan.flush_frame)
        token.take(SUPERVISOR, plan.flush_frame, scenario.timing.handoff_timeout_s, check)
        sw[phase] = Phase.STEPPING
        recorder.record_flush()
        for sink in run.frame_sinks:
            sink(seg, plan.flush_frame)
    sup["phase"] = Phase.DONE


def _supervise_pipelined(run: _Run, progress: Progress | None, check: Callable[[], None]) -> None:
    """:func:`_supervise` under the pipelined schedule: each member's blocks recorded as soon as it has published
    a frame (cosim.runtime.pipeline.supervise), the frame's rows, sinks, files and progress once all have."""
    scenario, seg, plan, recorder, stop = run.scenario, run.seg, run.plan, run.recorder, run.stop
    warned: set[str] = set()

    def on_frame(frame: int, turn_ns: int) -> None:
        if frame == 0:
            run.t_first = time.perf_counter()
        recorder.complete(frame, turn_ns if frame > 0 else None)
        for sink in run.frame_sinks:
            sink(seg, frame)
        stop.check(frame)
        run.files.maybe_append()
        _warn_dead_observers(run.watchers, warned)
        if progress is not None:
            progress(frame, plan.frames, frame * scenario.timing.sensor_period_s, time.perf_counter() - run.t_start)

    supervise(seg, plan, Gates(seg, plan, run.sems, SUPERVISOR, check),
              startup_timeout_s=scenario.timing.startup_timeout_s, handoff_timeout_s=scenario.timing.handoff_timeout_s,
              on_take=recorder.take, on_frame=on_frame)


def _tear_down(run: _Run, error: RunError | None) -> RunResult:
    """End every process (bounded), write the last rows, maps and the final summary, unlink the segment, draw the
    figures. Signals meanwhile are only counted (a first one cuts the figures short); the exit status is 130
    whenever a stop signal came."""
    t_down = time.perf_counter()
    wall = t_down - run.t_start if run.t_start else 0.0
    for sink in run.frame_sinks:
        close = getattr(sink, "close", None)
        if close is not None:
            try:
                close()
            except Exception:  # noqa: BLE001 - a sink's close must not hide the run's outcome
                log.exception("closing a frame sink failed")
    stop_processes(run.procs, graceful=error is None, join_timeout_s=JOIN_TIMEOUT_S, grace_s=TERMINATE_GRACE_S)
    stop_processes(run.watchers, graceful=False, join_timeout_s=JOIN_TIMEOUT_S, grace_s=TERMINATE_GRACE_S)
    if run.recorder is not None:
        run.recorder.finish()
    t_stopped = time.perf_counter()
    if error is None and run.stop.signum is not None:
        error = run.stop.error(run.frame)
    if error is not None:
        log.error("run failed: %s", error)
        if error.detail:
            log.error("traceback of %s:\n%s", error.process, error.detail)
    try:
        summary, failure = finish_outputs(run.run_dir, run.scenario, run.recorder, run.ring, wall_time_s=wall,
                                          error=error, files=run.files)
    finally:
        if run.seg is not None:
            run.seg.close()
            run.seg.unlink()
            _end_run_json(run.run_dir)
    if failure is not None:
        log.error("%s", failure)
        error = error or failure
    log.info("%s", outcome_line(summary.get("outcome")))
    t_outputs = time.perf_counter()
    if run.schema is not None and failure is None:
        _write_figures(run, summary)
    code = _exit_code(error, run.stop)
    t_end = time.perf_counter()
    log.info("run %s %s in %.2f s (exit %d); start-up %.2f s to the first frame (set-up before spawning %.2f s), "
             "shut-down %.2f s (children %.2f s, outputs %.2f s, figures %.2f s); launcher cpu %.2f s",
             run.run_dir.name, "completed" if error is None else "stopped", wall, code, run.t_first - run.t_enter,
             run.t_start - run.t_enter if run.t_start else 0.0, t_end - t_down, t_stopped - t_down,
             t_outputs - t_stopped, t_end - t_outputs, time.process_time())
    return RunResult(run.run_dir, summary, error, run.name, code, {n: p.exitcode for n, p in run.procs.items()},
                     dict(run.recorder.arrays) if run.recorder is not None else {})


def _write_figures(run: _Run, summary: dict) -> None:
    """The run's figures; a stop signal cuts them short (the run's data is already written)."""
    if run.stop.signum is not None:
        log.warning("figures not written: stopped by %s", run.stop.name)
        return
    try:
        with run.stop.raising():
            write_figures(run.run_dir, run.scenario, summary, run.recorder)
    except RunInterrupted:
        log.warning("figures not written: stopped by %s", run.stop.name)


def _exit_code(error: RunError | None, stop: StopSignals) -> int:
    if stop.signum is not None or isinstance(error, RunInterrupted):
        return EXIT_INTERRUPTED
    return EXIT_OK if error is None else EXIT_RUN_ERROR


def _write_run_json(run_dir: Path, info: dict) -> None:
    atomic_write(run_dir / "run.json", json.dumps(info, indent=2) + "\n")


def _end_run_json(run_dir: Path) -> None:
    """Mark run.json ended (the segment is gone); a write error here is only logged."""
    try:
        info = json.loads((run_dir / "run.json").read_text())
        info["ended"] = True
        _write_run_json(run_dir, info)
    except (OSError, ValueError, OutputError) as exc:
        log.warning("could not mark run.json ended: %s", exc)


def _observer_main(obs: ObserverSpec, segment: str, log_path: str) -> None:
    """Entry of an observer process: log to the run's log, ignore Ctrl-C (the launcher stops it)."""
    from .specs import load_callable

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    configure_logging(log_path, console=False)
    load_callable(obs.target)(segment, **dict(obs.kwargs))


def _warn_dead_observers(watchers: Mapping[str, mp.process.BaseProcess], warned: set[str]) -> None:
    """Log once per observer that has ended; the run goes on."""
    for n, w in watchers.items():
        if w.exitcode is not None and n not in warned:
            warned.add(n)
            log.warning("observer %s ended (exit %s); the run goes on without it", n, w.exitcode)
