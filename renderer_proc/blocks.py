"""The renderer's shared-memory blocks (CONTRACTS.md): one set per camera of the planned rig.

* ``<cam>_depth`` image (H, W, 4) uint8: depth-encoded RGBA8 (Eqs 1-2, linear bytes), A = 255 valid;
* ``<cam>_rgb`` image (H, W, 4) uint8: shaded image, only when something consumes it;
* ``<cam>_zf`` array (H, W) float32: planar depth m, NaN invalid, only with ``render.float_depth``;
* with ``sensor.method: beam_native`` instead of the cameras' blocks: ``beams_depth`` (rows, cols, 4) uint8, the
  encoded range along each beam (one pixel per beam, ``cosim.world.beamtarget``), and ``beams_rgb`` when
  something consumes it;
* ``render_state`` struct: the frame's simulation time, render wall time and valid-pixel fraction, and for a
  renderer that ray-casts the LiDAR (:func:`ray_casts`) the ray caster that ran (``renderer_proc/summary.py``);
* per camera sensor (``sensors:``, docs/cameras.md), named ``cam_<name>_<part>`` (cosim.world.sensors):
  ``rgb`` (H, W, 4) uint8 the colour image (a stereo pair's left), ``right`` (H, W, 4) uint8 a stereo pair's
  right image, ``depth`` (H, W) float32 exact planar depth m (NaN no hit; a depth camera's input), ``labels``
  (H, W) uint8 the per-pixel labels (cosim.world.labels), each only where the camera has it
  (``cosim.world.sensors.camera_parts``).

Sizes follow the renderer actually used (``plan_rig`` and ``camera_pinhole`` apply ``render.mock_scale`` for
the mock). With no LiDAR (a camera-only ``sensors:``) there are no LiDAR image blocks.
"""
from __future__ import annotations

from cosim.scenario.config.scenario import Scenario
from cosim.world.beamtarget import BEAMS_DEPTH_BLOCK, BEAMS_RGB_BLOCK, beam_layout
from cosim.world.rig import plan_rig
from cosim.world.sensors import camera_block, camera_parts, camera_pinhole
from shm_schema import ArrayBlock, Block, Field, StructBlock, image_block

__all__ = ["STATE_BLOCK", "WRITER", "declare_blocks", "camera_blocks", "ray_casts", "wants_rgb"]

#: writer name of every renderer block
WRITER = "renderer"
#: name of the renderer's status struct
STATE_BLOCK = "render_state"


def wants_rgb(scenario: Scenario) -> bool:
    """Whether the shaded image is rendered: ``render.rgb == "on"``, or ``"auto"`` with a viewer."""
    return scenario.render.rgb == "on" or (scenario.render.rgb == "auto" and scenario.viewer)


def ray_casts(scenario: Scenario) -> bool:
    """Whether the LiDAR's renderer is an exact ray cast: ``renderer: mock``, or beam-native GL with a CSV pattern
    (no angle grid to draw into); False without a LiDAR."""
    lidar = scenario.lidar
    if lidar is None:
        return False
    if scenario.renderer == "mock":
        return True
    return lidar.method == "beam_native" and not beam_layout(lidar.pattern).gridded


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
    return blocks + _lidar_blocks(scenario) + camera_blocks(scenario)


def camera_blocks(scenario: Scenario) -> list[Block]:
    """The blocks of the camera sensors (``cam_<name>_<part>``), in declaration order."""
    blocks: list[Block] = []
    for name, cam in scenario.cameras.items():
        pin = camera_pinhole(cam, scenario)
        h, w = pin.height, pin.width
        for _, part in camera_parts(cam):
            block = camera_block(name, part)
            if part in ("rgb", "right"):
                blocks.append(image_block(block, WRITER, h, w, doc=f"camera {name}: {part} colour image RGBA8"))
            elif part == "depth":
                blocks.append(ArrayBlock(block, WRITER, "f4", (h, w), unit="m",
                                         doc=f"camera {name}: exact planar depth, NaN no hit"))
            else:
                blocks.append(ArrayBlock(block, WRITER, "u1", (h, w), doc=f"camera {name}: per-pixel labels"))
    return blocks


def _lidar_blocks(scenario: Scenario) -> list[Block]:
    """The LiDAR's image blocks (none without a LiDAR)."""
    lidar = scenario.lidar
    if lidar is None:
        return []
    blocks: list[Block] = []
    rgb = wants_rgb(scenario)
    if lidar.method == "beam_native":
        h, w = beam_layout(lidar.pattern).shape
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
