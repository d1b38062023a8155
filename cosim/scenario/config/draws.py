"""What a scenario's seed draws of its field (``field:``; cosim.scenario.config.fielddraw, docs/field.md).

A field case names the conditions its seed draws (``draw``) and the range of each; the draw replaces the values
of the keys it owns (listed per condition below) by values drawn uniformly from those ranges, from a generator
keyed by the scenario's seed and the condition. So N seeds are N fields, not N noise draws over one trajectory.
A scenario that draws nothing (the default) is unchanged, to the bit.
"""
from __future__ import annotations

from typing import Annotated, Literal

from pydantic import AfterValidator, Field, field_validator, model_validator

from .base import Model, NonNegFloat, Options

__all__ = ["CONDITIONS", "Range", "FlowDraw", "GnssDraw", "ProfileDraw", "TerrainDraw", "DustDraw", "OffsetsDraw",
           "FieldDraws"]

#: the conditions a seed can draw, in the order they are drawn
CONDITIONS = ("flow", "gnss", "profile", "terrain", "dust", "offsets")



def _ordered(v: tuple[float, float]) -> tuple[float, float]:
    if v[0] > v[1]:
        raise ValueError(f"a range is [low, high] with low <= high, got [{v[0]:g}, {v[1]:g}]")
    return v


#: a closed interval [low, high] a value is drawn from uniformly (low == high: that value)
Range = Annotated[tuple[float, float], AfterValidator(_ordered)]


class _Draw(Model):
    """A condition's ranges."""


class FlowDraw(_Draw):
    """The yield-driven variation of the flow (owns ``auger.flow_variation``): its standard deviation (relative to
    the nominal flow) and its correlation time; its realisation is the seed's as ever."""

    sigma: Range = (0.02, 0.08)
    """Range of auger.flow_variation.sigma, a fraction of the nominal flow."""
    correlation_time_s: Range = (5.0, 20.0)
    """Range of auger.flow_variation.correlation_time_s, s."""

    @field_validator("sigma")
    @classmethod
    def _sigma(cls, v: Range) -> Range:
        if v[0] < 0.0 or v[1] > 1.0:
            raise ValueError(f"the flow's relative sigma is drawn within [0, 1], got [{v[0]:g}, {v[1]:g}]")
        return v

    @field_validator("correlation_time_s")
    @classmethod
    def _positive(cls, v: Range) -> Range:
        if v[0] <= 0.0:
            raise ValueError(f"a correlation time is drawn above 0 s, got [{v[0]:g}, {v[1]:g}]")
        return v


class GnssDraw(_Draw):
    """Each receiver's GNSS error (owns ``machine_sync.gnss``): standard deviation and correlation time; its
    realisation is the seed's as ever."""

    sigma_m: Range = (0.01, 0.03)
    """Range of machine_sync.gnss.sigma, m."""
    correlation_time_s: Range = (15.0, 60.0)
    """Range of machine_sync.gnss.correlation_time_s, s."""

    @field_validator("sigma_m")
    @classmethod
    def _sigma(cls, v: Range) -> Range:
        if v[0] < 0.0 or v[1] > 0.5:
            raise ValueError(f"the GNSS sigma is drawn within [0, 0.5] m, got [{v[0]:g}, {v[1]:g}]")
        return v

    @field_validator("correlation_time_s")
    @classmethod
    def _positive(cls, v: Range) -> Range:
        return FlowDraw._positive(v)


class ProfileDraw(_Draw):
    """Jitter of the combine's speed and turn profile (owns ``combine.profile``, or ``combine.speed_mps`` where
    there is no profile): every point's speed times ``1 + U(-speed, speed)`` and curvature times
    ``1 + U(-curvature, curvature)``, every point after the first moved by one common ``U(shift_s)`` (when the
    events come) and by its own ``U(-time_s, time_s)``."""

    speed: float = Field(default=0.1, ge=0.0, le=0.5, allow_inf_nan=False)
    """Relative half-width of each speed's jitter."""
    curvature: float = Field(default=0.0, ge=0.0, le=0.5, allow_inf_nan=False)
    """Relative half-width of each curvature's jitter."""
    shift_s: Range = (0.0, 0.0)
    """Range of the common shift of every point after the first, s."""
    time_s: NonNegFloat = 0.0
    """Half-width of each point's own time jitter (after the first), s."""


