"""Launcher and supervisor of one run (docs/architecture.md): set-up, supervision, teardown.

:func:`launch` reads as the run's lifecycle. It claims and locks the run directory (cosim.runtime.rundir);
:func:`_set_up` writes a "running" summary and scenario.yaml, creates the segment and starts the observers
(spawned), the sinks and one named process per ring member (forked from a server that has imported their common
modules, cosim.runtime.procstart; both started by cosim.runtime.spawning). :func:`_supervise` closes the ring as
the supervisor, recording each completed frame and appending the rows to disk in blocks (cosim.runtime.stream).
:func:`cosim.runtime.teardown.tear_down` ends every process in bounded time, writes the last rows, the maps and
the final summary, unlinks the segment and draws the figures of a completed run. The three share one
:class:`cosim.runtime.runstate.RunState`.

Whatever happens the run ends cleanly: a child's exception comes back with its traceback; a dead child, or one
that makes no progress (SIGSTOP, a deadlock, a wait that never ends: cosim.runtime.liveness), stops the run within
2 s naming the process, the frame and the cause; a child that spends more than its CPU budget on one frame is a
runaway; a child that is only slow (a busy machine) is waited for; any number
of SIGINT/SIGTERM at any moment stop it the same way (cosim.runtime.signals); a write error (a full disk) is
named with its path. Afterwards no child is left running and the segment is unlinked; the run directory holds
everything up to the last completed frame. The launcher is back within 2 s of any fault (docs/reliability.md).
"""
from __future__ import annotations

import logging
import multiprocessing as mp
import os
import secrets
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

from cosim.errors import RunError
from cosim.scenario.config import Scenario
from shm_schema import Phase, Segment
from shm_schema.layout import SLOT_WORD

from .capacity import check_segment_fits
from .child import ChildArgs, child_main
from .daemonic import children_allowed
from .liveness import Watch, child_failure
from .lockstep import RingPlan, Token
from .logs import configure_logging
from .outputs import default_run_dir, write_scenario
from .pipeline import Gates, PipePlan, effective_schedule, supervise
from .procstart import ring_context
from .recorder import Recorder
from .rundir import open_run_dir
from .runstate import RunState
from .signals import StopSignals, no_sigint_in_children
from .spawning import start_process
from .specs import SUPERVISOR, ParticipantSpec, build_schema, ring_specs
from .stream import RunFiles, write_running_summary
from .teardown import EXIT_INTERRUPTED, EXIT_OK, EXIT_RUN_ERROR, JOIN_TIMEOUT_S, at_fault, tear_down, write_run_json

__all__ = ["RunResult", "ObserverSpec", "launch", "EXIT_OK", "EXIT_RUN_ERROR", "EXIT_INTERRUPTED", "JOIN_TIMEOUT_S"]

log = logging.getLogger("cosim.runtime.launcher")

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


def launch(scenario: Scenario, out_dir: Path | None = None, *,
           specs: Mapping[str, ParticipantSpec] | None = None, progress: Progress | None = None,
           console_log: bool = True, observers: Sequence[ObserverSpec] = (),
           sinks: Sequence[SinkFactory] = (), overwrite: bool = False, parents: bool = False) -> RunResult:
    """Run ``scenario`` over OS processes and write its run directory. Never raises for run failures.

    ``observers`` are started after the segment exists and stopped at the end; ``sinks`` are called with each
    completed frame (see :data:`SinkFactory`). The run directory's ``run.json`` names the segment while the run
    lives, so that ``python -m cosim.viewer --attach RUN_DIR`` can find it. ``overwrite``: replace the files of
    an earlier run in ``out_dir`` (refused without); ``parents``: create ``out_dir``'s missing parents too (the
    default run directory always). Raises :class:`cosim.runtime.rundir.RunDirError` before anything starts when
    the run directory cannot be used (cosim.runtime.rundir), and :class:`cosim.errors.RunRefused` when its
    shared memory would not fit (cosim.runtime.capacity).
    """
    t_enter = time.perf_counter()
    stop = StopSignals().install()
    try:
        ring = ring_specs(scenario, specs)
        schema = build_schema(scenario, ring)
        check_segment_fits(schema)
        run_dir = Path(out_dir) if out_dir is not None else default_run_dir(scenario)
        lock = open_run_dir(run_dir, overwrite=overwrite, parents=parents or out_dir is None)
        stop.register(run_dir)
        run = RunState(scenario, run_dir, lock, stop, t_enter, ring=ring, schema=schema)
        try:
            error: RunError | None = None
            try:
                _set_up(run, console_log, observers, sinks)
                _supervise(run, progress)
            except RunError as exc:
                error = at_fault(run, exc)
            except BaseException as exc:  # noqa: BLE001 - a supervisor bug still ends the run cleanly
                error = RunError(f"supervisor failed: {type(exc).__name__}: {exc}", process=SUPERVISOR,
                                 frame=run.frame)
                log.exception("supervisor failure")
            summary, error, code = tear_down(run, error)
            return RunResult(run.run_dir, summary, error, run.name, code, {n: p.exitcode for n, p in run.procs.items()},
                             dict(run.recorder.arrays) if run.recorder is not None else {})
        finally:
            run.lock.release()
    finally:
        stop.restore()


