"""One run's state (cosim.runtime.launcher): what set-up made, what supervision and teardown use."""
from __future__ import annotations

import multiprocessing as mp
from dataclasses import dataclass, field
from pathlib import Path

from cosim.scenario.config import Scenario
from shm_schema import Segment

from .lockstep import RingPlan
from .pipeline import PipePlan
from .recorder import Recorder
from .rundir import RunDirLock
from .signals import StopSignals
from .specs import SUPERVISOR
from .stream import RunFiles

__all__ = ["RunState"]


@dataclass
class RunState:
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
    #: why the run has its schedule (cosim.runtime.pipeline.effective_schedule)
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
