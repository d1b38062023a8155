"""The renderer ring member: reads the dynamics state, renders the LiDAR's images and every camera sensor,
writes the image blocks.

Thin shell: ``start`` makes the LiDAR's backend (GL context or the numpy mock; none without a LiDAR) and the
cameras' (``renderer_proc.cameras``, sharing the GL context) and binds the segment's views; ``step(frame)``
checks the state's frame stamp, rebuilds the :class:`~cosim.world.scene.Scene` where something is drawn, uploads
it (poses as instance records, grain heights as a buffer write where they changed), then per LiDAR camera (or the
beams target) and per camera sensor view due draws and reads straight into the shared-memory blocks under their
seqlocks.
"""
from __future__ import annotations

import logging
import os
import time
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from cosim.errors import FrameMismatch
from cosim.runtime.participant import activity
from cosim.scenario.config.scenario import Scenario
from cosim.world.beamtarget import BEAMS_DEPTH_BLOCK, BEAMS_RGB_BLOCK, beam_layout
from cosim.world.fastcast import CASTERS
from cosim.world.parts import entity_parts
from cosim.world.rig import plan_rig
from cosim.world.scene import scene_from_state
from renderer_proc.blocks import STATE_BLOCK, WRITER, ray_casts, wants_rgb
from renderer_proc.cameras import CameraSet
from renderer_proc.projection import camera_poses, world_from_sensor

if TYPE_CHECKING:
    from shm_schema.segment import Segment

__all__ = ["INPUT_BLOCKS", "RendererParticipant", "create", "make_backend"]

log = logging.getLogger("cosim.renderer")

#: blocks the renderer reads (written by dynamics)
INPUT_BLOCKS = ("dyn_state", "heightmap_truth", "stream")
#: an RGBA8 pixel read as one little-endian word: alpha is its top byte, non-zero exactly when the word is
#: at least 2**24 (one comparison per pixel instead of a strided read of every fourth byte)
_WORD = np.dtype("<u4")
_ALPHA_SET = 1 << 24
_MS_PER_S = 1000.0


def shader_activity(env: Mapping[str, str] | None = None) -> str:
    """What a starting GL renderer says it does (cosim.runtime.participant.activity): compiling shaders, and
    whether Mesa's on-disk shader cache (``MESA_SHADER_CACHE_DIR``, else ``$XDG_CACHE_HOME`` or ``~/.cache``) is
    still empty, which makes the first run on a machine compile every program from scratch (10-30 s on llvmpipe
    under load)."""
    env = os.environ if env is None else env
    root = env.get("MESA_SHADER_CACHE_DIR") or os.path.join(
        env.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "mesa_shader_cache")
    candidates = [root, root + "_db"] if not env.get("MESA_SHADER_CACHE_DIR") else [root]
    warm = any(os.path.isdir(c) and any(os.scandir(c)) for c in candidates)
    return "compiling shaders" if warm else "compiling shaders (empty cache: first run)"


def make_backend(scenario: Scenario, rig, context: Any = None):
    """The backend ``scenario.renderer`` names: ``GLRenderer`` ("gl", imports moderngl now) or ``MockRenderer``
    ("mock", no GL). Raises RendererUnavailable when no GL context can be made."""
    if scenario.lidar.method == "beam_native":
        return _beam_backend(scenario, context)
    opts = dict(rgb=wants_rgb(scenario), float_depth=scenario.render.float_depth)
    if scenario.renderer == "gl":
        from renderer_proc.gl.backend import GLRenderer

        return GLRenderer(rig, scenario.lidar.codec, context=context, **opts)
    if scenario.renderer == "mock":
        from renderer_proc.mock.backend import MockRenderer

        return MockRenderer(rig, scenario.lidar.codec, parts=entity_parts(scenario), **opts)
    raise ValueError(f"scenario.renderer is {scenario.renderer!r}: this scenario runs no renderer")


def _beam_backend(scenario: Scenario, context: Any = None):
    """The beam-native backend (``sensor.method: beam_native``): ``GLBeamRenderer`` (gl, grid and honeycomb
    patterns) or ``MockBeamRenderer`` (mock; gl with a CSV pattern)."""
    layout, codec, rgb = beam_layout(scenario.lidar.pattern), scenario.lidar.codec, wants_rgb(scenario)
    if scenario.renderer == "gl" and layout.gridded:
        from renderer_proc.gl.beam import GLBeamRenderer

        return GLBeamRenderer(layout, codec, rgb=rgb, context=context)
    if scenario.renderer in ("gl", "mock"):       # a CSV table has no angle grid: its exact ray cast under gl too
        from renderer_proc.mock.beam import MockBeamRenderer

        return MockBeamRenderer(layout, codec, rgb=rgb, parts=entity_parts(scenario))
    raise ValueError(f"scenario.renderer is {scenario.renderer!r}: this scenario runs no renderer")