def _set_up(run: RunState, console_log: bool, observers: Sequence[ObserverSpec],
            sinks: Sequence[SinkFactory]) -> None:
    """The "running" summary (first: it marks the directory as a run's, cosim.runtime.rundir), logging,
    scenario.yaml, the segment, then observers, sinks and ring children. A stop signal is honoured between any
    two steps."""
    scenario, stop = run.scenario, run.stop
    schema = run.schema
    run.plan, run.schedule_why = _plan(scenario, run.ring, hold=bool(sinks))
    plan = run.plan
    write_running_summary(run.run_dir, {"scenario": scenario.name, "participants": list(plan.members),
                                        "seed": scenario.seed, "frames_planned": scenario.frames + 1,
                                        "launcher_pid": os.getpid()})
    run.log_path = run.run_dir / "log.txt"
    configure_logging(str(run.log_path), console=console_log)
    write_scenario(run.run_dir, scenario)
    run.name = name = f"cosim-{os.getpid()}-{secrets.token_hex(3)}"
    stop.check(-1)
    ring_ctx = ring_context()  # ring members forked from the fork server (observers are spawned)
    pipelined = isinstance(plan, PipePlan)
    run.sems = {n: ring_ctx.Semaphore(0) for n in (plan.semaphore_names if pipelined else (*plan.members, SUPERVISOR))}
    run.seg = seg = Segment.create(name, schema, run_id=run.run_dir.name, frames=scenario.frames)
    run.t_start = run.t_first = time.perf_counter()
    log.info("run %s: segment %s (%d bytes, fingerprint %s), ring %s, %d frames, %s schedule (%s)", run.run_dir.name,
             name, schema.total_nbytes, schema.fingerprint[:12], " -> ".join(plan.members), scenario.frames + 1,
             "pipelined" if pipelined else "sequential", run.schedule_why)
    write_run_json(run.run_dir, {"segment": name, "launcher_pid": os.getpid(), "fingerprint": schema.fingerprint,
                                  "participants": list(plan.members), "ended": False})
    seg.slot(SUPERVISOR)["pid"] = os.getpid()
    for obs in observers:
        stop.check(-1)
        run.watchers[obs.name] = start_process(_observer_main, (obs, name, str(run.log_path)),
                                               name=f"cosim-{obs.name}")
    for make_sink in sinks:
        stop.check(-1)
        with no_sigint_in_children(), children_allowed():  # a sink of the user's may start a process its own way
            run.frame_sinks.append(make_sink(scenario, run.run_dir, seg))
    scenario_json = scenario.model_dump_json()
    for spec in run.ring:
        stop.check(-1)
        args = ChildArgs(spec, scenario_json, name, schema.fingerprint, plan, run.sems, str(run.log_path),
                         os.getpid(), time.time())
        run.procs[spec.name] = start_process(child_main, (args,), name=f"cosim-{spec.name}", ctx=ring_ctx)
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


def _supervise(run: RunState, progress: Progress | None) -> None:
    """Close the ring for every frame (and the flush turn): record, feed the sinks, append rows, report progress.

    Between wait slices it checks, in this order: a stop signal, a child stopped, blocked or running away (the
    evidence of progress, cosim.runtime.liveness: named within ~1.5 s on a quiet machine), a child that exited.
    Raises the RunError that ends the run."""
    scenario, seg, plan, recorder, stop = run.scenario, run.seg, run.plan, run.recorder, run.stop
    sup = seg.slot(SUPERVISOR)
    watch = Watch(seg, run.procs, frame_cpu_s=scenario.timing.handoff_timeout_s,
                  startup_cpu_s=scenario.timing.startup_timeout_s, report=log.info)
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
        token.take(SUPERVISOR, frame, None, check)  # no deadline: the watch in ``check`` judges progress
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
        token.take(SUPERVISOR, plan.flush_frame, None, check)
        sw[phase] = Phase.STEPPING
        recorder.record_flush()
        for sink in run.frame_sinks:
            sink(seg, plan.flush_frame)
    sup["phase"] = Phase.DONE


def _supervise_pipelined(run: RunState, progress: Progress | None, check: Callable[[], None]) -> None:
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

    supervise(seg, plan, Gates(seg, plan, run.sems, SUPERVISOR, check), startup_timeout_s=None, handoff_timeout_s=None,
              on_take=recorder.take, on_frame=on_frame)


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
