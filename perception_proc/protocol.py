"""The perception plug-in points: the whole per-frame algorithm (``perception.algorithm``) and its three stages
(``perception.stages.rim`` / ``.heightmap`` / ``.impact``), as functions of a per-run context and the frame.

Signatures (all plain callables; built-ins in :mod:`perception_proc.staged`):

* algorithm: ``algorithm(ctx: PerceptionContext, inp: PerceptionInput) -> PerceptionOutput``
* rim stage: ``rim(ctx, inp) -> CartEstimate`` (perception_proc.estimates.rim): the cart's rim corners and pose;
* height map stage: ``heightmap(ctx, inp, cart) -> HeightMap`` (perception_proc.estimates.heightmap): grain heights on
  the controller grid, in the frame of the cart found;
* impact stage: ``impact(ctx, inp, cart, heightmap) -> Impact`` (perception_proc.estimates.impact): where the stream
  lands, grid frame.

Frames: ``inp.points`` are in the **level frame** (the sensor's parent body frame: x forward, y left, z up from
flat ground, m); the cart grid frame has its origin at the cart's front-left inner floor corner, x to the rear
along the cart, y across, z up (``cart.level_from_grid`` (4, 4) maps grid to level). Heights are m above the
cart floor on the controller grid ``ctx.grid`` = (nx, ny) cells of ``ctx.cell_xy`` = (dx, dy) m, cell (i, j)
covering grid x in [i dx, (i + 1) dx); NaN where a cell has no answer (holes are allowed and expected).

Every sensor's own frame (docs/cameras.md): ``inp.sensors`` maps each sensor's name to a :class:`SensorFrame`
with its ``points`` (N, 3) in the level frame and, for cameras, its images (``rgb``, ``depth_m``, ``labels``),
intrinsics ``K`` and pose ``level_from_camera``. ``inp.points`` (what the built-in stages use) holds the
points of every depth-giving sensor merged in the level frame; with one LiDAR it is that LiDAR's.

What comes back is checked (:func:`check_output`): a wrong type, a height map of the wrong shape or with
infinite heights, a valid cart or impact with non-finite coordinates ends the run with a
:class:`cosim.errors.PluginFault` naming the plug-in, the frame and the cause.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from cosim.errors import PluginFault
from cosim.scenario.config import Scenario
from perception_proc.estimates.heightmap import HeightMap
from perception_proc.estimates.impact import Impact
from perception_proc.estimates.rim import CartEstimate
from perception_proc.estimates.rimfit import CartPrior

__all__ = ["PerceptionContext", "PerceptionInput", "PerceptionOutput", "SensorFrame", "StageSet", "ALGORITHM_POINT",
           "STAGE_POINTS", "check_cart", "check_heightmap", "check_impact", "check_output"]

#: the scenario keys of the plug-in points (named in faults)
ALGORITHM_POINT = "perception.algorithm"
STAGE_POINTS = {"rim": "perception.stages.rim", "heightmap": "perception.stages.heightmap",
                "impact": "perception.stages.impact"}


@dataclass(frozen=True)
class StageSet:
    """The loaded stages (``perception.stages``) and their references, for algorithms that reuse them."""

    rim: Callable
    heightmap: Callable
    impact: Callable
    refs: dict[str, str]


@dataclass(frozen=True)
class PerceptionContext:
    """What stays the same over a run: the ``scenario`` (cart dimensions ``scenario.cart``, noise
    ``scenario.lidar.noise.range_sigma_m``, ``scenario.perception`` knobs); the controller ``grid`` (nx, ny)
    and its ``cell_xy`` (dx, dy) m; ``level_from_sensor`` (4, 4), the sensor pose in the level frame (the
    LiDAR's, else the first depth-giving camera's); ``beam_shape`` (rows, columns) of the beam pattern when it
    is a grid and the LiDAR is the only depth-giving sensor, else None; the loaded ``stages``."""

    scenario: Scenario
    grid: tuple[int, int]
    cell_xy: tuple[float, float]
    level_from_sensor: np.ndarray
    beam_shape: tuple[int, int] | None
    stages: StageSet
    #: a typical depth 1-sigma of the cameras at their working distance (m; 0 without depth cameras)
    camera_sigma_m: float = 0.0

    @property
    def noise_sigma_m(self) -> float:
        """The range noise 1-sigma, m: the LiDAR's, or the cameras' typical one when it is larger."""
        lidar = self.scenario.lidar
        return max(lidar.noise.range_sigma_m if lidar is not None else 0.0, self.camera_sigma_m)


@dataclass(frozen=True)
class SensorFrame:
    """One sensor's data of the frame (``PerceptionInput.sensors[name]``). Level frame as above.

    * ``name``, ``kind`` (``lidar``, ``depth_camera``, ``stereo_camera``, ``rgb_camera``); ``frame``: the ring
      frame of its latest image (a camera with ``every_frames`` > 1 keeps it between its frames);
    * ``points`` (N, 3) float64 m, level frame, NaN rows invalid: the LiDAR's returns, or a depth-giving
      camera's pixels back-projected (every ``points_stride``-th pixel along each axis); (0, 3) for an RGB
      camera; ``ranges`` (N,) float32 m, each point's distance from its sensor (NaN invalid);
    * cameras only (None for the LiDAR): ``rgb`` (H, W, 3) uint8 (a stereo pair's left image; None where the
      camera renders no colour), ``depth_m`` (H, W) float32 planar depth m, NaN invalid (the depth camera's
      noisy depth, the stereo matcher's; None for an RGB camera), ``labels`` (H, W) uint8 per-pixel labels
      (cosim.world.labels) when the camera has ``labels: true``, ``right`` (H, W, 3) uint8 a stereo pair's
      right image; ``K`` (3, 3) the pinhole (u right, v down, pixel centres at half-integers);
      ``level_from_camera`` (4, 4) the camera (X right, Y up, Z forward) in the level frame.
    """

    name: str
    kind: str
    frame: int
    points: np.ndarray
    ranges: np.ndarray
    rgb: np.ndarray | None = None
    depth_m: np.ndarray | None = None
    labels: np.ndarray | None = None
    right: np.ndarray | None = None
    K: np.ndarray | None = None
    level_from_camera: np.ndarray | None = None


@dataclass(frozen=True)
class PerceptionInput:
    """One frame: ``frame``; ``ranges`` (N,) float32 m per beam, NaN no return; ``points`` (N, 3) float64 m, the
    returns in the level frame, NaN rows invalid (and where the return is on the sensor's own vehicle), stored
    column-major (``points[:, k]`` contiguous); ``border`` (N,) uint8 beam flags (perception_proc.estimates.rim
    ``FOV_EDGE`` / ``OCCLUDED``); the pose hint ``heading_xy``: the towing direction in the level frame (unit
    (x, y)); ``heights_out``: an optional (nx, ny) float32 destination a height map stage may fill;
    ``sensors``: every sensor's :class:`SensorFrame` by name. With several depth-giving sensors, ``ranges``,
    ``points`` and ``border`` hold theirs one after the other, in declaration order. ``cart_prior``: where
    Machine Sync puts the cart in the level frame, with the pose gate's reach
    (perception_proc.estimates.rimfit.CartPrior; None when the frame has no cart pose or the gate is off)."""

    frame: int
    ranges: np.ndarray
    points: np.ndarray
    border: np.ndarray
    heading_xy: tuple[float, float]
    heights_out: np.ndarray | None = None
    sensors: Mapping[str, SensorFrame] = field(default_factory=dict)
    cart_prior: CartPrior | None = None


@dataclass
class PerceptionOutput:
    """An algorithm's answer: ``cart``; ``heightmap`` (None: no map this frame, all cells unknown);
    ``impact``; ``timing_ms`` stage name -> wall ms (optional; 'cart', 'heightmap', 'impact' are reported)."""

    cart: CartEstimate
    heightmap: HeightMap | None
    impact: Impact
    timing_ms: dict[str, float] = field(default_factory=dict)


def _finite(a) -> bool:
    return isinstance(a, np.ndarray) and bool(np.isfinite(a).all())


def check_cart(cart: object, ref: str, point: str) -> CartEstimate:
    """``cart`` if it is a CartEstimate whose corners (4, 3) and pose (4, 4) are finite when valid."""
    if not isinstance(cart, CartEstimate):
        raise PluginFault(ref, point, f"returned {type(cart).__name__} as the cart, expected CartEstimate")
    if cart.valid and not (_finite(cart.corners) and cart.corners.shape == (4, 3)
                           and _finite(cart.level_from_grid) and cart.level_from_grid.shape == (4, 4)):
        raise PluginFault(ref, point, "a valid cart needs finite corners (4, 3) and level_from_grid (4, 4)")
    return cart


def check_heightmap(hm: object, grid: tuple[int, int], ref: str, point: str) -> HeightMap:
    """``hm`` if it is a HeightMap whose heights are (nx, ny) floats, each finite or NaN."""
    if not isinstance(hm, HeightMap):
        raise PluginFault(ref, point, f"returned {type(hm).__name__} as the height map, expected HeightMap")
    h = hm.heights
    if not isinstance(h, np.ndarray) or h.shape != tuple(grid) or h.dtype.kind != "f":
        what = f"{h.shape} {h.dtype}" if isinstance(h, np.ndarray) else type(h).__name__
        raise PluginFault(ref, point, f"height map heights must be a {tuple(grid)} float array (the controller "
                          f"grid), got {what}")
    if np.isinf(h).any():
        raise PluginFault(ref, point, "height map has infinite heights (NaN marks a cell without an answer)")
    if not (isinstance(hm.coverage, (float, int)) and 0.0 <= hm.coverage <= 1.0):
        raise PluginFault(ref, point, f"coverage must be a fraction in [0, 1], got {hm.coverage!r}")
    return hm


def check_impact(imp: object, ref: str, point: str) -> Impact:
    """``imp`` if it is an Impact whose point (3,) is finite when valid."""
    if not isinstance(imp, Impact):
        raise PluginFault(ref, point, f"returned {type(imp).__name__} as the impact, expected Impact")
    if imp.valid and not (_finite(imp.xyz) and imp.xyz.shape == (3,)):
        raise PluginFault(ref, point, f"a valid impact needs a finite (3,) point, got {imp.xyz!r}")
    return imp


def check_output(out: object, grid: tuple[int, int], ref: str) -> PerceptionOutput:
    """``out`` if it is a valid PerceptionOutput for the controller ``grid`` (PluginFault otherwise)."""
    if not isinstance(out, PerceptionOutput):
        raise PluginFault(ref, ALGORITHM_POINT, f"returned {type(out).__name__}, expected PerceptionOutput")
    check_cart(out.cart, ref, ALGORITHM_POINT)
    if out.heightmap is not None:
        check_heightmap(out.heightmap, grid, ref, ALGORITHM_POINT)
    check_impact(out.impact, ref, ALGORITHM_POINT)
    if not all(isinstance(v, (float, int)) and not math.isinf(v) for v in out.timing_ms.values()):
        raise PluginFault(ref, ALGORITHM_POINT, "timing_ms values must be finite numbers (ms)")
    return out
