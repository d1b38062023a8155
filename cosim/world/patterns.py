"""LiDAR beam patterns as data: a table of (elevation, azimuth) per beam.

Angles are in the LiDAR (sensor) frame, which is the camera-convention frame X right, Y up, Z forward
(``cosim.world.camera``): elevation is the angle above the X-Z plane (towards +Y), azimuth is measured from +Z
(forward) towards the LEFT (-X), so ``cosim.world.camera.beam_directions(elevation, azimuth)`` gives the unit beam
direction and ``cosim.world.camera.paper_angles`` the paper's (theta, phi).

Presets (``cosim.scenario.config.Pattern.preset``):

* ``grid`` - uniform in elevation and azimuth over the record's closed ranges (both ends included), with
  ``elevation_count`` x ``azimuth_count`` beams.
* ``honeycomb`` - a Honeycomb-like unit: a fixed 95 deg vertical field of view centred on the horizon, rings
  denser near the horizon than at the top and bottom (spacing ratio :data:`HONEYCOMB_DENSITY_RATIO`),
  ``elevation_count`` rings, azimuth window and count from the record. Such a unit has a minimum range of
  zero; the range limits themselves live in ``Sensor.range_min_m`` / ``range_max_m``.
* ``csv`` - a user table: a header line, then one ``elevation_deg, azimuth_deg`` row per beam.

Beam order for the presets is row-major like an image: rows from the top elevation down, columns from the
leftmost azimuth (largest) to the rightmost, so ``reshape(elevation_count, azimuth_count)`` is a range image.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from cosim.scenario.config import Pattern

__all__ = [
    "PatternError", "beam_table", "grid_table", "honeycomb_elevations", "load_csv_table", "validate_table",
    "pattern_shape", "HONEYCOMB_VFOV_DEG", "HONEYCOMB_DENSITY_RATIO", "HONEYCOMB_RANGE_MIN_M",
]

#: vertical field of view of the Honeycomb-like preset, deg
HONEYCOMB_VFOV_DEG = 95.0
#: ring spacing at the edge of the field of view over the spacing at the horizon (dimensionless, >= 1)
HONEYCOMB_DENSITY_RATIO = 4.0
#: minimum range of a Honeycomb-like unit, m
HONEYCOMB_RANGE_MIN_M = 0.0
#: largest |azimuth| accepted in a table, deg (one full turn either way)
MAX_ABS_AZIMUTH_DEG = 360.0


class PatternError(ValueError):
    """A beam table is malformed (non-finite angle, elevation beyond +-90 deg, empty, unreadable CSV)."""


def validate_table(elevation_rad: np.ndarray, azimuth_rad: np.ndarray, source: str = "pattern") -> None:
    """Raise :class:`PatternError` unless both arrays are 1-D, equally long, non-empty, finite and in range.

    ``elevation_rad`` and ``azimuth_rad``: (N,) float64, rad, sensor frame.
    """
    e = np.asarray(elevation_rad)
    a = np.asarray(azimuth_rad)
    if e.ndim != 1 or a.ndim != 1 or e.shape != a.shape:
        raise PatternError(f"{source}: elevation and azimuth must be 1-D of equal length, got {e.shape}, {a.shape}")
    if e.size == 0:
        raise PatternError(f"{source}: the beam table is empty")
    bad = ~(np.isfinite(e) & np.isfinite(a))
    if bad.any():
        raise PatternError(f"{source}: beam {int(np.argmax(bad))} has a non-finite angle")
    lim = math.pi / 2.0 + 1e-12
    out = np.abs(e) > lim
    if out.any():
        i = int(np.argmax(out))
        raise PatternError(
            f"{source}: beam {i} elevation {math.degrees(e[i]):.6g} deg lies outside [-90, 90] deg"
        )
    far = np.abs(a) > math.radians(MAX_ABS_AZIMUTH_DEG) + 1e-12
    if far.any():
        i = int(np.argmax(far))
        raise PatternError(f"{source}: beam {i} azimuth {math.degrees(a[i]):.6g} deg lies outside +-360 deg")


def _span(lo_deg: float, hi_deg: float, n: int) -> np.ndarray:
    """n values uniform over [lo, hi] deg inclusive (the midpoint when n == 1), returned in rad."""
    if n == 1:
        return np.array([math.radians(0.5 * (lo_deg + hi_deg))])
    return np.radians(np.linspace(lo_deg, hi_deg, n))


def _outer(elev_rows: np.ndarray, az_cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ee, aa = np.meshgrid(elev_rows, az_cols, indexing="ij")
    return ee.ravel().astype(np.float64), aa.ravel().astype(np.float64)


def grid_table(pattern: Pattern) -> tuple[np.ndarray, np.ndarray]:
    """Uniform grid over the record's elevation and azimuth ranges; (N,) float64 rad each, image order."""
    elev = _span(pattern.elevation_min_deg, pattern.elevation_max_deg, pattern.elevation_count)[::-1]
    az = _span(pattern.azimuth_min_deg, pattern.azimuth_max_deg, pattern.azimuth_count)[::-1]
    return _outer(elev, az)


