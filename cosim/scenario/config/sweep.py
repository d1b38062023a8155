"""The sweep file's record (``launch.py sweep FILE``, docs/sweeps.md): what to vary over a base scenario.

Run count = product of the ``grid`` list lengths x the ``zip`` length x the ``random`` count x the number of
seeds (each section that is empty counts 1). Values of ``set``/``grid``/``zip`` and sampled values are checked
against the scenario schema separately (cosim/studies/sweepfile.py), with the sweep file's lines.
"""
from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from .base import Model

__all__ = ["SWEEP_FORMAT_VERSION", "Distribution", "SweepFile"]

SWEEP_FORMAT_VERSION = 1
MAX_RUNS = 100_000  # a sweep larger than this is almost surely a typo (a count of 10**6)

NonEmptyList = Annotated[list[Any], Field(min_length=1)]


class Distribution(Model):
    """A sampled parameter: ``distribution`` with its arguments, and how many values to draw (``count``).

    uniform(low, high), loguniform(low, high) (uniform in log, 0 < low), normal(mean, std), choice(values).
    Every random parameter of a sweep draws the same ``count`` values, jointly (value i of each makes point i).
    """

    distribution: Literal["uniform", "normal", "loguniform", "choice"]
    count: Annotated[int, Field(ge=1)]
    low: float | None = None
    high: float | None = None
    mean: float | None = None
    std: Annotated[float, Field(ge=0.0)] | None = None
    values: NonEmptyList | None = None

    @model_validator(mode="after")
    def _arguments(self):
        need = {"uniform": ("low", "high"), "loguniform": ("low", "high"), "normal": ("mean", "std"),
                "choice": ("values",)}[self.distribution]
        extra = [k for k in ("low", "high", "mean", "std", "values") if k not in need and getattr(self, k) is not None]
        missing = [k for k in need if getattr(self, k) is None]
        if missing or extra:
            raise ValueError(f"{self.distribution} takes {' and '.join(need)}"
                             + (f"; missing {', '.join(missing)}" if missing else "")
                             + (f"; {', '.join(extra)} not allowed" if extra else ""))
        if self.low is not None and self.high is not None and not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        if self.distribution == "loguniform" and self.low <= 0:
            raise ValueError(f"loguniform needs 0 < low, got low = {self.low}")
        return self


class SweepFile(Model):
    """A sweep: ``base`` scenario, fixed overrides ``set``, and the varied parameters (dotted scenario paths)."""

    format_version: Literal[1]
    name: str | None = None
    base: str = "default"
    set: dict[str, Any] = Field(default_factory=dict)
    grid: dict[str, NonEmptyList] = Field(default_factory=dict)
    zip: dict[str, NonEmptyList] = Field(default_factory=dict)
    random: dict[str, Distribution] = Field(default_factory=dict)
    #: random seed of the sampled parameters (the runs' own seeds are ``seeds``)
    sample_seed: Annotated[int, Field(ge=0)] = 0
    #: a list of scenario seeds, or a count n meaning 0..n-1
    seeds: Any = 1

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, v):
        def is_int(x) -> bool:
            return isinstance(x, int) and not isinstance(x, bool)

        if not ((is_int(v) and v >= 1) or (isinstance(v, list) and v and all(is_int(x) and x >= 0 for x in v))):
            raise ValueError(f"expected a count (an integer >= 1) or a non-empty list of seeds (integers >= 0), "
                             f"got {v!r}")
        if isinstance(v, list) and len(set(v)) != len(v):
            raise ValueError(f"seeds repeat: {v}")
        return v

    @property
    def seed_list(self) -> list[int]:
        return list(range(self.seeds)) if isinstance(self.seeds, int) else list(self.seeds)
