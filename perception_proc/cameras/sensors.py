"""The camera sensors in the perception participant (docs/cameras.md): reading their images, making their depth
and points, publishing them, and their accuracy.

``PerceptionCameras(scenario, level_parent)`` holds one ``CameraPipeline`` per camera. Per ring frame:
``check(segment, frame)`` checks the stamps of the blocks of the cameras due (a camera takes an image every
``every_frames`` frames; in between perception keeps its last frame); ``gather(frame)`` copies the images of
the cameras due (the only read of their shared images: with overlap the rest runs after the token moved on);
``frames(gathered, state)`` runs each due camera's model and back-projection into its :class:`SensorFrame`
(kept for the frames in between) and the records to publish; ``accuracy(...)`` compares a frame with truth.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from functools import cached_property
from typing import TYPE_CHECKING, Mapping

import numpy as np

import perception_proc.accuracy.sensors as cacc
from cosim.errors import FrameMismatch
from cosim.scenario.config.scenario import Scenario
from cosim.world.geometry import invert
from cosim.world.sensors import world_from_parent
from perception_proc.blocks import WRITER, camera_output_blocks
from perception_proc.cameras.expected import cart_depth_m, cell_sigma_m
from perception_proc.cameras.pipeline import CameraImages, CameraPipeline
from perception_proc.protocol import SensorFrame

if TYPE_CHECKING:
    from shm_schema import Segment

__all__ = ["CameraResult", "PerceptionCameras"]

_MS_PER_S = 1e3


@dataclass
class CameraResult:
    """One camera's latest data: its ``frame`` (SensorFrame), the ``border`` flags (M,) of its points, what is
    published (``measured`` (H, W) float32 and ``record`` (M, 4) float32, None for an RGB camera), the
    model's wall time ``measure_ms`` and the ``t_s`` of the state its images show; ``counts``: (valid pixels of
    ``measured``, its pixels, finite points), made once (the frames in between report the same data)."""

    frame: SensorFrame
    border: np.ndarray
    measured: np.ndarray | None
    record: np.ndarray | None
    measure_ms: float
    t_s: float

    @cached_property
    def counts(self) -> tuple[int, int, int]:
        d = self.measured
        valid, pixels = (int(np.count_nonzero(np.isfinite(d))), d.size) if d is not None else (0, 0)
        return valid, pixels, int(np.count_nonzero(np.isfinite(self.frame.points[:, 0])))


class PerceptionCameras:
    """Every camera sensor of ``scenario`` in perception; ``level_parent``: the body whose frame is the level
    frame."""

    def __init__(self, scenario: Scenario, level_parent: str | None = None):
        self.scenario = scenario
        order = list(scenario.sensor_set)
        self.pipes = [CameraPipeline(scenario, name, order.index(name)) for name in scenario.cameras]
        self.level_parent = level_parent
        self.latest: dict[str, CameraResult] = {}
        self._views: dict[str, dict[str, np.ndarray]] = {}
        self.outputs: dict[str, dict[str, str]] = {}

    def __len__(self) -> int:
        return len(self.pipes)

    def start(self, segment: "Segment") -> None:
        """Bind every camera's input blocks (written by the renderer) and its output blocks."""
        for p in self.pipes:
            views = {}
            for part, block in p.blocks.items():
                if not segment.has(block):
                    raise KeyError(f"perception needs block {block!r} (written by the renderer), absent from this run")
                views[part] = segment.view(block)
            self._views[p.name] = views
            if p.depth_giving:
                out = camera_output_blocks(self.scenario, p.name)
                for block, shape in out.values():
                    if segment.view(block).shape != shape:
                        raise ValueError(f"block {block!r} has shape {segment.view(block).shape}, expected {shape}")
                self.outputs[p.name] = {k: b for k, (b, _) in out.items()}

    def due(self, frame: int) -> list[CameraPipeline]:
        """The cameras that take an image at ring frame ``frame``."""
        return [p for p in self.pipes if frame % p.spec.every_frames == 0]

    def check(self, segment: "Segment", frame: int) -> None:
        """Every due camera's blocks carry ``frame`` (FrameMismatch naming the block otherwise)."""
        for p in self.due(frame):
            for block in p.blocks.values():
                got = segment.frame_of(block)
                if got != frame:
                    raise FrameMismatch(f"perception expected {block} of frame {frame}, found frame {got}",
                                        process=WRITER, frame=frame)

    def gather(self, frame: int) -> list[tuple[CameraPipeline, CameraImages]]:
        """Copies of the due cameras' images."""
        return [(p, p.gather(self._views[p.name], frame)) for p in self.due(frame)]

    def level_from_parent(self, parent: str, state: Mapping[str, float]) -> np.ndarray:
        """(4, 4) a camera parent's body frame in the level frame (identity for the level body itself)."""
        if parent == self.level_parent or not state:
            return np.eye(4)
        return invert(world_from_parent(self.level_parent, state)) @ world_from_parent(parent, state)

    def frames(self, gathered: list[tuple[CameraPipeline, CameraImages]], state: Mapping[str, float]
               ) -> list[tuple[SensorFrame, np.ndarray]]:
        """Run the due cameras' models; every camera's latest (SensorFrame, border flags), declaration order."""
        t_s = float(state.get("t_s", 0.0)) if state else 0.0
        for p, images in gathered:
            t0 = time.perf_counter()
            images = replace(images, t_s=t_s)
            depth = p.measure(images)
            lfp = self.level_from_parent(p.parent, state)
            level, ranges, border, record = p.points(depth, lfp)
            frame = SensorFrame(p.name, p.kind, images.frame, level, ranges,
                                rgb=None if images.rgb is None else images.rgb[..., :3],
                                depth_m=depth, labels=images.labels,
                                right=None if images.right is None else images.right[..., :3],
                                K=p.K, level_from_camera=lfp @ p.parent_from_camera)
            self.latest[p.name] = CameraResult(frame, border, depth, record if p.depth_giving else None,
                                               _MS_PER_S * (time.perf_counter() - t0),
                                               float(state.get("t_s", np.nan)) if state else np.nan)
        return [(self.latest[p.name].frame, self.latest[p.name].border) for p in self.pipes if p.name in self.latest]

    def sigmas_at_cart(self, corners: np.ndarray) -> dict[str, tuple[float, float]]:
        """Per depth-giving camera that sees the cart (``corners`` (4, 3), its rim corners in the level frame):
        name -> (expected 1-sigma of a controller cell's height m, the median planar depth m of its points inside
        the rim), perception_proc.cameras.expected; a camera that does not see it is absent."""
        cell_m = self.scenario.controller.grid_cell_m
        out = {}
        for p in self.pipes:
            r = self.latest.get(p.name)
            if not p.depth_giving or r is None or r.record is None:
                continue
            z = cart_depth_m(r.record, r.frame.points, corners)
            if math.isfinite(z):
                out[p.name] = (cell_sigma_m(p.spec, p.pin.f, p.stride, cell_m, z), z)
        return out

    def height_sigma_at_cart(self, corners: np.ndarray) -> tuple[float, str, float]:
        """(sigma m, camera name, depth m): the largest of :meth:`sigmas_at_cart`; NaN, "", NaN when no camera
        sees the cart."""
        worst = (math.nan, "", math.nan)
        for name, (sigma, z) in self.sigmas_at_cart(corners).items():
            if not sigma <= worst[0]:
                worst = (sigma, name, z)
        return worst

    def sensor_values(self, name: str) -> dict:
        """The non-accuracy fields of ``sensor_<name>`` for camera ``name``'s latest data."""
        r = self.latest[name]
        valid, pixels, points = r.counts
        return {"t_s": r.t_s, "frame": r.frame.frame,
                "valid_fraction": float(valid / pixels) if r.measured is not None else np.nan,
                "points": points, "measure_ms": r.measure_ms}

    def depth_accuracy(self, name: str, scene, state: Mapping[str, float], frame: int) -> dict:
        """The depth-error fields of camera ``name``'s latest data against the exact ray cast of the state."""
        from cosim.world.sensors import world_from_sensor

        p = next(q for q in self.pipes if q.name == name)
        r = self.latest[name]
        if r.measured is None:
            return dict(cacc.NAN_STATS)
        pixels = cacc.sample_pixels(p.pin, self.scenario.perception.accuracy_beams, self.scenario.seed, frame)
        exact = cacc.exact_depths(scene, world_from_sensor(p.spec, state), p.pin, pixels)
        return cacc.depth_error_stats(r.measured.reshape(-1)[pixels], exact, p.spec.range_min_m,
                                      p.spec.range_max_m)
