"""The camera sensors in the renderer (docs/cameras.md): their views, their blocks, their backend.

``CameraSet(scenario)`` lists every view the scenario's cameras need (one per camera, two for a stereo pair:
``cosim.world.sensors.camera_views``) with the parts read from it into shared memory
(``cosim.world.sensors.camera_parts``: rgb, right, depth, labels). ``start`` binds the blocks and makes the
backend (``camera_gl.GLCameraRenderer``, sharing the LiDAR renderer's GL context when there is one, or
``camera_mock.MockCameraRenderer``). ``render(frame, state, scene)`` draws the cameras due this frame
(``every_frames``) at their poses and reads each part straight into its block under the seqlock.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from cosim.scenario.config.scenario import Scenario
from cosim.world.camera import Pinhole
from cosim.world.lighting import work_light_world
from cosim.world.scene import Scene
from cosim.world.sensors import camera_block, camera_parts, camera_pinhole, camera_views, world_from_sensor

if TYPE_CHECKING:
    from shm_schema.segment import Segment

__all__ = ["View", "CameraSet", "camera_backend"]


@dataclass
class View:
    """One rendered view: camera ``camera`` (its record ``spec``), ``sensor_from_view`` (4, 4), its ``pin``,
    and ``parts`` part -> block name read from it."""

    camera: str
    spec: Any
    sensor_from_view: np.ndarray
    pin: Pinhole
    parts: dict[str, str] = field(default_factory=dict)


def camera_backend(scenario: Scenario, views: list[View], context: Any = None):
    """The camera backend ``scenario.renderer`` names: GL (``context``: a GL context to share, else its own)
    or the mock."""
    labelled = [bool({"labels", "rgb", "right"} & set(v.parts)) for v in views]
    pins = [v.pin for v in views]
    if scenario.renderer == "gl":
        from renderer_proc.gl.camera import GLCameraRenderer

        return GLCameraRenderer(pins, scenario.render.lighting, context=context,
                                parts=[_gl_parts(v) for v in views])
    if scenario.renderer == "mock":
        from cosim.world.parts import entity_parts
        from renderer_proc.mock.camera import MockCameraRenderer

        return MockCameraRenderer(pins, scenario.render.lighting, labelled, parts=entity_parts(scenario))
    raise ValueError(f"scenario.renderer is {scenario.renderer!r}: this scenario runs no renderer")


def _gl_parts(v: View) -> set[str]:
    """The parts the GL backend draws for view ``v``: those read into blocks (``right`` is a colour image), and
    depth and labels too where the camera's motion blur reads them (``CameraSet._blurred``)."""
    parts = {"rgb" if p == "right" else p for p in v.parts}
    if getattr(v.spec, "motion_blur", False):
        parts |= {"depth", "labels"}
    return parts


class CameraSet:
    """Every camera view of a scenario and the backend that draws them."""

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.views: list[View] = []
        for name, cam in scenario.cameras.items():
            pin = camera_pinhole(cam, scenario)
            views = [View(name, cam, pose, pin) for _, pose in camera_views(name, cam)]
            for k, part in camera_parts(cam):
                views[k].parts[part] = camera_block(name, part)
            self.views += views
        self.backend = None
        self._segment: "Segment | None" = None
        #: the previous frame's state (a stereo camera's motion blur interpolates the exposure's start from it)
        self._before: dict | None = None

    def __len__(self) -> int:
        return len(self.views)

    def start(self, segment: "Segment", context: Any = None) -> None:
        """Check every block exists with its view's size, then make the backend."""
        for v in self.views:
            for block in v.parts.values():
                if segment.view(block).shape[:2] != (v.pin.height, v.pin.width):   # KeyError names a missing one
                    raise ValueError(f"block {block!r} is {segment.view(block).shape}, camera {v.camera!r} renders "
                                     f"{v.pin.height} x {v.pin.width}")
        self._segment = segment
        self.backend = camera_backend(self.scenario, self.views, context)

    def due(self, frame: int) -> bool:
        """Whether some view is drawn at ``frame`` (its camera's ``every_frames`` divides it)."""
        return any(frame % v.spec.every_frames == 0 for v in self.views)

    def render(self, frame: int, state: Mapping[str, float], scene: Scene | None) -> tuple[int, int]:
        """Draw the views due at ``frame`` and write their parts; returns (valid depth pixels, depth pixels)
        of the depth parts written. ``scene`` may be None at a frame where no view is due (:meth:`due`)."""
        seg, backend = self._segment, self.backend
        if seg is None or backend is None:
            raise RuntimeError("camera set rendered before start")
        if not self.due(frame):                         # nothing drawn: no scene to upload
            self._before = dict(state)
            return 0, 0
        backend.set_scene(scene, work_light_world(self.scenario.render.lighting, state))
        valid = total = 0
        for k, v in enumerate(self.views):
            if frame % v.spec.every_frames:
                continue
            backend.draw(k, world_from_sensor(v.spec, state) @ v.sensor_from_view)
            image = self._blurred(k, v, state)
            for part, block in v.parts.items():
                with seg.write(block, frame) as out:
                    if part in ("rgb", "right") and image is not None:
                        np.copyto(out, image)
                    elif part in ("rgb", "right"):
                        backend.read_rgb(k, out)
                    elif part == "depth":
                        backend.read_depth(k, out)
                        valid += int(np.count_nonzero(np.isfinite(out)))
                        total += out.size
                    else:
                        backend.read_labels(k, out)
        self._before = dict(state)
        return valid, total

    def _blurred(self, k: int, v: View, state: Mapping[str, float]) -> np.ndarray | None:
        """View ``k``'s colour image blurred over its camera's exposure (``motion_blur``,
        renderer_proc.exposure); None where the camera has no motion blur or there is no earlier state."""
        if not getattr(v.spec, "motion_blur", False) or self._before is None or not state:
            return None
        from renderer_proc.exposure import blurred

        shape = (v.pin.height, v.pin.width)
        image, depth, label = np.empty(shape + (4,), np.uint8), np.empty(shape, np.float32), np.empty(shape, np.uint8)
        self.backend.read_rgb(k, image)
        self.backend.read_depth(k, depth)
        self.backend.read_labels(k, label)
        return blurred(image, depth, label, v.pin, v.spec, v.sensor_from_view, self._before, state)

    def close(self) -> None:
        """Release the backend; safe to call more than once."""
        if self.backend is not None:
            self.backend.close()
            self.backend = None
