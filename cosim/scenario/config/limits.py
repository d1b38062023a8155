"""Plausible ranges of the scenario's numbers, by the unit in each key's name.

Every numeric field of every record (a number, an optional number, each number of a tuple) is bounded on both
sides: by its own ``Field`` bounds where it has them, otherwise by the magnitude of its unit, read from the key's
suffix (``_m`` metres, ``_s`` seconds, ``_deg`` degrees, ... :data:`UNITS`). The magnitudes are limits no machine
or field this platform simulates reaches (10 km, ~28 h, 100 m/s); a value beyond one is a typo (milliseconds
typed as seconds, a missing decimal point) or hostile input, and would otherwise reach the run as an array of
terabytes or an overflow. A number without a unit suffix is bounded by :data:`DIMENSIONLESS_MAX`.

:func:`check_limits` is run by every record's validator (cosim.scenario.config.base.Model), so a value is refused
at its own key wherever the record is built (a scenario file, ``--set``, the Python API, a child re-validating
the scenario). :func:`schema_limits` writes the same bounds into the JSON Schema, so that editors know them too.
New fields are covered by their unit suffix without any change here.
"""
from __future__ import annotations

import functools
import math
import types
import typing
from dataclasses import dataclass

import annotated_types as at
from pydantic import BaseModel, ValidationError
from pydantic_core import InitErrorDetails, PydanticCustomError

__all__ = ["Unit", "UNITS", "DIMENSIONLESS_MAX", "Limit", "unit_of", "field_limits", "check_limits",
           "schema_limits", "LIMIT_ERROR", "key_error"]

#: pydantic error type of a value a record refuses at its own key (the loader shows its message as it is)
LIMIT_ERROR = "value_limit"


def key_error(record: str, loc: tuple, message: str, value: object) -> ValidationError:
    """A ValidationError at ``loc`` inside the field or record being validated (a validator raises it, and
    pydantic prefixes the field's own key), so that a cross-field problem is reported at the value to change."""
    return ValidationError.from_exception_data(record, [InitErrorDetails(
        type=PydanticCustomError(LIMIT_ERROR, message), loc=loc, input=value)])


@dataclass(frozen=True)
class Unit:
    """A unit read from a key's suffix: ``symbol`` for messages and ``magnitude``, the largest |value| accepted."""

    suffix: str
    symbol: str
    magnitude: float


#: key suffix -> unit and largest magnitude (longest suffix first, so that ``_mps`` is not read as ``_s``)
UNITS: tuple[Unit, ...] = tuple(sorted((
    Unit("_m", "m", 1e4),              # 10 km: beyond any field, machine or sensor range
    Unit("_cm", "cm", 1e6),            # 10 km
    Unit("_s", "s", 1e5),              # ~28 h: longer than a harvest day
    Unit("_deg", "deg", 360.0),        # one turn
    Unit("_mps", "m/s", 100.0),        # 360 km/h
    Unit("_mps2", "m/s^2", 100.0),     # 10 g
    Unit("_degps", "deg/s", 3600.0),   # ten turns a second
    Unit("_ps", "1/s", 1e3),           # a gain or rate beyond any loop's bandwidth
    Unit("_m3ps", "m^3/s", 10.0),      # 80 times a combine's unloading rate
    Unit("_kgpm3", "kg/m^3", 2e4),     # denser than lead
    Unit("_px", "px", 1e5),
    Unit("_kg", "kg", 1e6),            # 1000 t: thirty carts of grain
), key=lambda u: -len(u.suffix)))

#: largest |value| of a number whose key names no unit (gains, ratios, counts): no scenario needs more
DIMENSIONLESS_MAX = 1e6


@dataclass(frozen=True)
class Limit:
    """The range a numeric field is checked against by :func:`check_limits` (its own ``Field`` bounds are checked
    by pydantic): ``lo`` / ``hi`` None where the field's own bound applies on that side."""

    lo: float | None
    hi: float | None
    unit: str


def unit_of(key: str) -> Unit | None:
    """The unit named by ``key``'s suffix (``sensor_period_s`` -> seconds), None for a key without one."""
    return next((u for u in UNITS if key.endswith(u.suffix)), None)


