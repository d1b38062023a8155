"""The perception stage as pure functions over one frame: images -> LiDAR -> cart, height map, impact.

``Perception(scenario, rig)`` precomputes everything that depends only on the rig and the pattern (beam table,
beam-to-pixel tables, the sensor mount). ``lidar(images, frame)`` makes the frame's ranges (decode, resample,
noise, limits); ``perceive(ranges, heading_xy)`` runs the scenario's perception algorithm (``perception.algorithm``,
a plug-in point: perception_proc.protocol; the built-in ``staged`` runs the rim, height map and impact stages).
The participant is a thin shell around these two calls; tests and benchmarks call them directly.

Frames: ranges and ``lidar_points`` are in the sensor frame (X right, Y up, Z forward). The algorithms work in
the *level frame*, the sensor's parent body frame (x forward, y left, z up from flat ground):
``level_from_sensor = mount_transform(mount) @ body_from_camera_axes()``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from cosim.errors import PluginFault
from cosim.scenario.config import Scenario
from cosim.scenario.plugins import load_plugin
from cosim.world.beamtarget import beam_layout
from cosim.world.camera import Rig, beam_directions
from cosim.world.geometry import body_from_camera_axes, mount_transform
from cosim.world.patterns import beam_table, pattern_shape
from perception_proc.cameras.pipeline import CameraPipeline
from perception_proc.estimates.heightmap import HeightMap, grid_shape
from perception_proc.estimates.impact import Impact
from perception_proc.estimates.rim import CartEstimate, border_beams
from perception_proc.estimates.rimfit import CartPrior
from perception_proc.fusion import merge
from perception_proc.lidar.beam_decode import BeamDecoder
from perception_proc.lidar.resample import beam_words, build_table, resample, resample_words
from perception_proc.lidar.resample_offset import build_offset_table, is_offset, resample_offset
from perception_proc.lidar.sensor import apply_noise_and_limits, frame_generator, point_basis, to_points
from perception_proc.protocol import (
    ALGORITHM_POINT,
    PerceptionContext,
    PerceptionInput,
    SensorFrame,
    StageSet,
    check_output,
)

__all__ = ["Perception", "FrameResult", "own_vehicle_box", "OWN_BOX_MARGIN_M"]

#: margin around the sensor's own vehicle box inside which returns are the vehicle itself, m
OWN_BOX_MARGIN_M = 0.3
#: reach along each beam, and samples, used to order the own-box test's axes (_own_box_axes), m
OWN_AXIS_PROBE_M = 20.0
OWN_AXIS_PROBE_STEPS = 41


def own_vehicle_box(scenario: Scenario, parent: str | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """(lo (3,), hi (3,)) m, level frame: the body box of the vehicle carrying the sensor (``parent``, by
    default the LiDAR's; the combine's low, wide header in front is left out: it is far below the rim and never
    over the cart) with :data:`OWN_BOX_MARGIN_M`; None for a sensor on the cart or in the world."""
    if parent is None:
        parent = scenario.lidar.mount.parent
    if parent == "combine":
        c = scenario.combine
        lo, hi = np.array([-c.length_m / 2, -c.width_m / 2, 0.0]), np.array([c.length_m / 2, c.width_m / 2, c.height_m])
    elif parent == "tractor":
        t = scenario.tractor
        lo = np.array([-t.length_m / 2, -t.width_m / 2, 0.0])
        hi = np.array([t.length_m / 2, t.width_m / 2, t.height_m])
    else:
        return None
    return lo - OWN_BOX_MARGIN_M, hi + OWN_BOX_MARGIN_M


def _own_box_axes(box: tuple[np.ndarray, np.ndarray] | None, origin: np.ndarray,
                  directions: np.ndarray) -> tuple[int, int, int]:
    """Level-frame axes (0 x, 1 y, 2 z) in the order the own-vehicle box test should take them: fewest beams
    first whose ray from ``origin`` (3,) m along ``directions`` (N, 3) (level frame) crosses the box's slab on
    that axis within :data:`OWN_AXIS_PROBE_M` (a proxy for the returns the axis keeps; any order gives the
    same set)."""
    if box is None:
        return (0, 1, 2)
    lo, hi = box
    t = np.linspace(0.0, OWN_AXIS_PROBE_M, OWN_AXIS_PROBE_STEPS)
    kept = []
    for a in range(3):
        c = origin[a] + directions[:, a, None] * t                       # (N, steps): the axis along each ray
        kept.append(int(np.count_nonzero(((c >= lo[a]) & (c <= hi[a])).any(axis=1))))
    return tuple(int(a) for a in np.argsort(kept, kind="stable"))


@dataclass
class FrameResult:
    """One frame's perception. ``points`` (N, 4) float32 lidar_points record (sensor frame; None when not
    asked for); ``cart``,
    ``heightmap`` (None when there was no cart), ``impact``; ``timing_ms`` stage name -> wall ms."""

    points: np.ndarray | None
    cart: CartEstimate
    heightmap: HeightMap | None
    impact: Impact
    timing_ms: dict[str, float] = field(default_factory=dict)


class Perception:
    """Per-rig precomputation and the per-frame pure pipeline. ``rig``: the camera rig (None, and unused, with
    ``sensor.method: beam_native``, whose one image is the beams target)."""

    def __init__(self, scenario: Scenario, rig: Rig | None, cameras: Sequence[CameraPipeline] = ()):
        self.scenario = scenario
        self.rig = rig
        #: the camera sensors (perception_proc.cameras.pipeline), in declaration order
        self.cameras = list(cameras)
        sensor = scenario.lidar
        if sensor is not None:
            self.elevation, self.azimuth = beam_table(sensor.pattern)
            self.shape = pattern_shape(sensor.pattern)
            #: ``sensor.method: beam_native``: ranges decoded per beam (perception_proc.lidar.beam_decode), no rig
            self.beams = (BeamDecoder(beam_layout(sensor.pattern), sensor.codec) if sensor.method == "beam_native"
                          else None)
            self.level_from_sensor = mount_transform(sensor.mount) @ body_from_camera_axes()
            #: the body whose frame is the level frame (the primary sensor's parent)
            self.level_parent = sensor.mount.parent
        else:                                        # cameras only: no beams, the first depth camera leads
            self.elevation = self.azimuth = np.zeros(0)
            self.shape, self.beams = None, None
            lead = next((c for c in self.cameras if c.depth_giving), self.cameras[0])
            self.level_from_sensor = lead.parent_from_camera
            self.level_parent = lead.parent
        self.directions = beam_directions(self.elevation, self.azimuth)
        self.offset = sensor is not None and self.beams is None and is_offset(rig)
        if self.beams is not None or sensor is None:
            self.table = None
        elif self.offset:
            self.table = build_offset_table(rig, self.elevation, self.azimuth, self.shape)
        else:
            self.table = build_table(rig, self.directions)
        self.level_directions = self.directions @ self.level_from_sensor[:3, :3].T    # (N, 3) level frame
        #: (3, N) float64 C-contiguous: the level-frame direction components, one row each
        self._level_dir_rows = np.ascontiguousarray(self.level_directions.T)
        #: (N, 4) float64 rows (s, 1): the lidar_points record is this times the range (lidar.point_basis)
        self.point_basis = point_basis(self.directions)
        self.own_box = own_vehicle_box(scenario, self.level_parent)
        self._own_axes = _own_box_axes(self.own_box, self.level_from_sensor[:3, 3], self.level_directions)
        self.grid = grid_shape(scenario.cart, scenario.controller.grid_cell_m)
        self.cell_xy = (scenario.cart.interior_length_m / self.grid[0],
                        scenario.cart.interior_width_m / self.grid[1])
        depth_cams = [c for c in self.cameras if c.depth_giving]
        self.algorithm, self.context = _algorithm(scenario), PerceptionContext(
            scenario, self.grid, self.cell_xy, self.level_from_sensor, None if depth_cams else self.shape,
            _stages(scenario), max((c.typical_sigma_m for c in depth_cams), default=0.0))

    @property
    def n_beams(self) -> int:
        return int(self.directions.shape[0])

    def resample(self, images: Sequence[np.ndarray], out: np.ndarray | None = None) -> np.ndarray:
        """Noise-free ranges (N,) float32 m, NaN where no return, from one depth image per rig camera (rig
        order): decode and resample only, no range limits."""
        codec = self.scenario.lidar.codec
        if self.beams is not None:
            return self.beams.ranges(images, out=out)
        if self.offset:
            r = resample_offset(images, self.table, codec)
            if out is not None:
                out[:] = r
                return out
            return r
        return resample(images, self.table, codec, self.scenario.perception.sampler, out=out)

    def gather(self, images: Sequence[np.ndarray]) -> list[np.ndarray]:
        """The part of :meth:`resample` that reads the images, as copies (cheap: the beams' raw words; with an
        offset mount, the whole resampling); :meth:`resample_gathered` finishes it without the images."""
        if self.beams is not None:
            return self.beams.gather(images)
        if self.offset:
            return [self.resample(images)]
        sampler = self.scenario.perception.sampler
        return [beam_words(img, cam, sampler) for img, cam in zip(images, self.table.cameras)]

    def resample_gathered(self, gathered: list[np.ndarray], out: np.ndarray | None = None) -> np.ndarray:
        """:meth:`resample` from :meth:`gather`'s copies: the same ranges (N,) float32 m."""
        if self.beams is not None:
            return self.beams.decode(gathered, out=out)
        if self.offset:
            if out is None:
                return gathered[0]
            out[:] = gathered[0]
            return out
        return resample_words(gathered, self.table, self.scenario.lidar.codec, self.scenario.perception.sampler,
                              out=out)

    def noisy(self, ranges: np.ndarray, frame: int | None) -> np.ndarray:
        """Apply the noise model (seeded by scenario seed and ``frame``; None: none) and the range limits, in
        place on ``ranges`` (N,) float32; returns it. A model that draws nothing (no range noise, no dropout)
        gets no generator: seeding one costs some 20 us a frame and none of its numbers would be used."""
        sensor = self.scenario.lidar
        if sensor is None:
            return ranges
        draws = sensor.noise.range_sigma_m > 0.0 or sensor.noise.dropout > 0.0
        gen = frame_generator(self.scenario.seed, frame) if frame is not None and draws else None
        return apply_noise_and_limits(ranges, sensor, gen)

    def lidar(self, images: Sequence[np.ndarray], frame: int | None, out: np.ndarray | None = None) -> np.ndarray:
        """The frame's LiDAR ranges (N,) float32 m, NaN invalid: :meth:`resample` then :meth:`noisy`."""
        return self.noisy(self.resample(images, out=out), frame)

    def level_points(self, ranges: np.ndarray) -> np.ndarray:
        """Level-frame points (N, 3) float64 m of the ranges (NaN rows where invalid, and where the return is on
        the sensor's own vehicle: its body box, known like its GNSS pose, is masked out).

        The array is column-major (a transposed (3, N) block): each coordinate ``p[:, k]`` is contiguous, which
        is what the algorithms read."""
        r = np.asarray(ranges, np.float64)
        rows = np.empty((3, r.shape[0]))
        np.multiply(self._level_dir_rows, r, out=rows)
        rows += self.level_from_sensor[:3, 3:4]
        if self.own_box is not None:
            lo, hi = self.own_box
            with np.errstate(invalid="ignore"):
                # the box test axis by axis, the most selective axis first (the one that keeps the fewest
                # returns of the beams' level-frame directions; the same set in any order)
                a0, a1, a2 = self._own_axes
                c = rows[a0]
                own = np.flatnonzero((c >= lo[a0]) & (c <= hi[a0]))
                for a in (a1, a2):
                    c = rows[a][own]
                    own = own[(c >= lo[a]) & (c <= hi[a])]
            rows[:, own] = np.nan
        return rows.T

    def points(self, ranges: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The ``lidar_points`` record (N, 4) float32 (sensor frame x, y, z, range; m) of the ranges, written
        into ``out`` (e.g. the shared block) when given."""
        return to_points(self.point_basis, ranges, out=out)

    def perceive(self, ranges: np.ndarray, heading_xy=(1.0, 0.0), points_out: np.ndarray | None = None,
                 heights_out: np.ndarray | None = None, with_points: bool = True, frame: int = -1,
                 cameras: Sequence[tuple[SensorFrame, np.ndarray]] = (),
                 level_from_parent: np.ndarray | None = None, cart_prior: CartPrior | None = None) -> FrameResult:
        """Cart, height map and impact from the frame's ranges (N,) float32 (the LiDAR's; (0,) without one) and
        the ``cameras``' frames with their border flags [(SensorFrame, (M,) uint8)], merged in the level frame.
        ``heading_xy``: the towing direction in the level frame. ``points_out`` (N, 4) / ``heights_out``
        (nx, ny): optional destinations. ``with_points`` False leaves the ``lidar_points`` record out
        (``FrameResult.points`` is None): a caller that writes it straight into shared memory uses
        :meth:`points`. ``frame``: named in a plug-in's fault. ``level_from_parent`` (4, 4): this frame's level
        frame on uneven ground (perception_proc.leveling; None: the parent's body frame). ``cart_prior``: where
        Machine Sync puts the cart in that level frame (``PerceptionInput.cart_prior``)."""
        t0 = time.perf_counter()
        pts = self.points(ranges, out=points_out) if with_points or points_out is not None else None
        lvl = self.level_points(ranges)
        border = border_beams(ranges, self.shape)
        frames = {f.name: f for f, _ in cameras}
        depth = [(f, b) for f, b in cameras if len(f.points)]
        merged, all_ranges = lvl, ranges
        if depth:                                   # in the parent's body frame, where the own-vehicle box is
            merged, all_ranges, border = merge([lvl] + [f.points for f, _ in depth],
                                               [ranges] + [f.ranges for f, _ in depth],
                                               [border] + [b for _, b in depth], self.own_box)
        context = self.context
        if level_from_parent is not None:
            rot, shift = level_from_parent[:3, :3], level_from_parent[:3, 3]
            lvl = lvl @ rot.T + shift
            merged = merged @ rot.T + shift if depth else lvl
            context = replace(context, level_from_sensor=level_from_parent @ self.level_from_sensor)
            frames = {n: replace(f, points=f.points @ rot.T + shift, level_from_camera=None
                                 if f.level_from_camera is None else level_from_parent @ f.level_from_camera)
                      for n, f in frames.items()}
        sensors: dict[str, SensorFrame] = {}
        lidar_name = self.scenario.lidar_name
        if lidar_name is not None:
            sensors[lidar_name] = SensorFrame(lidar_name, "lidar", frame, lvl, ranges)
        sensors.update(frames)
        t1 = time.perf_counter()
        inp = PerceptionInput(frame, all_ranges, merged, border, heading_xy, heights_out, sensors, cart_prior)
        ref = self.scenario.perception.algorithm
        try:
            out = check_output(self.algorithm(context, inp), self.grid, ref)
        except PluginFault as e:
            raise e.at_frame(frame) from e.__cause__
        except Exception as e:  # noqa: BLE001 - the algorithm's failure ends the run with its name and cause
            raise PluginFault(ref, ALGORITHM_POINT, f"raised {type(e).__name__}: {e}", frame) from e
        hm = out.heightmap
        if heights_out is not None and (hm is None or hm.heights is not heights_out):
            heights_out[...] = np.nan if hm is None else hm.heights
        return FrameResult(pts, out.cart, hm, out.impact, {"points": 1e3 * (t1 - t0), **out.timing_ms})


def _algorithm(s: Scenario):
    """The scenario's perception algorithm (``perception.algorithm``), loaded."""
    return load_plugin("perception", s.perception.algorithm, base_dir=s.plugin_dir or None,
                       options=s.perception.algorithm_options)


def _stages(s: Scenario) -> StageSet:
    """The scenario's perception stages (``perception.stages``), loaded."""
    st = s.perception.stages
    refs = {"rim": st.rim, "heightmap": st.heightmap, "impact": st.impact}
    return StageSet(*(load_plugin(f"perception.{k}", r, base_dir=s.plugin_dir or None,
                                  options=getattr(st, f"{k}_options")) for k, r in refs.items()), refs)