class TerrainDraw(_Draw):
    """The ground's roughness (owns ``terrain.roughness_rms_m`` and ``terrain.correlation_length_m``); the surface
    itself is the seed's as ever."""

    roughness_rms_m: Range = (0.02, 0.04)
    """Range of terrain.roughness_rms_m, m."""
    correlation_length_m: Range = (1.5, 3.0)
    """Range of terrain.correlation_length_m, m."""

    @field_validator("roughness_rms_m", "correlation_length_m")
    @classmethod
    def _bounded(cls, v: Range, info) -> Range:
        low, high = (0.0, 0.5) if info.field_name == "roughness_rms_m" else (1e-3, 100.0)
        if v[0] < low or v[1] > high:
            raise ValueError(f"drawn within [{low:g}, {high:g}] m, got [{v[0]:g}, {v[1]:g}]")
        return v


class DustDraw(_Draw):
    """The dust (owns ``atmosphere.visibility_m`` and ``atmosphere.dust_window_s``): its visibility, and the start
    and length of its gust. A range left out keeps the scenario's value; ``start_s`` and ``length_s`` come
    together (they make the gust's window)."""

    visibility_m: Range | None = None
    """Range of atmosphere.visibility_m, m (None: the scenario's)."""
    start_s: Range | None = None
    """Range of the gust's start, s (None: the scenario's window)."""
    length_s: Range | None = None
    """Range of the gust's length, s (None: the scenario's window)."""

    @field_validator("visibility_m", "length_s")
    @classmethod
    def _positive(cls, v: Range | None) -> Range | None:
        if v is not None and v[0] <= 0.0:
            raise ValueError(f"drawn above 0, got [{v[0]:g}, {v[1]:g}]")
        return v

    @field_validator("start_s")
    @classmethod
    def _not_negative(cls, v: Range | None) -> Range | None:
        if v is not None and v[0] < 0.0:
            raise ValueError(f"a gust starts at 0 s or later, got [{v[0]:g}, {v[1]:g}]")
        return v

    @model_validator(mode="after")
    def _window_whole(self) -> "DustDraw":
        if (self.start_s is None) != (self.length_s is None):
            raise ValueError("start_s and length_s are drawn together (the gust's window): give both or neither")
        return self


class OffsetsDraw(_Draw):
    """The tractor's initial displacement from its setpoint (owns ``machine_sync.initial_long_error_m`` and
    ``initial_lat_error_m``), combine axes."""

    long_m: Range = (-0.5, 0.5)
    """Range of machine_sync.initial_long_error_m, m."""
    lat_m: Range = (-0.3, 0.3)
    """Range of machine_sync.initial_lat_error_m, m."""


class FieldDraws(Model):
    """The conditions the seed draws (``draw``, any of flow, gnss, profile, terrain, dust, offsets) and their
    ranges (one block per condition; a block left out has the defaults above). A block of a condition not in
    ``draw`` does nothing, so that ``--set field.draw=[]`` switches a case's draws off. ``base`` is written by the draw: the values it replaced, so
    that a resolved scenario loaded with another seed draws from the scenario's own values again; leave it out."""

    draw: tuple[Literal["flow", "gnss", "profile", "terrain", "dust", "offsets"], ...] = ()
    """The conditions the seed draws."""
    flow: FlowDraw = FlowDraw()
    """Ranges of the flow's variation."""
    gnss: GnssDraw = GnssDraw()
    """Ranges of the GNSS error."""
    profile: ProfileDraw = ProfileDraw()
    """Jitter of the speed and turn profile."""
    terrain: TerrainDraw = TerrainDraw()
    """Ranges of the roughness."""
    dust: DustDraw = DustDraw()
    """Ranges of the dust and its gust."""
    offsets: OffsetsDraw = OffsetsDraw()
    """Ranges of the initial offsets."""
    base: Options = {}
    """The values the draw replaced, dotted key -> value (written by the draw; leave it out)."""

    @field_validator("draw")
    @classmethod
    def _once(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        repeated = sorted({c for c in v if v.count(c) > 1})
        if repeated:
            raise ValueError(f"a condition is drawn once: {', '.join(repeated)} repeat")
        return v

