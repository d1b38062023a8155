"""The Python API: drive a run step by step from a notebook or a script (docs/api.md).

``Simulation(scenario, **options)`` sets up a run with the same participants as ``python launch.py run`` over the
in-process transport (:class:`cosim.runtime.inprocess.InProcessSession`: one process, no shared memory, nothing
spawned, so it works inside Dask workers and multiprocessing pool workers). ``reset`` runs frame 0, ``step``
the next frames; ``state`` holds the current frame's values keyed like timeseries.csv; ``set`` changes a
run-time input from the next frame on (a participant that takes inputs lists their paths in ``settable`` and
has ``set_input(path, value)``; today dynamics: :mod:`dynamics_proc.inputs`). ``run(scenario, **options)`` runs one to
the end and returns a :class:`SimulationResult`. With ``out=DIR`` the run directory is written as a launched
run writes it (cosim.runtime.outputs).

Frames: frame 0 is the initial state; frame m is time ``m * timing.sensor_period_s``; a run has frames
0..``scenario.frames``. Only the in-process transport exists: stepping the launched process ring turn by turn
would need the supervisor loop of cosim.runtime.launcher split into calls, which it is not.
"""
from __future__ import annotations

import math
import traceback
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from pydantic import ValidationError

from cosim.errors import (
    InputNotSettable,
    InputOutOfRange,
    ParticipantCrashed,
    RunError,
    SimulationClosed,
    SimulationDone,
    UnknownInput,
)
from cosim.runtime.figures import PENDING, draw_figures, figures_plan
from cosim.runtime.inprocess import InProcessSession
from cosim.runtime.outputs import compose_summary, finish_outputs, write_scenario
from cosim.runtime.rundir import RunDirLock, clear_run_files, open_run_dir
from cosim.runtime.state import FrameState, StateReader
from cosim.runtime.stream import write_running_summary
from cosim.scenario.config import Scenario
from cosim.scenario.options import load_with_options

__all__ = ["Simulation", "SimulationResult", "run"]


@dataclass(frozen=True)
class SimulationResult:
    """What a finished (or stopped) run produced: ``summary`` as in summary.json, ``timeseries`` column ->
    (frames,) float64 array as in timeseries.csv, ``arrays`` the last completed frame's array blocks (height maps
    (nx, ny) m, stream (64, 4) m, ...), ``run_dir`` where it was written (None without ``out``), ``error`` the
    fault that stopped it (None when it completed or was closed early)."""

    scenario: Scenario
    summary: dict
    timeseries: dict[str, np.ndarray]
    arrays: dict[str, np.ndarray]
    run_dir: Path | None
    error: RunError | None = None

    @property
    def completed(self) -> bool:
        """Whether every frame ran."""
        return bool(self.summary.get("completed"))


