"""The perception participant: a thin shell around :class:`perception_proc.pipeline.Perception`.

``start`` plans the rig (``cosim.world.rig.plan_rig``, the same pure function the renderer and the schema
use) and precomputes the beam tables. ``step(frame)`` checks that every ``<cam>_depth`` image carries the
frame, makes the LiDAR ranges (decode, resample, noise seeded from ``scenario.seed`` and the frame), runs
the cart / height map / impact algorithms and writes ``perc_state``, ``heightmap_perceived`` and
``lidar_points`` under the seqlock (the points straight into the shared block). Every
``perception.accuracy_every_frames`` frames it also compares with the truth (``dyn_state``,
``heightmap_truth``, ``stream``) through an exact ray cast of ``perception.accuracy_beams`` beams (a seeded
stratified sample, ``accuracy.sample_beams``; 0: all); that happens after the outputs are computed, so truth
never feeds an estimate.

The sensor's parent pose (the combine's GNSS) comes from ``dyn_state``; it places the perceived cart in the
world and orients the towing direction. The cart itself is found from the points alone; on uneven ground the
points are first put in a level frame on the cart's ground plane from both machines' attitude and height
(perception_proc.leveling).

Overlap (``cosim.runtime.participant.perception_overlaps``, on by default when the latency allows): ``step(frame)``
publishes the outputs kept from the previous frame, copies what it reads from the dynamics blocks and the
raw image words its beams need (``Perception.gather``: the only read of the images) and returns the rest (noise, algorithms, accuracy) as a callable that the
ring runs after passing the token on; the outputs go into private buffers and are published at the next turn
or by ``flush()``. The numbers are the same as without overlap.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

import perception_proc.accuracy.stage as acc
from cosim.errors import FrameMismatch
from cosim.runtime.participant import perception_overlaps
from cosim.scenario.config import Scenario
from cosim.world.beamtarget import BEAMS_DEPTH_BLOCK
from cosim.world.camera import Rig
from cosim.world.geometry import invert
from cosim.world.sensors import world_from_parent
from perception_proc.atmosphere.lidar import lidar_atmosphere
from perception_proc.blocks import ACCURACY_FIELDS, HEIGHTS_BLOCK, POINTS_BLOCK, STATE_BLOCK, WRITER, sensor_state_block
from perception_proc.cameras.expected import error_basis
from perception_proc.cameras.sensors import PerceptionCameras
from perception_proc.estimates.posegate import level_prior, pose_gate
from perception_proc.leveling import level_from_parent
from perception_proc.pipeline import FrameResult, Perception
from perception_proc.selection import CameraFit, FusionSelection, judge
from perception_proc.sensor_report import record_of, sensor_values

if TYPE_CHECKING:
    from shm_schema import Segment

__all__ = ["PerceptionParticipant", "create"]

_MS_PER_S = 1e3


class PerceptionParticipant:
    """Ring member ``perception``. Create with :func:`create`; the ring calls start, step, close.

    ``rig``: optional rig to use instead of ``cosim.world.rig.plan_rig(scenario)`` (tests, studies)."""

    name = WRITER

    def __init__(self, scenario: Scenario, rig: Rig | None = None):
        self.scenario = scenario
        self._rig = rig
        self.pipeline: Perception | None = None
        self.segment: "Segment | None" = None
        self.last: FrameResult | None = None
        #: publish one turn late, overlapping the next frame (cosim.runtime.participant)
        self.deferred = perception_overlaps(scenario)
        self._pending: _Outputs | None = None
        self._atmosphere = None

    # -- contract -------------------------------------------------------------------------------------------
    def start(self, segment: "Segment") -> None:
        """Bind views and precompute the beam-to-pixel tables and the cameras' pipelines."""
        rig, lidar = self._rig, self.scenario.lidar
        if rig is None and lidar is not None and lidar.method == "camera_rig":
            from cosim.world.rig import plan_rig

            rig = plan_rig(self.scenario)
        self.cameras = PerceptionCameras(self.scenario)
        self.pipeline = Perception(self.scenario, rig, self.cameras.pipes)
        self.cameras.level_parent = self.pipeline.level_parent
        self.selection = FusionSelection(has_lidar=lidar is not None)
        self._basis = {n: error_basis(c) for n, c in self.scenario.cameras.items()}
        self._atmosphere = lidar_atmosphere(self.scenario, self.pipeline.directions) if lidar is not None else None
        self._images = []
        for name, want in _image_blocks(self.pipeline, rig):
            if not segment.has(name):
                raise KeyError(f"perception needs block {name!r} (written by the renderer), absent from this run")
            img = segment.view(name)
            if img.shape != want:
                raise ValueError(f"block {name!r} has shape {img.shape}, the rig expects {want}")
            self._images.append((name, img))
        for name in (STATE_BLOCK, HEIGHTS_BLOCK) + ((POINTS_BLOCK,) if lidar is not None else ()):
            segment.view(name)                          # KeyError naming the missing block
        if lidar is not None and segment.view(POINTS_BLOCK).shape[0] != self.pipeline.n_beams:
            raise ValueError(f"{POINTS_BLOCK} has {segment.view(POINTS_BLOCK).shape[0]} rows, the pattern "
                             f"{self.pipeline.n_beams} beams")
        self.cameras.start(segment)
        self._sensor_blocks = {n: sensor_state_block(n) for n in self.scenario.depth_sensors} \
            if self.scenario.sensors else {}
        for block in self._sensor_blocks.values():
            segment.view(block)
        self._state = segment.view("dyn_state") if segment.has("dyn_state") else None
        self._state_names = self._state.array.dtype.names if self._state is not None else ()
        self._ranges = np.empty(self.pipeline.n_beams, np.float32)
        record = np.zeros((), segment.view(STATE_BLOCK).array.dtype)
        points = np.empty_like(segment.view(POINTS_BLOCK)) if lidar is not None else np.zeros((0, 4), np.float32)
        self._out = _Outputs(points, np.empty_like(segment.view(HEIGHTS_BLOCK)), record)
        self.segment = segment

    def step(self, frame: int):
        """Perceive frame ``frame``: the images I(frame) into the outputs P(frame). Overlapping, returns the work
        after the resampling as a callable and publishes P(frame) at the next turn (see the module docstring);
        else does everything and returns None."""
        seg, pipe = self.segment, self.pipeline
        if seg is None or pipe is None:
            raise RuntimeError("perception stepped before start")
        for name, _ in self._images:
            got = seg.frame_of(name)
            if got != frame:
                raise FrameMismatch(f"perception expected {name} of frame {frame}, found frame {got}",
                                    process=WRITER, frame=frame)
        self.cameras.check(seg, frame)
        self.flush()
        t0 = time.perf_counter()
        # everything read from the segment is read now: with overlap the rest runs while dynamics and the
        # renderer write the next frame
        # the whole record in one read (a field-by-field copy costs a numpy call per field)
        state = dict(zip(self._state_names, self._state.array.item())) if self._state is not None else {}
        due = self._accuracy_due(frame)
        truth = None
        if due and state:
            truth = (np.array(seg.view("heightmap_truth"), copy=True), np.array(seg.view("stream"), copy=True))
        gathered = pipe.gather([img for _, img in self._images]) if self._images else None
        cam_images = self.cameras.gather(frame)
        stream = None
        if self._atmosphere is not None and self._atmosphere.particles and seg.has("stream"):
            stream = np.array(seg.view("stream"), copy=True)

        def rest() -> None:
            clean = pipe.resample_gathered(gathered, out=self._ranges) if gathered is not None else self._ranges
            beams = self._accuracy_beams(frame) if due else None           # drawn here, off the token's path
            self._finish(frame, t0, state, clean, beams, truth, cam_images, stream)

        if self.deferred:
            return rest
        rest()
        self.flush()
        return None

    def flush(self) -> None:
        """Publish the outputs computed but not yet written (the last frame's, when overlapping)."""
        out, seg = self._pending, self.segment
        if out is None or seg is None:
            return
        if self.scenario.lidar is not None:
            with seg.write(POINTS_BLOCK, out.frame) as pts:
                np.copyto(pts, out.points)
        for block, data in out.extra.items():
            with seg.write(block, out.frame) as view:
                np.copyto(view, data)
        for block, rec in out.records.items():
            with seg.write(block, out.frame) as st:
                st.array[...] = rec
        with seg.write(HEIGHTS_BLOCK, out.frame) as hv:
            np.copyto(hv, out.heights)
        with seg.write(STATE_BLOCK, out.frame) as st:
            st.array[...] = out.record
        self._pending = None

    def _finish(self, frame: int, t0: float, state: dict, clean: np.ndarray, beams: np.ndarray | None,
                truth: tuple[np.ndarray, np.ndarray] | None, cam_images: list, stream: np.ndarray | None = None
                ) -> None:
        """Atmosphere, noise, the cameras' models, cart, height map, impact and accuracy of frame ``frame`` into
        the pending outputs (``stream``: the frame's stream rows, for the kernels of
        ``atmosphere.stream_particles``)."""
        pipe, out = self.pipeline, self._out
        clean_sample = clean[beams] if beams is not None else None        # a copy: noise comes next, in place
        wfp = world_from_parent(pipe.level_parent, state) if state else np.eye(4)
        if self._atmosphere is not None:                  # dust and the stream's kernels (docs/field.md)
            clean = self._atmosphere.apply(clean, frame, state, stream, wfp @ pipe.level_from_sensor)
        ranges = pipe.noisy(clean, frame)
        t1 = time.perf_counter()
        cams = self.cameras.frames(cam_images, state)
        lfp = level_from_parent(self.scenario, state, pipe.level_parent)
        if lfp is not None:                               # uneven ground: the level frame on the cart's plane
            wfp = wfp @ invert(lfp)
        res, fits, fused = self._perceive(ranges, self._heading(state, wfp), frame, cams, lfp, state, wfp)
        self.last = res
        pipe.points(ranges, out=out.points)
        t2 = time.perf_counter()
        if res.heightmap is None:
            out.heights.fill(np.nan)
        else:
            out.heights[...] = res.heightmap.heights
        lfs = pipe.level_from_sensor if lfp is None else lfp @ pipe.level_from_sensor
        values = self._outputs(frame, state, ranges, res, wfp, lfs)
        values.update(self._fitness(fits))
        if values["sensor_unfit"]:                       # no sensor can support the target: no height map
            out.heights.fill(np.nan)
            values["coverage"] = 0.0
        values["lidar_ms"] = _MS_PER_S * (t1 - t0)
        values["perception_ms"] = _MS_PER_S * (t2 - t0)
        values.update({n: (0 if d == "i8" else math.nan) for n, _, d, _ in ACCURACY_FIELDS})
        values["accuracy_ms"] = math.nan
        lidar_acc = None
        if truth is not None:
            t3 = time.perf_counter()
            values.update(self._accuracy(state, beams, clean_sample, res, wfp, lfs, *truth))
            lidar_acc = values if pipe.n_beams else None
            values["acc_evaluated"] = 1
            values["accuracy_ms"] = _MS_PER_S * (time.perf_counter() - t3)
        out.extra = {}
        for name, blocks in self.cameras.outputs.items():
            r = self.cameras.latest.get(name)
            if r is not None:
                out.extra[blocks["measured"]], out.extra[blocks["points"]] = r.measured, r.record
        if self._sensor_blocks:
            per = sensor_values(pipe, self.cameras, frame, state, ranges, values["lidar_ms"], res, lidar_acc, truth,
                                lfp)
            _fit_fields(per, fits, fused)
            out.records = {block: record_of(per[n], self.segment.view(block).array.dtype)
                           for n, block in self._sensor_blocks.items() if n in per}
        out.frame, out.values = frame, values
        out.record[()] = tuple(values[n] for n in out.record.dtype.names)      # every field, in one assignment
        self._pending = out

    def close(self) -> None:
        """Nothing to release but references; safe to call more than once."""
        self.segment = None

    # -- helpers --------------------------------------------------------------------------------------------
    def _accuracy_due(self, frame: int) -> bool:
        k = self.scenario.perception.accuracy_every_frames
        return k > 0 and frame % k == 0 and self.segment is not None and all(
            self.segment.has(b) for b in ("dyn_state", "heightmap_truth", "stream"))

    def _accuracy_beams(self, frame: int) -> np.ndarray | None:
        """The beams (K,) int64 the frame's accuracy evaluation casts (``perception.accuracy_beams``, a seeded
        stratified sample), or None when the frame is not evaluated."""
        if not self._accuracy_due(frame):
            return None
        sc = self.scenario
        return acc.sample_beams(self.pipeline.n_beams, sc.perception.accuracy_beams, sc.seed, frame)

    def _heading(self, state: dict, wfp: np.ndarray) -> tuple[float, float]:
        """Towing direction (the combine's heading) in the sensor's parent frame."""
        yaw = float(state.get("combine_yaw_rad", 0.0)) if state else 0.0
        d = invert(wfp)[:2, :2] @ np.array([math.cos(yaw), math.sin(yaw)])
        return float(d[0]), float(d[1])

    def _outputs(self, frame: int, state: dict, ranges: np.ndarray, res: FrameResult, wfp: np.ndarray,
                 lfs: np.ndarray) -> dict:
        v: dict[str, float] = {"t_s": float(state.get("t_s", math.nan)), "frame": frame,
                               "valid_beams": int(np.count_nonzero(np.isfinite(ranges)))}
        cart = res.cart
        v["cart_valid"], v["cart_partial"] = int(cart.valid), int(cart.partial)
        corners = (np.asarray(cart.corners) - lfs[:3, 3]) @ lfs[:3, :3]
        for k in range(4):
            for i, a in enumerate("xyz"):
                v[f"corner{k}_{a}_m"] = float(corners[k, i])
        if cart.valid:
            c = wfp @ np.array([cart.centre_xy[0], cart.centre_xy[1], 0.0, 1.0])
            v["cart_x_m"], v["cart_y_m"] = float(c[0]), float(c[1])
            v["cart_yaw_rad"] = float(math.atan2(wfp[1, 0], wfp[0, 0]) + cart.yaw_rad)
        else:
            v["cart_x_m"] = v["cart_y_m"] = v["cart_yaw_rad"] = math.nan
        imp = res.impact
        v["impact_valid"] = int(imp.valid)
        v["impact_gx_m"], v["impact_gy_m"], v["impact_gz_m"] = (float(x) for x in imp.xyz)
        v["coverage"] = res.heightmap.coverage if res.heightmap is not None else 0.0
        for key in ("cart", "heightmap", "impact"):
            v[f"{key}_ms"] = res.timing_ms.get(key, math.nan)
        return v

    def _perceive(self, ranges: np.ndarray, heading: tuple[float, float], frame: int, cams: list,
                  lfp: np.ndarray | None, state: dict, wfp: np.ndarray
                  ) -> tuple[FrameResult, dict[str, CameraFit], set[str]]:
        """The frame's perception from the fit sensors (perception_proc.selection): the cameras left out by
        earlier frames' verdicts are not fused; where this frame's verdicts leave out a camera that was fused,
        the frame is perceived again without it. Returns (result, the cameras' verdicts at its cart, the names
        of the cameras fused)."""
        gate, pipe = self.scenario.perception, self.pipeline
        prior = level_prior(state, wfp, gate.pose_gate_m, gate.pose_gate_deg)

        def run(fused: list) -> tuple[FrameResult, dict[str, CameraFit]]:
            res = pipe.perceive(ranges, heading, with_points=False, frame=frame, cameras=fused,
                                level_from_parent=lfp, cart_prior=prior)
            res = pose_gate(res, state, wfp, gate.pose_gate_m, gate.pose_gate_deg)
            if not len(self.cameras) or not res.cart.valid:
                return res, {}
            sigmas = self.cameras.sigmas_at_cart(np.asarray(res.cart.corners))
            return res, judge(sigmas, self.scenario.outcome.overfill_tolerance_m, self._basis)

        fused = self.selection.fused(cams)
        res, fits = run(fused)
        if self.selection.update(fits):
            fused = self.selection.fused(cams)
            res, fits = run(fused)
        lidar = {self.scenario.lidar_name} if self.scenario.lidar is not None else set()
        return res, fits, {f.name for f, _ in fused} | lidar

    def _fitness(self, fits: dict[str, CameraFit]) -> dict:
        """``height_sigma_m``, ``height_sigma_depth_m``, ``sensor_unfit``, ``sensors_dropped`` of the frame: the
        largest expected error of a cell's height among the cameras that see the found cart
        (perception_proc.cameras.expected), whether the height map is withheld (a camera unfit and no fit
        sensor left: perception_proc.selection) and how many cameras are left out of the fusion."""
        dropped = len(self.selection.dropped)
        if not fits:
            return {"height_sigma_m": math.nan, "height_sigma_depth_m": math.nan, "sensor_unfit": 0,
                    "sensors_dropped": dropped}
        worst = max(fits.values(), key=lambda f: f.sigma_m)
        withheld = any(f.unfit for f in fits.values()) and not self.selection.fit_left(fits)
        return {"height_sigma_m": worst.sigma_m, "height_sigma_depth_m": worst.depth_m,
                "sensor_unfit": int(withheld), "sensors_dropped": dropped}

    def _accuracy(self, state: dict, beams: np.ndarray, clean: np.ndarray, res: FrameResult, wfp: np.ndarray,
                  lfs: np.ndarray, truth_h: np.ndarray, stream: np.ndarray) -> dict:
        """Accuracy fields of the frame: ``clean`` (K,) float32 m, the noise-free ranges of ``beams`` (K,);
        ``truth_h`` and ``stream``: copies of the frame's ``heightmap_truth`` and ``stream`` blocks."""
        sc, pipe = self.scenario, self.pipeline
        wfs = wfp @ lfs                                   # world_from_level @ level_from_sensor
        out = {}
        if pipe.n_beams:
            exact = acc.exact_ranges(sc, state, truth_h, stream, wfs, pipe.directions[beams])
            clean = np.where((clean >= sc.lidar.range_min_m) & (clean <= sc.lidar.range_max_m), clean, np.nan)
            out = acc.range_error_stats(clean, exact, sc.lidar.range_min_m, sc.lidar.range_max_m)
        truth_grid = acc.truth_on_grid(truth_h, sc.grain.cell_m, pipe.grid, sc.cart)
        heights = res.heightmap.heights if res.heightmap is not None else np.full(pipe.grid, np.nan)
        out["heightmap_rmse_m"], out["heightmap_bias_m"], _ = acc.heightmap_error(heights, truth_grid)
        truth_corners = acc.true_corners_sensor(sc.cart, state, wfs)
        est = (np.asarray(res.cart.corners) - lfs[:3, 3]) @ lfs[:3, :3]
        out["corner_error_m"] = acc.corner_error(est, truth_corners)
        out["impact_error_m"] = acc.impact_error(res.impact.xyz, state)
        return out