def honeycomb_elevations(count: int, vfov_deg: float = HONEYCOMB_VFOV_DEG,
                         density_ratio: float = HONEYCOMB_DENSITY_RATIO) -> np.ndarray:
    """Ring elevations (count,) float64 rad, top first, over +-vfov/2, denser near the horizon.

    Map s uniform in [-1, 1] through e(s) = E (a s + (1 - a) s^3) with E = vfov/2; de/ds is a E at the horizon
    and (3 - 2a) E at the edges, so a = 3 / (2 + density_ratio) gives that spacing ratio. e is monotonic.
    """
    if count < 1:
        raise PatternError(f"honeycomb: elevation_count must be >= 1, got {count}")
    if not 1.0 <= density_ratio <= 1e3:
        raise PatternError(f"honeycomb: density ratio must lie in [1, 1000], got {density_ratio}")
    a = 3.0 / (2.0 + density_ratio)
    half = math.radians(vfov_deg) / 2.0
    s = np.linspace(1.0, -1.0, count) if count > 1 else np.zeros(1)
    return half * (a * s + (1.0 - a) * s**3)


def load_csv_table(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Read a CSV beam table (header line, then ``elevation_deg, azimuth_deg`` rows); (N,) float64 rad each."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise PatternError(f"{p}: cannot read the beam table ({exc.strerror})") from exc
    except UnicodeDecodeError as exc:
        raise PatternError(f"{p}: the beam table is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    try:
        rows = list(csv.reader(text.splitlines()))
    except csv.Error as exc:                       # a NUL byte, a broken quote
        raise PatternError(f"{p}: not a CSV table: {exc}") from None
    if not rows:
        raise PatternError(f"{p}: empty file, expected a header line and elevation_deg, azimuth_deg rows")
    header = [h.strip().lower() for h in rows[0]]
    if header[:2] != ["elevation_deg", "azimuth_deg"]:
        raise PatternError(f"{p}:1: header must start with 'elevation_deg,azimuth_deg', got {rows[0]!r}")
    elev: list[float] = []
    az: list[float] = []
    for lineno, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) < 2:
            raise PatternError(f"{p}:{lineno}: expected 2 columns, got {len(row)}")
        try:
            elev.append(float(row[0]))
            az.append(float(row[1]))
        except ValueError as exc:
            raise PatternError(f"{p}:{lineno}: not a number: {row[:2]!r}") from exc
    e = np.radians(np.asarray(elev, dtype=np.float64))
    a = np.radians(np.asarray(az, dtype=np.float64))
    validate_table(e, a, source=str(p))
    return e, a


def pattern_shape(pattern: Pattern) -> tuple[int, int] | None:
    """(rows, cols) of the range image for the grid presets, None for a CSV table (no implied layout)."""
    if pattern.preset == "csv":
        return None
    return pattern.elevation_count, pattern.azimuth_count


def beam_table(pattern: Pattern) -> tuple[np.ndarray, np.ndarray]:
    """The pattern's beams: (elevation_rad (N,), azimuth_rad (N,)) float64, sensor frame, validated."""
    if pattern.preset == "grid":
        e, a = grid_table(pattern)
    elif pattern.preset == "honeycomb":
        elev = honeycomb_elevations(pattern.elevation_count)
        az = _span(pattern.azimuth_min_deg, pattern.azimuth_max_deg, pattern.azimuth_count)[::-1]
        e, a = _outer(elev, az)
    elif pattern.preset == "csv":
        assert pattern.csv_file is not None  # the record's validator guarantees it
        return load_csv_table(pattern.csv_file)
    else:  # pragma: no cover - the record's Literal forbids it
        raise PatternError(f"unknown pattern preset {pattern.preset!r}")
    validate_table(e, a, source=f"preset {pattern.preset!r}")
    return e, a