class Simulation:
    """One run, stepped from Python. See docs/api.md.

    ``scenario``: a packaged scenario's name (``"default"``), a YAML path, or a loaded ``Scenario``. Options as on
    the command line: ``renderer`` ("gl", "mock", "none"), ``feedback`` ("ground_truth", "perception"), ``seed``,
    ``duration`` (s), ``overrides`` ({"dotted.path": value}) and ``set`` (["path=value", ...], as ``--set``),
    ``out`` (run directory to write, as ``--out``; nothing is written without it), ``record`` (True or a path:
    an MCAP recording, as ``--record``; needs ``out``), ``overwrite`` (replace an earlier run's files in ``out``,
    as ``--overwrite``; ``out`` holding an earlier run is refused without it, at the first ``reset``), ``allow_plugins``
    (False refuses any code that is not built in, as ``--no-plugins``). A bad scenario or option raises
    :class:`cosim.errors.ScenarioError`; an unusable ``out`` :class:`cosim.runtime.rundir.RunDirError`.
    """

    def __init__(self, scenario: str | Path | Scenario = "default", *, renderer: str | None = None,
                 feedback: str | None = None, seed: int | None = None, duration: float | None = None,
                 overrides: Mapping[str, Any] | None = None, set: Sequence[str] = (),  # noqa: A002 - as --set
                 out: str | Path | None = None, record: bool | str | Path | None = None,
                 overwrite: bool = False, allow_plugins: bool = True, transport: str = "inprocess"):
        if transport != "inprocess":
            raise ValueError(f"transport {transport!r}: only 'inprocess' exists (see cosim.api's docstring)")
        self._scenario = load_with_options(scenario, renderer=renderer, feedback=feedback, seed=seed,
                                           duration=duration, overrides=overrides, set_=set,
                                           allow_plugins=allow_plugins)
        self._out = Path(out) if out is not None else None
        if record is not None and record is not False and self._out is None:
            raise ValueError("record= needs out= (the recording is written into the run directory)")
        self._record = record
        self._overwrite = overwrite
        #: the lock of ``out`` (cosim.runtime.rundir), held from the first reset to close
        self._lock: RunDirLock | None = None
        self._session: InProcessSession | None = None
        self._reader: StateReader | None = None
        self._state: FrameState | None = None
        self._result: SimulationResult | None = None
        self._closed = False
        self._live = self._scenario
        self._changes: list[dict] = []
        #: the input paths of the last run, kept for error messages once its participants are gone
        self._ended_inputs: dict[str, object] = {}

    # -- properties ------------------------------------------------------------------------------------------
    @property
    def scenario(self) -> Scenario:
        """The scenario as the run started (options applied; ``set`` changes are not in it)."""
        return self._scenario

    @property
    def frame(self) -> int:
        """The current frame (-1 before the first ``reset``/``step``)."""
        return -1 if self._state is None else self._state.frame

    @property
    def time_s(self) -> float:
        """Simulated time of the current frame, s (``frame * timing.sensor_period_s``)."""
        return max(self.frame, 0) * self._scenario.timing.sensor_period_s

    @property
    def frames(self) -> int:
        """The last frame of the run (a run has frames 0..frames)."""
        return self._scenario.frames

    @property
    def done(self) -> bool:
        """Whether the run has ended: its last frame ran, or a participant failed."""
        return self._result is not None

    @property
    def state(self) -> FrameState:
        """The current frame's values (see :class:`cosim.runtime.state.FrameState`); starts the run if needed."""
        self._check_open()
        if self._state is None:
            self.reset()
        return self._state

    @property
    def inputs(self) -> tuple[str, ...]:
        """The scenario paths :meth:`set` accepts in this run (starts the run if needed)."""
        self._check_open()
        if self._session is None and self._result is None:
            self.reset()
        return tuple(self._input_owners())

    @property
    def result(self) -> SimulationResult | None:
        """The run's result once it is done or closed (None before)."""
        return self._result

    # -- stepping --------------------------------------------------------------------------------------------
    def reset(self, seed: int | None = None) -> FrameState:
        """Start the run again from the scenario (``seed``: a new seed for this and later runs) and run frame 0.
        A run in progress is dropped without writing its outputs. Returns the state of frame 0."""
        self._check_open()
        self._drop_session()
        if seed is not None:
            self._scenario = load_with_options(self._scenario, seed=seed)
        self._live, self._changes, self._result, self._state = self._scenario, [], None, None
        if self._out is not None:
            self._claim_out()
            write_running_summary(self._out, {"scenario": self._scenario.name, "seed": self._scenario.seed,
                                              "frames_planned": self._scenario.frames + 1})
            write_scenario(self._out, self._scenario)
        self._session = InProcessSession(self._scenario)
        self._session.sinks.extend(self._make_sinks(self._session.segment))
        self._reader = StateReader(self._session.segment)
        return self._advance(1)

    def step(self, n: int = 1) -> FrameState:
        """Run the next ``n`` frames (fewer if the run ends first) and return the state of the last one.

        Before any :meth:`reset` it resets first (frame 0, t = 0) and then runs ``n`` frames, so a fresh
        simulation's ``step(50)`` ends at frame 50, t = 50 * ``timing.sensor_period_s``."""
        self._check_open()
        if n < 1:
            raise ValueError(f"step(n): n must be >= 1, got {n}")
        if self._session is None and self._result is None:
            self.reset()
        self._check_running("step")
        return self._advance(n)

    def set(self, path: str, value: float) -> None:
        """Change run-time input ``path`` to ``value`` from the next frame on (:attr:`inputs` lists the paths).

        Raises :class:`~cosim.errors.UnknownInput` (no such scenario field), :class:`~cosim.errors.InputNotSettable`
        (a field that cannot change during a run) or :class:`~cosim.errors.InputOutOfRange` (the scenario's own
        limits refuse the value). The change is recorded: in the next frame's ``dyn_state`` row and in
        ``summary["inputs_changed"]``. Starts the run first if needed."""
        self._check_open()
        if self._session is None and self._result is None:
            self.reset()
        owners = self._input_owners()
        if path not in owners:
            known = ", ".join(owners) or "none"
            if _is_scenario_field(path):
                raise InputNotSettable(f"{path!r} cannot change during a run (set it before with overrides=); "
                                       f"inputs that can: {known}")
            raise UnknownInput(f"{path!r} is not a scenario field; run-time inputs: {known}")
        self._check_running("set")
        self._live = _validated(self._live, path, value)
        owners[path].set_input(path, float(value))
        frame = self.frame + 1
        self._changes.append({"frame": frame, "t_s": frame * self._scenario.timing.sensor_period_s, "path": path,
                              "value": float(value)})

    def close(self) -> None:
        """End the run (writing its outputs with ``out`` if it had not ended) and release everything.
        Idempotent; stepping afterwards raises :class:`~cosim.errors.SimulationClosed`."""
        if self._closed:
            return
        try:
            if self._session is not None and self._result is None:
                self._finish(None)
        finally:
            self._drop_session()
            if self._lock is not None:
                self._lock.release()
            self._closed = True

    def __enter__(self) -> "Simulation":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"<Simulation {self._scenario.name!r} frame {self.frame}/{self.frames}"
                f"{' done' if self.done else ''}{' closed' if self._closed else ''}>")

    # -- internals -------------------------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise SimulationClosed(f"simulation of {self._scenario.name!r} is closed; make a new Simulation")

    def _check_running(self, what: str) -> None:
        if self._result is not None:
            why = f"stopped on an error: {self._result.error}" if self._result.error else \
                f"has run its last frame ({self.frames}, t = {self.time_s:g} s)"
            raise SimulationDone(f"cannot {what}: the run of {self._scenario.name!r} {why}; reset() starts it again")

    def _advance(self, n: int) -> FrameState:
        session = self._session
        frame = self.frame
        try:
            for _ in range(n):
                frame = session.step()
                if session.done:
                    break
        except Exception as exc:  # noqa: BLE001 - a participant's fault ends the run, named
            who = session.turns.current or "supervisor"
            bad = session.turns.next_frame
            err = ParticipantCrashed(f"{who} raised {type(exc).__name__} at frame {bad}: {exc}", process=who,
                                     frame=bad, detail=traceback.format_exc())
            self._state = self._reader.take(frame) if frame >= 0 else None
            self._finish(err)
            self._drop_session()
            raise err from exc
        self._state = self._reader.take(frame)
        if session.done:
            self._finish(None)
            self._drop_session()
        return self._state

    def _finish(self, error: RunError | None) -> None:
        run = self._session.finish()
        for sink in self._session.sinks:
            close = getattr(sink, "close", None)
            if close is not None:
                close()
            error = error or getattr(sink, "error", None)  # a recording not written whole
        extra = {"inputs_changed": list(self._changes)} if self._changes else {}
        if self._out is not None:
            figures = figures_plan(self._out, self._live, run.recorder, error)
            summary, failure = finish_outputs(self._out, self._live, run.recorder, run.ring,
                                              wall_time_s=run.wall_time_s, error=error,
                                              extra={**extra, "figures": figures}, reserve=figures["status"] == PENDING)
            if failure is None and figures["status"] == PENDING:
                summary, failure = draw_figures(self._out, self._live, summary, run.recorder)
            error = error or failure
        else:
            summary = compose_summary(self._live, run.recorder, run.ring, wall_time_s=run.wall_time_s, error=error)
            summary.update(extra)
        arrays = {k: v.copy() for k, v in run.recorder.arrays.items()}
        self._result = SimulationResult(self._scenario, summary, run.recorder.series(), arrays, self._out, error)

    def _input_owners(self) -> dict[str, object]:
        """Run-time input path -> the participant that takes it (empty once the run has ended)."""
        if self._session is None:
            return self._ended_inputs
        owners = {}
        for p in self._session.participants.values():
            for path in getattr(p, "settable", ()):
                owners[path] = p
        self._ended_inputs = dict.fromkeys(owners)
        return owners

    def _make_sinks(self, segment) -> list:
        """The per-frame sinks ``record=`` asks for (as ``run --record``)."""
        if self._record is None or self._record is False:
            return []
        from cosim.recording import RecordOptions, mcap_sink

        path = None if self._record is True else Path(self._record)
        return [mcap_sink(RecordOptions(path=path))(self._scenario, self._out, segment)]

    def _claim_out(self) -> None:
        """Lock ``out`` at the first reset (an earlier run's files there: refused, or removed with ``overwrite``);
        at a later reset, remove the files of this simulation's previous run."""
        if self._lock is None:
            self._lock = open_run_dir(self._out, overwrite=self._overwrite, parents=True)
            weakref.finalize(self, self._lock.release)  # a Simulation dropped without close() frees ``out`` too
        else:
            clear_run_files(self._out)

    def _drop_session(self) -> None:
        session, self._session = self._session, None
        if session is not None:
            session.close()


