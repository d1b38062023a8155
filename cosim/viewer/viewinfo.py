"""What the dashboard knows of a run's scenario: the cart's shape, the depth-giving sensors' mounts, the fill target.

The point-cloud panels place every sensor's points in the cart frame with these and the machines' poses of the
snapshot (cosim.viewer.clouds); the fullness bars take their band around the target from them
(cosim.viewer.fill). A :class:`ViewInfo` is plain numbers, so it travels as a dict: to the observer process
(``launch.py run --viewer``), from a run directory's ``scenario.yaml`` (``launch.py view``), and in a recording's
``view`` metadata record (``launch.py replay``; docs/viewer.md).

Frames: ``SensorMount.parent_from_sensor`` (4, 4) is the sensor in its parent body's frame (body axes x forward,
y left, z up, m) with the sensor's axes those of its points block, camera axes X right, Y up, Z forward
(``mount_transform(mount) @ body_from_camera_axes()``, docs/CONTRACTS.md). The cart's dimensions are those of
``cart:`` (m).
"""
from __future__ import annotations

import functools
import json
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

__all__ = ["CartShape", "SensorMount", "ViewInfo", "METADATA_NAME", "default_fill"]

#: the recording's metadata record that holds a ViewInfo (key ``json``)
METADATA_NAME = "view"
#: the point block of the LiDAR (perception_proc.blocks)
LIDAR_POINTS = "lidar_points"


@dataclass(frozen=True)
class CartShape:
    """The cart's interior, walls and rim (``cart:``), m; the names are the scenario's, so the frame helpers of
    cosim.world.geometry take it as they take the scenario's record."""

    interior_length_m: float
    interior_width_m: float
    interior_depth_m: float
    floor_height_m: float
    wall_thickness_m: float
    rim_width_m: float
    rim_height_m: float

    @property
    def rim_above_floor_m(self) -> float:
        """Height of the rim top above the cart floor, m."""
        return self.interior_depth_m + self.rim_height_m

    @property
    def outer_m(self) -> float:
        """How far the walls or the rim reach outside the interior, m (the wider of the two)."""
        return max(self.wall_thickness_m, self.rim_width_m)


@dataclass(frozen=True)
class SensorMount:
    """One depth-giving sensor: its ``name``, ``kind`` (lidar, depth_camera, stereo_camera), the ``block`` of its
    points ((N, 4) float32 rows X, Y, Z, range in its camera axes), its ``parent`` body (combine, tractor, cart,
    world) and ``parent_from_sensor`` (16 floats, row-major (4, 4))."""

    name: str
    kind: str
    block: str
    parent: str
    parent_from_sensor: tuple[float, ...]

    @property
    def matrix(self) -> np.ndarray:
        """``parent_from_sensor`` as a (4, 4) float64 array."""
        return np.asarray(self.parent_from_sensor, np.float64).reshape(4, 4)


@dataclass(frozen=True)
class ViewInfo:
    """The cart, the depth-giving sensors in declaration order (the LiDAR's points first among equals: its
    block is ``lidar_points``), and the fill target with the outcome's tolerances (m)."""

    cart: CartShape
    sensors: tuple[SensorMount, ...]
    target_fill_m: float
    underfill_tolerance_m: float
    overfill_tolerance_m: float

    @property
    def size_m(self) -> tuple[float, float]:
        """(interior length, interior width) of the cart, m."""
        return self.cart.interior_length_m, self.cart.interior_width_m

    @property
    def fill_band(self) -> tuple[float, float]:
        """(lowest, highest) fullness at the target within the outcome's tolerances (fractions of the target)."""
        return fill_band(self.target_fill_m, self.underfill_tolerance_m, self.overfill_tolerance_m)

    @classmethod
    def of(cls, scenario) -> "ViewInfo":
        """The ViewInfo of a :class:`cosim.scenario.config.Scenario`."""
        from cosim.world.sensors import camera_block, level_from_sensor

        c = scenario.cart
        cart = CartShape(*(float(getattr(c, f.name)) for f in fields(CartShape)))
        sensors = []
        for name, s in scenario.sensor_set.items():
            if s.kind == "lidar":
                sensor, block = scenario.lidar, LIDAR_POINTS
            elif s.kind in ("depth_camera", "stereo_camera"):
                sensor, block = s, camera_block(name, "points")
            else:
                continue                                   # an RGB camera gives no points
            m = level_from_sensor(sensor)
            sensors.append(SensorMount(name, s.kind, block, sensor.mount.parent, tuple(float(v) for v in m.ravel())))
        o = scenario.outcome
        return cls(cart, tuple(sensors), float(scenario.controller.target_fill_m), float(o.underfill_tolerance_m),
                   float(o.overfill_tolerance_m))

    def to_dict(self) -> dict:
        """Plain lists and numbers (JSON and pickle safe)."""
        d = asdict(self)
        d["sensors"] = [dict(s, parent_from_sensor=list(s["parent_from_sensor"])) for s in d["sensors"]]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ViewInfo":
        """The ViewInfo of :meth:`to_dict`'s dict. Raises ValueError when a key is missing or a number is not
        finite."""
        try:
            cart = CartShape(**{f.name: float(d["cart"][f.name]) for f in fields(CartShape)})
            sensors = tuple(SensorMount(str(s["name"]), str(s["kind"]), str(s["block"]), str(s["parent"]),
                                        tuple(float(v) for v in s["parent_from_sensor"])) for s in d["sensors"])
            view = cls(cart, sensors, float(d["target_fill_m"]), float(d["underfill_tolerance_m"]),
                       float(d["overfill_tolerance_m"]))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"not a view record ({type(exc).__name__}: {exc})") from None
        numbers = [*(getattr(cart, f.name) for f in fields(CartShape)), view.target_fill_m,
                   view.underfill_tolerance_m, view.overfill_tolerance_m,
                   *(v for s in sensors for v in s.parent_from_sensor)]
        if not all(math.isfinite(v) for v in numbers) or any(len(s.parent_from_sensor) != 16 for s in sensors):
            raise ValueError("a view record needs finite numbers and 16 per sensor pose")
        return view

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    @classmethod
    def from_json(cls, text: str) -> "ViewInfo":
        try:
            return cls.from_dict(json.loads(text))
        except json.JSONDecodeError as exc:
            raise ValueError(f"not a view record: {exc}") from None

    @classmethod
    def from_scenario_yaml(cls, path: Path) -> "ViewInfo | None":
        """The ViewInfo of a run directory's resolved ``scenario.yaml``; None when it is missing or unreadable."""
        import yaml
        from pydantic import ValidationError

        from cosim.scenario.config import Scenario

        try:
            doc = yaml.safe_load(Path(path).read_text())
            return cls.of(Scenario.model_validate_json(json.dumps(doc)))
        except (OSError, yaml.YAMLError, ValidationError, ValueError, TypeError):
            return None


def fill_band(target_m: float, under_m: float, over_m: float) -> tuple[float, float]:
    """(lowest, highest) fullness (height / target) within ``under_m`` below and ``over_m`` above ``target_m``."""
    return 1.0 - under_m / target_m, 1.0 + over_m / target_m


@functools.lru_cache(maxsize=1)
def default_fill() -> tuple[float, float]:
    """The fill band of the scenario records' defaults (target_fill_m, the outcome's tolerances): the fullness
    bars' band when the run's scenario is unknown."""
    from cosim.scenario.config import Controller, Outcome

    return fill_band(Controller().target_fill_m, Outcome().underfill_tolerance_m, Outcome().overfill_tolerance_m)