def _fit_fields(per: dict[str, dict], fits: dict[str, CameraFit], fused: set[str]) -> None:
    """Add each depth-giving sensor's verdict to its ``sensor_<name>`` values ``per`` (in place):
    ``cart_sigma_m``, ``cart_depth_m`` (NaN for the LiDAR and where a camera does not see the cart), ``unfit``,
    ``fused`` (``fused``: the names of the sensors fused this frame)."""
    for name, values in per.items():
        fit = fits.get(name)
        values.update({"cart_sigma_m": fit.sigma_m if fit else math.nan,
                       "cart_depth_m": fit.depth_m if fit else math.nan,
                       "unfit": int(bool(fit and fit.unfit)), "fused": int(name in fused)})


def _image_blocks(pipe: Perception, rig: Rig | None) -> list[tuple[str, tuple[int, int, int]]]:
    """(block name, (H, W, 4)) of every image perception reads: the beams target (beam_native) or each camera's
    depth image."""
    if pipe.beams is not None:
        return [(BEAMS_DEPTH_BLOCK, pipe.beams.layout.shape + (4,))]
    if rig is None:
        return []
    return [(f"{c.name}_depth", (c.intrinsics.height, c.intrinsics.width, 4)) for c in rig.cameras]


@dataclass
class _Outputs:
    """One frame's outputs awaiting publication: ``points`` (N, 4) float32, ``heights`` (nx, ny) float32 and the
    ``perc_state`` values of frame ``frame`` (``values`` by name, and ``record``, the 0-d structured record
    of the block that publication copies); the cameras' outputs ``extra`` and the sensors' ``records``."""

    points: np.ndarray
    heights: np.ndarray
    record: np.ndarray
    frame: int = -1
    values: dict = field(default_factory=dict)
    #: the cameras' array outputs (block -> array) and the sensors' records (block -> 0-d record)
    extra: dict = field(default_factory=dict)
    records: dict = field(default_factory=dict)


def create(scenario: Scenario) -> PerceptionParticipant:
    """The perception participant for ``scenario``."""
    return PerceptionParticipant(scenario)
