"""The seed's draw of a scenario's field (``field:``, cosim.scenario.config.draws; docs/field.md).

:func:`realise` is the last validator of ``Scenario`` (it draws on the validated record's data with
:func:`draw_field`, validates the result once more and takes its values), so every way a scenario is built (a file, ``--set``, a sweep's run, a child process re-validating the scenario it was
sent, ``Simulation.reset(seed=...)``) draws the same values for the same seed. It first puts back the values an
earlier draw replaced (``field.base``), then draws each condition of ``field.draw`` from its own generator,
``numpy.random.default_rng([seed, key])`` with a fixed key per condition (adding a condition leaves the others'
draws as they were), and records what it replaced in ``field.base``. Drawing twice with one seed gives the same
values; a scenario that draws nothing is returned as it is.
"""
from __future__ import annotations

import zlib
from contextvars import ContextVar
from typing import Any

import numpy as np
from pydantic import BaseModel

from .draws import CONDITIONS, FieldDraws

__all__ = ["OWNED", "draw_field", "condition_rng", "realise", "profile_problem", "replaced_keys"]

#: the scenario keys each condition's draw replaces (dotted paths)
OWNED: dict[str, tuple[str, ...]] = {
    "flow": ("auger.flow_variation.sigma", "auger.flow_variation.correlation_time_s"),
    "gnss": ("machine_sync.gnss.sigma", "machine_sync.gnss.correlation_time_s"),
    "profile": ("combine.profile", "combine.speed_mps"),
    "terrain": ("terrain.roughness_rms_m", "terrain.correlation_length_m"),
    "dust": ("atmosphere.visibility_m", "atmosphere.dust_window_s"),
    "offsets": ("machine_sync.initial_long_error_m", "machine_sync.initial_lat_error_m"),
}
#: keys whose values are tuples (the validators refuse lists where a draw writes them)
_TUPLES = {"combine.profile", "atmosphere.dust_window_s"}


def replaced_keys(field: Any) -> dict[str, tuple[str, dict]]:
    """The keys a scenario's ``field`` block (its mapping, as written) replaces with a drawn value, dotted key ->
    (its condition, that condition's ranges as validated). A profile's draw jitters the values written (every point's speed, curvature and time, or the
    speed), so a profile key is not replaced; a dust key is replaced only where its range is given. An invalid
    block replaces nothing (validation reports it)."""
    try:
        spec = FieldDraws.model_validate(_plain(field), strict=False)
    except (ValueError, TypeError):
        return {}
    out: dict[str, tuple[str, dict]] = {}
    for condition in spec.draw:
        keys = OWNED[condition]
        if condition == "profile":
            keys = ()
        elif condition == "dust":
            keys = tuple(k for k, given in zip(keys, (spec.dust.visibility_m, spec.dust.start_s)) if given is not None)
        ranges = {k: v for k, v in getattr(spec, condition).model_dump().items() if v is not None}
        out.update({k: (condition, ranges) for k in keys})
    return out


def condition_rng(seed: int, condition: str) -> np.random.Generator:
    """The generator of ``condition``'s draw for ``seed`` (its own stream: the key is a checksum of its name)."""
    return np.random.default_rng([int(seed), zlib.crc32(f"field.{condition}".encode())])


def _plain(node: Any) -> Any:
    """A block as a dict (a record given as an instance is dumped, tuples kept)."""
    return node.model_dump() if isinstance(node, BaseModel) else node


def _default(model: type[BaseModel], path: str) -> Any:
    """The default value of a dotted key of the record ``model`` (the scenario's), from the records' defaults."""
    head, *rest = path.split(".")
    value: Any = model.model_fields[head].get_default(call_default_factory=True)
    for key in rest:
        value = getattr(value, key)
    return value.model_dump() if isinstance(value, BaseModel) else value


def _get(data: dict, path: str, model: type[BaseModel]) -> Any:
    node: Any = data
    for key in path.split("."):
        node = _plain(node)
        if not isinstance(node, dict) or key not in node:
            return _default(model, path)
        node = node[key]
    return _plain(node)


def _set(data: dict, path: str, value: Any) -> None:
    """Set ``path`` in ``data``, copying every block on the way (the caller's data is never changed)."""
    *heads, last = path.split(".")
    node = data
    for key in heads:
        child = _plain(node.get(key))
        child = dict(child) if isinstance(child, dict) else {}
        node[key] = child
        node = child
    if path in _TUPLES and value is not None:
        value = tuple(dict(_plain(v)) if isinstance(_plain(v), dict) else v for v in value)
    node[last] = value


def _uniform(rng: np.random.Generator, rng_range) -> float:
    low, high = rng_range
    return float(low + (high - low) * rng.random())


def _draw_profile(rng: np.random.Generator, spec, base: dict) -> dict[str, Any]:
    """Jittered profile points, or a jittered speed where the scenario has no profile."""
    points = base["combine.profile"] or ()
    if not points:
        return {"combine.speed_mps": base["combine.speed_mps"] * (1.0 + spec.speed * rng.uniform(-1.0, 1.0))}
    shift = _uniform(rng, spec.shift_s)
    out = []
    for i, p in enumerate(points):
        p = dict(_plain(p))
        p.setdefault("curvature_1pm", 0.0)
        p["speed_mps"] = float(p["speed_mps"]) * (1.0 + spec.speed * rng.uniform(-1.0, 1.0))
        p["curvature_1pm"] = float(p["curvature_1pm"]) * (1.0 + spec.curvature * rng.uniform(-1.0, 1.0))
        if i > 0:
            p["t_s"] = float(p["t_s"]) + shift + spec.time_s * rng.uniform(-1.0, 1.0)
        out.append(p)
    return {"combine.profile": tuple(out)}


