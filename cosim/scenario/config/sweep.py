"""The sweep file's record (``launch.py sweep FILE``, docs/sweeps.md): what to vary over a base scenario.

Run count = product of the ``grid`` list lengths x the ``zip`` length x the ``random`` count x the number of
seeds (each section that is empty counts 1). Values of ``set``/``grid``/``zip`` and sampled values are checked
against the scenario schema separately (cosim/studies/sweepfile.py), with the sweep file's lines.
"""
from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from .base import Model

__all__ = ["SWEEP_FORMAT_VERSION", "MAX_RUNS", "Distribution", "SweepFile"]

SWEEP_FORMAT_VERSION = 1
MAX_RUNS = 100_000  # a sweep larger than this is almost surely a typo (a count of 10**6)

NonEmptyList = Annotated[list[Any], Field(min_length=1)]


class Distribution(Model):
    """A sampled parameter: ``distribution`` with its arguments, and how many values to draw (``count``).

    uniform(low, high), loguniform(low, high) (uniform in log, 0 < low), normal(mean, std), choice(values).
    Every random parameter of a sweep draws the same ``count`` values, jointly (value i of each makes point i).
    The arguments are in the unit of the varied key: each drawn value is checked against that key's limits, not
    here.
    """

    __unit_limits__ = False

    distribution: Literal["uniform", "normal", "loguniform", "choice"]
    """uniform, normal, loguniform or choice."""
    count: Annotated[int, Field(ge=1, le=MAX_RUNS)]
    """How many values to draw."""
    low: float | None = None
    """Lower end of uniform / loguniform (0 < low for loguniform)."""
    high: float | None = None
    """Upper end of uniform / loguniform."""
    mean: float | None = None
    """Mean of normal."""
    std: Annotated[float, Field(ge=0.0)] | None = None
    """Standard deviation of normal."""
    values: NonEmptyList | None = None
    """The values choice draws from."""
    """The values choice draws from."""

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

    __unit_limits__ = False

    format_version: Literal[1]
    """Version of the sweep file format: 1."""
    name: str | None = None
    """Name of the sweep (default: the file's stem)."""
    base: str | list[str] = "default"
    """The scenario every run starts from: a packaged name or a path relative to the sweep file; a list of them
    runs every point over each (a suite of cases: the table's ``base`` column names each run's)."""
    set: dict[str, Any] = Field(default_factory=dict)
    """Overrides every run gets: dotted scenario key -> value."""
    grid: dict[str, NonEmptyList] = Field(default_factory=dict)
    """Parameters varied over every combination: dotted key -> list of values."""
    zip: dict[str, NonEmptyList] = Field(default_factory=dict)
    """Parameters varied together (value i of each makes point i): dotted key -> list of values."""
    random: dict[str, Distribution] = Field(default_factory=dict)
    """Sampled parameters: dotted key -> distribution."""
    sample_seed: Annotated[int, Field(ge=0, le=2**63 - 1)] = 0
    """Random seed of the sampled parameters (the runs' own seeds are ``seeds``)."""
    seeds: Any = 1
    """A list of scenario seeds, or a count n meaning 0..n-1 (at most the run limit)."""

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, v):
        def is_int(x) -> bool:
            return isinstance(x, int) and not isinstance(x, bool)

        if not ((is_int(v) and v >= 1) or (isinstance(v, list) and v and all(is_int(x) and x >= 0 for x in v))):
            raise ValueError(f"expected a count (an integer >= 1) or a non-empty list of seeds (integers >= 0), "
                             f"got {v!r}")
        if is_int(v) and v > MAX_RUNS:
            raise ValueError(f"{v:,} seeds: a sweep has at most {MAX_RUNS:,} runs")
        if isinstance(v, list) and len(set(v)) != len(v):
            raise ValueError(f"seeds repeat: {v}")
        return v

    @property
    def seed_list(self) -> list[int]:
        return list(range(self.seeds)) if isinstance(self.seeds, int) else list(self.seeds)