def run(scenario: str | Path | Scenario = "default", **options) -> SimulationResult:
    """Run ``scenario`` to its end in this process (options as :class:`Simulation`'s) and return the result.
    A participant's fault raises :class:`~cosim.errors.ParticipantCrashed` after the outputs are written."""
    with Simulation(scenario, **options) as sim:
        sim.reset()
        while not sim.done:
            sim.step(sim.frames)
        return sim.result


def _is_scenario_field(path: str) -> bool:
    """Whether ``path`` ("section.field") names a field of the Scenario model."""
    model: Any = Scenario
    for part in path.split("."):
        fields = getattr(model, "model_fields", None)
        if fields is None or part not in fields:
            return False
        model = fields[part].annotation
    return True


def _validated(scenario: Scenario, path: str, value: Any) -> Scenario:
    """``scenario`` with ``path`` set to ``value``, checked by the scenario's own validators."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputOutOfRange(f"{path} = {value!r}: a number is needed")
    if not math.isfinite(float(value)):
        raise InputOutOfRange(f"{path} = {value!r}: the value must be finite")
    data = scenario.model_dump()
    *parents, leaf = path.split(".")
    node = data
    for part in parents:
        node = node[part]
    node[leaf] = float(value)
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        msgs = "; ".join(e["msg"] for e in exc.errors())
        raise InputOutOfRange(f"{path} = {value!r}: {msgs}") from None