def _draw_dust(rng: np.random.Generator, spec, base: dict) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if spec.visibility_m is not None:
        out["atmosphere.visibility_m"] = _uniform(rng, spec.visibility_m)
    if spec.start_s is not None:
        start = _uniform(rng, spec.start_s)
        out["atmosphere.dust_window_s"] = (start, start + _uniform(rng, spec.length_s))
    return out


def _draw(condition: str, rng: np.random.Generator, spec: FieldDraws, base: dict) -> dict[str, Any]:
    """The drawn values of one condition, dotted key -> value."""
    if condition == "flow":
        return {"auger.flow_variation.sigma": _uniform(rng, spec.flow.sigma),
                "auger.flow_variation.correlation_time_s": _uniform(rng, spec.flow.correlation_time_s)}
    if condition == "gnss":
        return {"machine_sync.gnss.sigma": _uniform(rng, spec.gnss.sigma_m),
                "machine_sync.gnss.correlation_time_s": _uniform(rng, spec.gnss.correlation_time_s)}
    if condition == "terrain":
        return {"terrain.roughness_rms_m": _uniform(rng, spec.terrain.roughness_rms_m),
                "terrain.correlation_length_m": _uniform(rng, spec.terrain.correlation_length_m)}
    if condition == "offsets":
        return {"machine_sync.initial_long_error_m": _uniform(rng, spec.offsets.long_m),
                "machine_sync.initial_lat_error_m": _uniform(rng, spec.offsets.lat_m)}
    if condition == "profile":
        return _draw_profile(rng, spec.profile, base)
    return _draw_dust(rng, spec.dust, base)


def draw_field(data: Any, model: type[BaseModel]) -> Any:
    """``data`` (a scenario's mapping, of the record ``model``) with its field drawn for its seed (module
    docstring). Data that is not a mapping, or whose ``field`` or ``seed`` is invalid, is returned as it is
    (validation then reports it)."""
    if not isinstance(data, dict) or "field" not in data:
        return data
    try:
        spec = FieldDraws.model_validate(_plain(data["field"]), strict=False)
        seed = int(data.get("seed", 0))
    except (ValueError, TypeError):
        return data
    if not spec.draw and not spec.base:
        return data
    out = dict(data)
    for path, value in spec.base.items():                       # the scenario's own values back
        _set(out, path, value)
    paths = [p for c in CONDITIONS if c in spec.draw for p in OWNED[c]]
    base = {p: _get(out, p, model) for p in paths}
    for condition in (c for c in CONDITIONS if c in spec.draw):
        for path, value in _draw(condition, condition_rng(seed, condition), spec, base).items():
            _set(out, path, value)
    field = dict(_plain(data["field"]))
    field["base"] = {p: _json(v) for p, v in base.items()}
    out["field"] = field
    return out


def _json(value: Any) -> Any:
    """A value as plain JSON (tuples as lists, records as mappings), for ``field.base``."""
    value = _plain(value)
    if isinstance(value, (list, tuple)):
        return [_json(v) for v in value]
    if isinstance(value, dict):
        return {k: _json(v) for k, v in value.items()}
    return value


#: set while :func:`realise` validates the drawn data (whose own validation must not draw again)
_DRAWING: ContextVar[bool] = ContextVar("_DRAWING", default=False)


def realise(scenario) -> None:
    """Draw ``scenario``'s field for its seed in place (the record is frozen: its fields are replaced as a
    validator may). Nothing happens when it draws nothing and records no earlier draw."""
    if _DRAWING.get() or (not scenario.field.draw and not scenario.field.base):
        return
    data = draw_field(scenario.model_dump(), type(scenario))
    token = _DRAWING.set(True)
    try:
        drawn = type(scenario).model_validate(data)
    finally:
        _DRAWING.reset(token)
    for name in type(scenario).model_fields:
        object.__setattr__(scenario, name, getattr(drawn, name))


def profile_problem(points, spec) -> str | None:
    """Why the profile jitter ``spec`` (a ProfileDraw) could put ``points`` (ProfilePoint records or their
    mappings, in time order) out of order, None when no draw can."""
    times = [float(_plain(p)["t_s"]) for p in points]
    for i, (a, b) in enumerate(zip(times, times[1:])):
        # the first point stays; the others move together by the shift, each by its own jitter
        closest = (b - a + spec.shift_s[0] - spec.time_s) if i == 0 else (b - a - 2.0 * spec.time_s)
        if closest <= 0.0:
            return (f"profile points at {a:g} s and {b:g} s are {b - a:g} s apart: a shift of "
                    f"[{spec.shift_s[0]:g}, {spec.shift_s[1]:g}] s and a time jitter of +-{spec.time_s:g} s could "
                    "put them out of order")
    return None
