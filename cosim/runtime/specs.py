"""Which code plays which ring role: participant specs, resolved by import path so children can spawn them."""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from cosim.scenario.config import Scenario
from shm_schema import Schema

__all__ = ["ParticipantSpec", "DEFAULT_SPECS", "SUPERVISOR", "load_callable", "build_schema", "ring_specs"]

#: header slot name of the launcher process, which closes the ring by recording each completed frame
SUPERVISOR = "supervisor"


@dataclass(frozen=True)
class ParticipantSpec:
    """A ring role: ``factory(scenario, **kwargs) -> Participant``, ``blocks(scenario) -> list[Block]`` and an
    optional ``summary`` function, each given as an import path ``"package.module:function"``."""

    name: str
    factory: str
    blocks: str
    summary: str | None = None
    #: ``predicate(scenario) -> bool``: whether this member publishes one turn late (cosim.runtime.participant)
    defers: str | None = None
    #: ``reads(scenario) -> {producer: lag}``: the members whose outputs this one reads, and how many frames back
    #: (the pipelined schedule, cosim.runtime.pipeline); None: the member cannot be pipelined
    reads: str | None = None
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    #: ``initial_state(scenario) -> (dyn_state fields, truth height map float32)``: the frame-0 world the scenario
    #: checks look at (cosim.scenario.plausibility); the dynamics role only
    initial_state: str | None = None

    def create(self, scenario: Scenario):
        return load_callable(self.factory)(scenario, **dict(self.kwargs))

    def defers_outputs(self, scenario: Scenario) -> bool:
        """Whether this member overlaps the next frame and publishes its outputs at its next turn."""
        return self.defers is not None and bool(load_callable(self.defers)(scenario))

    def reads_of(self, scenario: Scenario) -> dict[str, int] | None:
        """{producer: lag} of what this member reads at frame m (the producer's frame m - lag), or None."""
        return None if self.reads is None else dict(load_callable(self.reads)(scenario))

    def declare_blocks(self, scenario: Scenario) -> list:
        return list(load_callable(self.blocks)(scenario))


DEFAULT_SPECS: dict[str, ParticipantSpec] = {
    "dynamics": ParticipantSpec("dynamics", "dynamics_proc.participant:create", "dynamics_proc.blocks:declare_blocks",
                                "dynamics_proc.summary:summarize", reads="cosim.runtime.participant:dynamics_reads",
                                initial_state="dynamics_proc.model:frame0_state"),
    "renderer": ParticipantSpec("renderer", "renderer_proc.participant:create", "renderer_proc.blocks:declare_blocks",
                                "renderer_proc.summary:summarize", reads="cosim.runtime.participant:renderer_reads"),
    "perception": ParticipantSpec("perception", "perception_proc.participant:create",
                                  "perception_proc.blocks:declare_blocks", "perception_proc.summary:summarize",
                                  defers="cosim.runtime.participant:perception_overlaps",
                                  reads="cosim.runtime.participant:perception_reads"),
}


def load_callable(path: str) -> Callable:
    """Import ``"package.module:attr"`` and return the attribute."""
    module, _, attr = path.partition(":")
    if not module or not attr:
        raise ValueError(f"import path {path!r} must look like 'package.module:function'")
    return getattr(importlib.import_module(module), attr)


def ring_specs(scenario: Scenario, specs: Mapping[str, ParticipantSpec] | None = None) -> list[ParticipantSpec]:
    """The ring's specs in order: by default those of ``scenario.participants``; given ``specs`` (stand-ins in
    tests), exactly those, in their order."""
    if specs is not None:
        return list(specs.values())
    missing = [n for n in scenario.participants if n not in DEFAULT_SPECS]
    if missing:
        raise KeyError(f"no participant spec for {missing}")
    return [DEFAULT_SPECS[n] for n in scenario.participants]


def build_schema(scenario: Scenario, ring: list[ParticipantSpec]) -> Schema:
    """The run's schema: every ring member's blocks (only members the scene needs are asked)."""
    blocks = []
    for spec in ring:
        blocks.extend(spec.declare_blocks(scenario))
    return Schema(blocks, [s.name for s in ring] + [SUPERVISOR])
