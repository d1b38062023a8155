"""The renderer's shared-memory blocks (CONTRACTS.md): one set per camera of the planned rig.

* ``<cam>_depth`` image (H, W, 4) uint8: depth-encoded RGBA8 (Eqs 1-2, linear bytes), A = 255 valid;
* ``<cam>_rgb`` image (H, W, 4) uint8: shaded image, only when something consumes it;
* ``<cam>_zf`` array (H, W) float32: planar depth m, NaN invalid, only with ``render.float_depth``;
* with ``sensor.method: beam_native`` instead of the cameras' blocks: ``beams_depth`` (rows, cols, 4) uint8, the
  encoded range along each beam (one pixel per beam, ``cosim.world.beamtarget``), and ``beams_rgb`` when
  something consumes it;
* ``render_state`` struct: the frame's simulation time, render wall time and valid-pixel fraction, and for a
  renderer that ray-casts (:func:`ray_casts`) the ray caster that ran (``renderer_proc/summary.py``).

Sizes follow the renderer actually used (``plan_rig`` applies ``render.mock_scale`` for the mock).
"""
from __future__ import annotations

from cosim.scenario.config.scenario import Scenario
from cosim.world.beamtarget import BEAMS_DEPTH_BLOCK, BEAMS_RGB_BLOCK, beam_layout
from cosim.world.rig import plan_rig
from shm_schema import ArrayBlock, Block, Field, StructBlock, image_block

__all__ = ["STATE_BLOCK", "WRITER", "declare_blocks", "ray_casts", "wants_rgb"]

#: writer name of every renderer block
WRITER = "renderer"
#: name of the renderer's status struct
STATE_BLOCK = "render_state"


def wants_rgb(scenario: Scenario) -> bool:
    """Whether the shaded image is rendered: ``render.rgb == "on"``, or ``"auto"`` with a viewer."""
    return scenario.render.rgb == "on" or (scenario.render.rgb == "auto" and scenario.viewer)


def ray_casts(scenario: Scenario) -> bool:
    """Whether the renderer is an exact ray cast: ``renderer: mock``, or beam-native GL with a CSV pattern (no
    angle grid to draw into)."""
    if scenario.renderer == "mock":
        return True
    return scenario.sensor.method == "beam_native" and not beam_layout(scenario.sensor.pattern).gridded


def declare_blocks(scenario: Scenario) -> list[Block]:
    """The renderer's blocks for ``scenario`` (empty when the scenario runs no renderer)."""
    if not scenario.needs_renderer:
        return []
    fields = [Field("t_s", "s", doc="simulation time of the rendered state"),
              Field("render_ms", "ms", doc="wall time of the frame: scene update, every camera, reads"),
              Field("valid_fraction", "", doc="fraction of depth pixels with a valid hit, all cameras")]
    if ray_casts(scenario):
        fields.append(Field("ray_caster", "", doc="the exact ray cast that ran: index in cosim.world.fastcast.CASTERS"))
    blocks: list[Block] = [StructBlock(STATE_BLOCK, WRITER, tuple(fields), doc="renderer status per frame")]
    rgb = wants_rgb(scenario)
    if scenario.sensor.method == "beam_native":
        h, w = beam_layout(scenario.sensor.pattern).shape
        blocks.append(image_block(BEAMS_DEPTH_BLOCK, WRITER, h, w, doc="range along each beam, RGBA8, Eqs 1-2"))
        if rgb:
            blocks.append(image_block(BEAMS_RGB_BLOCK, WRITER, h, w, doc="shaded RGBA8 per beam"))
        return blocks
    for cam in plan_rig(scenario).cameras:
        h, w = cam.intrinsics.height, cam.intrinsics.width
        blocks.append(image_block(f"{cam.name}_depth", WRITER, h, w, doc="depth-encoded RGBA8, Eqs 1-2"))
        if rgb:
            blocks.append(image_block(f"{cam.name}_rgb", WRITER, h, w, doc="shaded RGBA8"))
        if scenario.render.float_depth:
            blocks.append(ArrayBlock(f"{cam.name}_zf", WRITER, "f4", (h, w), unit="m",
                                     doc="planar depth, NaN invalid"))
    return blocks
