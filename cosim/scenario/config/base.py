"""Base record type for scenario configuration.

Every scenario section is a frozen, typed pydantic model that mirrors the YAML one to one. Unknown keys are
errors, values are never coerced from strings ("2" is not a float), and derived values are properties, not
stored defaults.
"""
from __future__ import annotations

import json
from typing import Annotated, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, JsonValue, model_validator

from .docs import schema_docs
from .limits import check_limits, schema_limits

__all__ = ["Model", "Vec3", "Mount", "Entity", "PosFloat", "NonNegFloat", "Fraction", "Angle", "PluginRef",
           "PluginOptions", "Options"]


class Model(BaseModel):
    """Frozen, strict record: unknown keys are rejected, no silent type coercion, every number finite and within
    the limits of its unit (cosim.scenario.config.limits). A field's docstring (the string literal under it) is
    its description in the JSON Schema (cosim.scenario.config.docs)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, validate_default=True, allow_inf_nan=False,
                              json_schema_extra=lambda schema, model: (schema_limits(schema, model),
                                                                       schema_docs(schema, model)))

    @model_validator(mode="after")
    def _within_limits(self):
        check_limits(self)
        return self


PosFloat = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
Fraction = Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]
Angle = Annotated[float, Field(ge=-360.0, le=360.0, allow_inf_nan=False)]
Vec3 = tuple[float, float, float]
#: a plug-in reference: a short name (built in or an entry point) or an import path ``package.module:name``;
#: the loader imports and checks it (cosim.scenario.plugins)
PluginRef = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_.-]*(:[A-Za-z_][A-Za-z0-9_.]*)?$")]


class PluginOptions(dict):
    """A plug-in's options from the scenario: keyword name -> plain YAML value (the plug-in is called with them,
    cosim.scenario.plugins). Hashable by value, so that a scenario holding them stays a cache key."""

    def __hash__(self) -> int:  # type: ignore[override]
        return hash(json.dumps(self, sort_keys=True))

    def __reduce__(self):
        return PluginOptions, (dict(self),)


#: the ``*_options`` mapping beside a plug-in reference: keyword arguments it is called with (docs/plugins.md)
Options = Annotated[dict[str, JsonValue], AfterValidator(PluginOptions)]

Entity = Literal["world", "combine", "tractor", "cart"]


class Mount(Model):
    """Pose of a rigid attachment (sensor, camera) relative to an entity's body frame.

    Body frames are x forward, y left, z up with the origin on the ground (docs/architecture.md). ``rpy_deg`` is
    roll, pitch, yaw applied as R = Rz(yaw) Ry(pitch) Rx(roll). With y left, positive pitch tips the forward axis
    down (nose down) and positive yaw turns it to the left.
    """

    parent: Entity = "combine"
    """Entity whose body frame the pose is given in: world, combine, tractor or cart."""
    xyz_m: Vec3 = (0.0, 0.0, 0.0)
    """Position (x forward, y left, z up) in the parent's body frame, m."""
    rpy_deg: Vec3 = (0.0, 0.0, 0.0)
    """Roll, pitch, yaw, deg, applied as R = Rz(yaw) Ry(pitch) Rx(roll); positive pitch tips the forward axis
    down."""
