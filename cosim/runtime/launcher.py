"""Launcher and supervisor of one run (issue 2, DESIGN.md sections 1, 2, 6, 7).

It creates the run's segment, spawns one named process per ring member (spawn context), closes the ring itself
as the supervisor (recording each completed frame), and ends the run cleanly whatever happens: a child's
exception comes back with its traceback, a dead child or a hand-off timeout stops the run well within 2 s
naming the process, the frame and the cause, SIGINT/SIGTERM stop it the same way. Afterwards no child is left
running and the segment is unlinked; the run directory holds everything up to the last completed frame.
"""
from __future__ import annotations

import json
import logging
import multiprocessing as mp
import os
import secrets
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

from shm_schema import Phase, Segment
from shm_schema.layout import SLOT_WORD

from .child import ChildArgs, child_main
from cosim.scenario.config import Scenario
from cosim.errors import ParticipantCrashed, ParticipantDied, RunError, RunInterrupted
from .lockstep import RingPlan, Token
from .logs import configure_logging
from .outputs import default_run_dir, write_figures, write_outputs, write_scenario
from .recorder import Recorder
from .specs import SUPERVISOR, ParticipantSpec, build_schema, ring_specs
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


class _StopFlag:
    """Set by SIGINT/SIGTERM handlers; checked between wait slices."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __call__(self, signum, frame) -> None:
        self.signum = signum


def _install_signals(flag: _StopFlag) -> dict:
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {s: signal.signal(s, flag) for s in (signal.SIGINT, signal.SIGTERM)}


def _child_failure(name: str, proc, seg: Segment) -> RunError:
    err = seg.read_error(name)
    slot = seg.slot(name)
    frame = int(slot["frame"])
    if err:
        return ParticipantCrashed(
            f"{name} raised {err['type']} at frame {err['frame']}: {err['message']}",
            process=name, frame=int(err["frame"]), detail=err.get("traceback", ""))
    code = proc.exitcode
    how = f"signal {signal.Signals(-code).name}" if code is not None and code < 0 else f"exit status {code}"
    phase = Phase.NAMES[int(slot["phase"])] if 0 <= int(slot["phase"]) < len(Phase.NAMES) else "?"
    return ParticipantDied(f"{name} (pid {proc.pid}) died with {how} during frame {frame} (phase {phase})",
                           process=name, frame=frame)


def launch(scenario: Scenario, out_dir: Path | None = None, *,
           specs: Mapping[str, ParticipantSpec] | None = None, progress: Progress | None = None,
           console_log: bool = True, observers: Sequence[ObserverSpec] = (),
           sinks: Sequence[SinkFactory] = ()) -> RunResult:
    """Run ``scenario`` over OS processes and write its run directory. Never raises for run failures.

    ``observers`` are started after the segment exists and stopped at the end; ``sinks`` are called with each
    completed frame (see :data:`SinkFactory`). The run directory's ``run.json`` names the segment while the run
    lives, so that ``python -m cosim.viewer --attach RUN_DIR`` can find it.
    """
    t_enter = time.perf_counter()
    run_dir = Path(out_dir) if out_dir is not None else default_run_dir(scenario)
    run_dir.mkdir(parents=True, exist_ok=True)
    log_path = run_dir / "log.txt"
    configure_logging(str(log_path), console=console_log)
    write_scenario(run_dir, scenario)
    ring = ring_specs(scenario, specs)
    schema = build_schema(scenario, ring)
    plan = RingPlan(tuple(s.name for s in ring), scenario.frames, SUPERVISOR,
                    tuple(s.name for s in ring if s.defers_outputs(scenario)))
    name = f"cosim-{os.getpid()}-{secrets.token_hex(3)}"
    ctx = mp.get_context("spawn")
    sems = {n: ctx.Semaphore(0) for n in (*plan.members, SUPERVISOR)}
    flag = _StopFlag()
    old_handlers = _install_signals(flag)
    seg = Segment.create(name, schema, run_id=run_dir.name, frames=scenario.frames)
    procs: dict[str, mp.process.BaseProcess] = {}
    recorder: Recorder | None = None
    error: RunError | None = None
    t_start = t_first = time.perf_counter()
    log.info("run %s: segment %s (%d bytes, fingerprint %s), ring %s, %d frames", run_dir.name, name,
             schema.total_nbytes, schema.fingerprint[:12], " -> ".join(plan.members), scenario.frames + 1)
    (run_dir / "run.json").write_text(json.dumps({"segment": name, "launcher_pid": os.getpid(),
                                                   "fingerprint": schema.fingerprint,
                                                   "participants": list(plan.members), "ended": False},
                                                  indent=2) + "\n")
    watchers: dict[str, mp.process.BaseProcess] = {}
    warned: set[str] = set()
    frame_sinks: list = []
    try:
        sup = seg.slot(SUPERVISOR)
        sup["pid"] = os.getpid()
        for obs in observers:
            w = ctx.Process(target=_observer_main, args=(obs, name, str(log_path)), name=f"cosim-{obs.name}",
                            daemon=True)
            with single_threaded_pools():
                w.start()
            watchers[obs.name] = w
        for make_sink in sinks:
            frame_sinks.append(make_sink(scenario, run_dir, seg))
        scenario_json = scenario.model_dump_json()
        for spec in ring:
            args = ChildArgs(spec, scenario_json, name, schema.fingerprint, plan, sems, str(log_path), os.getpid(),
                             scenario.timing.startup_timeout_s, scenario.timing.handoff_timeout_s + 5.0, time.time())
            p = ctx.Process(target=child_main, args=(args,), name=f"cosim-{spec.name}", daemon=True)
            with single_threaded_pools():
                p.start()
            procs[spec.name] = p
        recorder = Recorder(seg, plan.members, deferred=bool(plan.deferred))
        finished: set[str] = set()

        def check_stop() -> None:
            if flag.signum is not None:
                raise RunInterrupted(f"stopped by {signal.Signals(flag.signum).name} at frame {int(sup['frame'])}",
                                     process=SUPERVISOR, frame=int(sup["frame"]))

        def check() -> None:
            check_stop()
            for n, p in procs.items():
                if p.exitcode is None or n in finished:
                    continue
                if p.exitcode == 0 and int(seg.slot(n)["phase"]) in (Phase.DONE, Phase.CLOSED):
                    finished.add(n)
                    continue
                raise _child_failure(n, p, seg)

        token = Token(seg, sems)
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
                t_first = time.perf_counter()
            sw[frame_word] = frame
            sw[phase] = Phase.STEPPING
            recorder.record(frame, turn if frame > 0 else None)
            for sink in frame_sinks:
                sink(seg, frame)
            check_stop()
            sw[heartbeat] = time.monotonic_ns()
            if frame < plan.frames:
                t_turn = time.monotonic_ns()
                token.give(first, frame + 1)
            # what does not read the blocks runs while the next frame does
            _warn_dead_observers(watchers, warned)
            if progress is not None:
                progress(frame, plan.frames, frame * scenario.timing.sensor_period_s, time.perf_counter() - t_start)
        if plan.flush_frame is not None:
            # the deferred members publish their last frame's outputs
            sw[phase] = Phase.WAITING
            token.give(plan.flush_next_of(SUPERVISOR), plan.flush_frame)
            token.take(SUPERVISOR, plan.flush_frame, scenario.timing.handoff_timeout_s, check)
            sw[phase] = Phase.STEPPING
            recorder.record_flush()
            for sink in frame_sinks:
                sink(seg, plan.flush_frame)
        sup["phase"] = Phase.DONE
    except RunError as exc:
        error = exc
    except BaseException as exc:  # noqa: BLE001 - a supervisor bug still ends the run cleanly
        error = RunError(f"supervisor failed: {type(exc).__name__}: {exc}", process=SUPERVISOR,
                         frame=int(seg.slot(SUPERVISOR)["frame"]))
        log.exception("supervisor failure")
    finally:
        wall = time.perf_counter() - t_start
        for sink in frame_sinks:
            close = getattr(sink, "close", None)
            if close is not None:
                try:
                    close()
                except Exception:  # noqa: BLE001 - a sink's close must not hide the run's outcome
                    log.exception("closing a frame sink failed")
        _stop_children(procs, graceful=error is None)
        _stop_children(watchers, graceful=False)
        if recorder is not None:
            recorder.finish()
        for s, h in old_handlers.items():
            signal.signal(s, h)
        t_stopped = time.perf_counter()
    if error is not None:
        log.error("run failed: %s", error)
        if error.detail:
            log.error("traceback of %s:\n%s", error.process, error.detail)
    try:
        summary = write_outputs(run_dir, scenario, recorder, ring, wall_time_s=wall, error=error)
    finally:
        seg.close()
        seg.unlink()
        info = json.loads((run_dir / "run.json").read_text())
        info["ended"] = True
        (run_dir / "run.json").write_text(json.dumps(info, indent=2) + "\n")
    t_outputs = time.perf_counter()
    write_figures(run_dir, scenario, summary, recorder)
    code = EXIT_OK if error is None else EXIT_INTERRUPTED if isinstance(error, RunInterrupted) else EXIT_RUN_ERROR
    t_end = time.perf_counter()
    log.info("run %s %s in %.2f s (exit %d); start-up %.2f s to the first frame (set-up before spawning %.2f s), "
             "shut-down %.2f s (children %.2f s, outputs %.2f s, figures %.2f s); launcher cpu %.2f s", run_dir.name,
             "completed" if error is None else "stopped", wall, code, t_first - t_enter, t_start - t_enter,
             t_end - t_start - wall, t_stopped - t_start - wall, t_outputs - t_stopped, t_end - t_outputs,
             time.process_time())
    return RunResult(run_dir, summary, error, name, code, {n: p.exitcode for n, p in procs.items()},
                     dict(recorder.arrays) if recorder is not None else {})


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


def _stop_children(procs: Mapping[str, mp.process.BaseProcess], *, graceful: bool) -> None:
    """Join children after a clean finish; otherwise terminate, then kill whatever is left. Never leaves one."""
    if graceful:
        deadline = time.monotonic() + JOIN_TIMEOUT_S
        for p in procs.values():
            p.join(max(0.0, deadline - time.monotonic()))
    alive = [p for p in procs.values() if p.is_alive()]
    for p in alive:
        p.terminate()
    deadline = time.monotonic() + TERMINATE_GRACE_S
    for p in alive:
        p.join(max(0.0, deadline - time.monotonic()))
    for p in procs.values():
        if p.is_alive():
            log.warning("%s (pid %s) ignored SIGTERM; killing it", p.name, p.pid)
            p.kill()
            p.join(1.0)