class RendererParticipant:
    """Ring member ``renderer``. Create with :func:`create`; the ring calls start, step, close."""

    name = WRITER

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.has_lidar = scenario.lidar is not None
        self.beam_native = self.has_lidar and scenario.lidar.method == "beam_native"
        self.rig = plan_rig(scenario) if self.has_lidar and not self.beam_native else None
        self.cameras = CameraSet(scenario)
        self.backend = None
        self.segment: Segment | None = None
        self.rgb = wants_rgb(scenario)
        self.last_ms = float("nan")

    def start(self, segment: Segment) -> None:
        """Bind the input and output views, then make the backend (GL context creation happens here)."""
        for name in INPUT_BLOCKS:
            if not segment.has(name):
                raise KeyError(f"renderer needs block {name!r} (written by dynamics), absent from this run")
        self.segment = segment
        self._state = segment.view("dyn_state")
        self._state_names = self._state.array.dtype.names
        self._heights = segment.view("heightmap_truth")
        self._stream = segment.view("stream")
        self._outputs = []
        if self.beam_native:
            self._outputs.append({"depth": BEAMS_DEPTH_BLOCK, **({"rgb": BEAMS_RGB_BLOCK} if self.rgb else {})})
        for cam in (self.rig.cameras if self.rig is not None else ()):
            outs = {"depth": f"{cam.name}_depth"}
            if self.rgb:
                outs["rgb"] = f"{cam.name}_rgb"
            if self.scenario.render.float_depth:
                outs["zf"] = f"{cam.name}_zf"
            for block in outs.values():
                segment.view(block)            # raises KeyError naming the missing block
            self._outputs.append(outs)
        self._caster_code = None
        if self.scenario.renderer == "gl":
            activity(shader_activity())
        if self.has_lidar:
            self.backend = make_backend(self.scenario, self.rig)
            caster = getattr(self.backend, "caster", None)
            self._caster_code = CASTERS.index(caster.name) if caster is not None and ray_casts(self.scenario) \
                else None
            if caster is not None:
                log.info("exact ray cast: %s", caster.name)
        if len(self.cameras):
            self.cameras.start(segment, context=getattr(self.backend, "ctx", None))

    def step(self, frame: int) -> None:
        """Render frame ``frame``: the dynamics state S(frame) into the images I(frame)."""
        seg = self.segment
        if seg is None or (self.backend is None and self.cameras.backend is None):
            raise RuntimeError("renderer stepped before start")
        got = seg.frame_of("dyn_state")
        if got != frame:
            raise FrameMismatch(f"renderer expected dyn_state of frame {frame}, found frame {got}",
                                process=WRITER, frame=frame)
        t0 = time.perf_counter()
        # the inputs copied first (the whole record in one read, the arrays a few KiB): under the pipelined
        # schedule dynamics may write the next frame once this member writes its first output
        state = dict(zip(self._state_names, self._state.array.item()))
        drawn = self.backend is not None or self.cameras.due(frame)      # else no scene to build this frame
        scene = scene_from_state(self.scenario, state, self._heights.copy(), self._stream.copy()) if drawn else None
        valid = total = 0
        if self.backend is not None:
            self.backend.set_scene(scene)
        poses = ([] if not self.has_lidar else [world_from_sensor(self.scenario, state)] if self.beam_native
                 else camera_poses(self.scenario, state, self.rig))
        for k, pose in enumerate(poses):
            self.backend.draw(k, pose)
            outs = self._outputs[k]
            with seg.write(outs["depth"], frame) as img:
                self.backend.read_depth(k, img)
                valid += int(np.count_nonzero(img.view(_WORD) >= _ALPHA_SET))     # alpha, the word's top byte
                total += img.shape[0] * img.shape[1]
            if "rgb" in outs:
                with seg.write(outs["rgb"], frame) as img:
                    self.backend.read_rgb(k, img)
            if "zf" in outs:
                with seg.write(outs["zf"], frame) as zf:
                    self.backend.read_zf(k, zf)
        if len(self.cameras):
            cam_valid, cam_total = self.cameras.render(frame, state, scene)
            if not self.has_lidar:                     # valid_fraction is the LiDAR's where there is one
                valid, total = cam_valid, cam_total
        self.last_ms = (time.perf_counter() - t0) * _MS_PER_S
        if seg.has(STATE_BLOCK):
            with seg.write(STATE_BLOCK, frame) as st:
                st.t_s = float(state.get("t_s", 0.0))
                st.render_ms = self.last_ms
                st.valid_fraction = valid / total if total else float("nan")
                if self._caster_code is not None:
                    st.ray_caster = self._caster_code

    def close(self) -> None:
        """Release the backends (the GL context). Safe to call more than once, also after a failed start."""
        self.cameras.close()                           # before the context it may share
        if self.backend is not None:
            self.backend.close()
            self.backend = None


def create(scenario: Scenario) -> RendererParticipant:
    """The renderer participant for ``scenario`` (backend chosen by ``scenario.renderer`` at ``start``)."""
    return RendererParticipant(scenario)