def _numeric(annotation) -> tuple[bool, list]:
    """(whether ``annotation`` holds numbers, the constraint objects of its ``Annotated`` layers)."""
    if typing.get_origin(annotation) is typing.Annotated:
        inner, *meta = typing.get_args(annotation)
        found, more = _numeric(inner)
        return found, more + [m for item in meta for m in getattr(item, "metadata", [item])]
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        parts = [_numeric(a) for a in typing.get_args(annotation) if a is not type(None)]
        return any(p[0] for p in parts), [m for p in parts for m in p[1]]
    if typing.get_origin(annotation) is tuple:
        parts = [_numeric(a) for a in typing.get_args(annotation) if a is not Ellipsis]
        return bool(parts) and all(p[0] for p in parts), [m for p in parts for m in p[1]]
    return annotation in (int, float), []


@functools.lru_cache(maxsize=None)
def field_limits(model: type[BaseModel]) -> dict[str, Limit]:
    """Field name -> :class:`Limit` for every numeric field of ``model`` (its own fields, not its sub-records);
    none for a record that sets ``__unit_limits__ = False`` (one whose numbers are in another key's unit, such as
    a sweep's distributions)."""
    out = {}
    if not getattr(model, "__unit_limits__", True):
        return out
    for name, info in model.model_fields.items():
        numeric, meta = _numeric(info.annotation)
        if not numeric:
            continue
        meta = meta + list(info.metadata)
        has_lo = any(isinstance(m, (at.Gt, at.Ge)) for m in meta)
        has_hi = any(isinstance(m, (at.Lt, at.Le)) for m in meta)
        unit = unit_of(name)
        mag = unit.magnitude if unit is not None else DIMENSIONLESS_MAX
        if has_lo and has_hi:
            continue
        out[name] = Limit(None if has_lo else -mag, None if has_hi else mag, unit.symbol if unit else "")
    return out


def _numbers(value) -> list[tuple[tuple, float]]:
    """(location inside the field, number) of each number in a field's value (a tuple gives one per item)."""
    if isinstance(value, tuple):
        return [((i,), v) for i, v in enumerate(value) if isinstance(v, (int, float)) and not isinstance(v, bool)]
    return [((), value)] if isinstance(value, (int, float)) and not isinstance(value, bool) else []


def _with_unit(x: float, unit: str) -> str:
    return f"{x:g} {unit}" if unit else f"{x:g}"


def check_limits(record: BaseModel) -> None:
    """Raise a pydantic ValidationError (one error per value, at its field) for every number of ``record`` beyond
    its :class:`Limit`; the message names the unit."""
    errors = []
    for name, limit in field_limits(type(record)).items():
        for where, x in _numbers(getattr(record, name)):
            side = ("above", limit.hi) if limit.hi is not None and x > limit.hi else \
                   ("below", limit.lo) if limit.lo is not None and x < limit.lo else None
            if side is None or not math.isfinite(x):     # non-finite numbers are refused by the type itself
                continue
            what = f"{_with_unit(x, limit.unit)} is {side[0]} {_with_unit(side[1], limit.unit)}, "
            what += ("beyond any machine, field or run this platform simulates (a unit typed wrong?)" if limit.unit
                     else "beyond any plausible value of a number without a unit")
            errors.append(InitErrorDetails(type=PydanticCustomError(LIMIT_ERROR, what), loc=(name, *where),
                                           input=x))
    if errors:
        raise ValidationError.from_exception_data(type(record).__name__, errors)


def schema_limits(schema: dict, model: type[BaseModel]) -> None:
    """Add the :func:`field_limits` of ``model`` to its JSON Schema (``minimum`` / ``maximum`` of each numeric
    property, its items for a tuple, its number branch for an optional number), where the field has none."""
    for name, limit in field_limits(model).items():
        prop = schema.get("properties", {}).get(name)
        if prop is None:
            continue
        targets = prop.get("prefixItems") or [b for b in prop.get("anyOf", []) if b.get("type") in
                                              ("number", "integer")] or [prop]
        for target in targets:
            if limit.lo is not None:
                target.setdefault("minimum", limit.lo)
            if limit.hi is not None:
                target.setdefault("maximum", limit.hi)
