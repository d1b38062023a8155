"""Running cases: every case's arms in interleaved rounds, the cases themselves interleaved too, and the figures
of each case (medians over the rounds, paired ratios of each arm to the first)."""
from __future__ import annotations

import sys
from dataclasses import dataclass, field
from typing import Mapping, Sequence, TextIO

from .arms import Arm, SampleFailed, sample
from .machine import commit, facts, load, now_utc
from .registry import Case
from .rounds import aggregate, alternating, paired_ratios

__all__ = ["Result", "Session", "run_cases"]


@dataclass
class Result:
    """One case's samples: ``samples[arm label][round]``."""

    case: Case
    opts: dict
    arms: list[Arm]
    rounds: int
    samples: dict[str, list[dict]] = field(default_factory=dict)
    #: what failed, one line per failed sample (its traceback went to standard error)
    failures: list[str] = field(default_factory=list)

    def median(self) -> dict[str, dict]:
        """Per arm: every figure's median (min-max) over the rounds (``harness.rounds.aggregate``)."""
        return {a.label: aggregate(self.samples[a.label]) for a in self.arms}

    def paired(self) -> dict[str, dict]:
        """Per arm after the first: each figure's ratio to the first arm's, round by round (median, min-max)."""
        base = self.samples[self.arms[0].label]
        if any(len(self.samples[a.label]) != len(base) for a in self.arms):
            return {}                                           # a failed sample: rounds no longer pair up
        return {a.label: paired_ratios(base, self.samples[a.label], self.case.compare) for a in self.arms[1:]}


@dataclass
class Session:
    """What a report says besides the figures: the command, the machine, the load before and after, the date
    and the commit of every tree."""

    command: str
    results: list[Result]
    machine: dict
    load_before: float
    load_after: float
    written_utc: str
    commits: dict[str, str | None]
    quick: bool

    @property
    def failed(self) -> bool:
        return any(r.failures for r in self.results)


def run_cases(cases: Sequence[Case], arms: Sequence[Arm], *, rounds: int | None = None, quick: bool = False,
              opts: Mapping[str, Mapping] | None = None, settings: Sequence[str] = (), in_process: bool = False,
              command: str = "", log: TextIO | None = sys.stderr) -> Session:
    """Measure every case for every arm: round r runs the cases, and within each case the arms, in order when r is
    even and reversed when it is odd. ``rounds``: for every case (default: each case's own, 1 with ``quick``);
    ``opts``: options given per case name (over the full or quick values); ``settings``: ``--set`` strings for
    every arm of the cases that run a scenario."""
    opts = dict(opts or {})
    want = {c.name: (rounds if rounds is not None else (1 if quick else c.rounds)) for c in cases}
    results = {c.name: Result(c, c.resolve(quick, opts.get(c.name)), list(arms), want[c.name],
                              {a.label: [] for a in arms}) for c in cases}
    load_before = load()
    for r in range(max(want.values(), default=0)):
        for c in alternating([c for c in cases if r < want[c.name]], r):
            res = results[c.name]
            for arm in alternating(arms, r):
                try:
                    got = sample(c, arm, res.opts, quick, r, settings if c.settings else (), in_process)
                except SampleFailed as exc:
                    res.failures.append(str(exc))
                    got = None
                else:
                    res.samples[arm.label].append(got)
                if log is not None:
                    print(f"round {r + 1}/{want[c.name]} {c.name} {arm.label}: {'done' if got else 'FAILED'}, "
                          f"load {load():.1f}", file=log, flush=True)
    commits = {a.label: commit(a.tree) for a in arms}
    return Session(command, list(results.values()), facts(), load_before, load(), now_utc(), commits, quick)
