"""The exception hierarchy, split by phase.

* before the run: :class:`ScenarioError` (with every problem found, each ``file:line:col: path: message``);
* at attach: :class:`shm_schema.SchemaMismatch` (lives in shm_schema, which does not import cosim);
* during the run: :class:`RunError` and its subclasses, whose messages name the process, the frame and the cause;
* driving a run from Python (``cosim.Simulation``): :class:`SimulationError` and its subclasses, for calls that do
  not fit the run's state (closed, done) and for :class:`InputError` (``set`` of an unknown, fixed or out-of-range
  input).
"""
from __future__ import annotations

import os
from dataclasses import dataclass

__all__ = [
    "shown_path", "CosimError", "Problem", "ScenarioError", "RunError", "HandoffTimeout", "FrameMismatch",
    "ParticipantCrashed", "ParticipantDied", "ParticipantHung", "RunInterrupted", "OutputError", "RecordingFailed",
    "RunRefused",
    "RendererUnavailable", "PluginFault", "SimulationError", "SimulationClosed", "SimulationDone", "InputError",
    "UnknownInput", "InputNotSettable", "InputOutOfRange",
]


def shown_path(path: str | os.PathLike) -> str:
    """``path`` for a message or the console: as it is when printable, else Python's escaped repr, so that a
    control byte in a user's path (an escape typed into ``--out``) never reaches the terminal raw."""
    text = os.fsdecode(path)
    return text if text.isprintable() else repr(text)


class CosimError(Exception):
    """Base of every error this platform raises on purpose."""


@dataclass(frozen=True)
class Problem:
    """One scenario problem: where it is and what is wrong. ``line``/``col`` are 1-based, 0 when unknown."""

    file: str
    line: int
    col: int
    path: str
    message: str

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}: {self.path or '<root>'}: {self.message}"


class ScenarioError(CosimError):
    """The scenario is invalid. ``problems`` lists every problem found, in file order."""

    def __init__(self, problems: list[Problem]):
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems) or "invalid scenario")


class RunRefused(CosimError):
    """A run cannot start (its ``--out`` is not a writable directory or another run holds it, its shared memory
    would not fit): nothing was started. The CLI exits 2."""


class RunError(CosimError):
    """A run stopped before its last frame. ``process`` and ``frame`` say where."""

    def __init__(self, message: str, *, process: str = "", frame: int = -1, detail: str = ""):
        self.process = process
        self.frame = frame
        self.detail = detail
        super().__init__(message)


class HandoffTimeout(RunError):
    """A lockstep hand-off did not arrive in time (a participant hangs or is far too slow)."""


class FrameMismatch(RunError):
    """A hand-off carried another frame id than the receiver expected (out-of-order call)."""


class ParticipantCrashed(RunError):
    """A participant raised; ``detail`` holds its traceback."""


class ParticipantDied(RunError):
    """A participant process ended without reporting (killed by a signal, os._exit, ...)."""


class ParticipantHung(RunError):
    """A participant process stopped running (SIGSTOP, a deadlock): its liveness heartbeat stopped. ``threads``:
    what its threads were doing when it was named (cosim.runtime.threadreport), one line each."""

    def __init__(self, message: str, *, threads: list[str] | None = None, **kwargs):
        super().__init__(message, **kwargs)
        self.threads = list(threads or [])


class OutputError(RunError):
    """Writing the run's outputs failed (no space left on the device, permission): names the path. The process at
    fault is the one that writes the outputs, the launcher (its ring name: ``supervisor``), unless said."""

    def __init__(self, message: str, *, process: str = "supervisor", frame: int = -1, detail: str = ""):
        super().__init__(message, process=process, frame=frame, detail=detail)


class RecordingFailed(OutputError):
    """The recording asked for (``--record``, ``record=``) was not written whole: names the file and the cause.
    The run goes on without it (an observer never stops a run) and ends failed, with every other output."""

    def __init__(self, message: str, *, process: str = "recorder", frame: int = -1, detail: str = ""):
        super().__init__(message, process=process, frame=frame, detail=detail)


class RunInterrupted(RunError):
    """The run was stopped by SIGINT or SIGTERM."""


class PluginFault(RunError):
    """A plug-in raised or returned a bad value during the run. ``ref`` is the plug-in as the scenario names it,
    ``point`` its scenario key (``controller.strategy``, ...), ``cause`` what went wrong, ``frame`` where (-1:
    not known yet; :meth:`at_frame` adds it)."""

    def __init__(self, ref: str, point: str, cause: str, frame: int = -1):
        self.ref, self.point, self.cause = ref, point, cause
        where = f" at frame {frame}" if frame >= 0 else ""
        super().__init__(f"plug-in {point} = {ref!r}{where}: {cause}", process=point, frame=frame)

    def at_frame(self, frame: int) -> "PluginFault":
        """The same fault at ``frame`` (self when it already names one)."""
        return self if self.frame >= 0 else PluginFault(self.ref, self.point, self.cause, frame)

    def __reduce__(self):
        return PluginFault, (self.ref, self.point, self.cause, self.frame)


class RendererUnavailable(CosimError):
    """No OpenGL context can be made here; the message suggests ``--renderer mock``."""


class SimulationError(CosimError):
    """A call on a :class:`cosim.Simulation` that its state does not allow."""


class SimulationClosed(SimulationError):
    """The simulation was closed; make a new one."""


class SimulationDone(SimulationError):
    """The run has reached its last frame (or stopped on an error); ``reset()`` starts it again."""


class InputError(SimulationError):
    """``Simulation.set(path, value)`` refused: see the subclasses."""


class UnknownInput(InputError, LookupError):
    """No scenario field has that path."""


class InputNotSettable(InputError):
    """The path is a scenario field, but not one that may change during a run (use ``overrides=`` before it)."""


class InputOutOfRange(InputError, ValueError):
    """The value is not allowed for that input (the scenario's own limits)."""
