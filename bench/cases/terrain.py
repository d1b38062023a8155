"""The terrain's patch in the GL beam-native renderer: culled on the CPU (``renderer_proc/gl/meshcull.py``) against
every triangle drawn, on sample frames of the packaged ``rough_terrain`` scenario.

``terrain_cull``: ``frames`` sample frames (``renderer_proc.sample.sample_frame`` at times spread over ``span``
simulated seconds, the scene on the scenario's terrain), each drawn by two renderers in one GL context, one culling
the patch and one drawing every triangle, interleaved per frame: process CPU (llvmpipe's threads included) of
``set_scene``, ``draw`` and ``read_depth``, median of ``reps`` per frame (after one unmetered frame each), the culled one's ratio to the other's,
the share of the patch's triangles kept, and whether the two images (encoded ranges) are the same bytes on every
frame.
"""
from __future__ import annotations

import statistics
import time

from harness import Context, case

__all__ = ["terrain_cull"]


def _frames(frames: int, span: float):
    """(scenario, [(scene, world_from_sensor)]) of the sample frames."""
    import numpy as np

    from cosim.scenario.loader import load_scenario, packaged_scenarios
    from cosim.world.scene import scene_from_state
    from renderer_proc.projection import world_from_sensor
    from renderer_proc.sample import sample_frame

    s = load_scenario(packaged_scenarios()["rough_terrain"])
    out = []
    for t in np.linspace(0.0, span, frames):
        state, heights, stream = sample_frame(s, float(t))
        out.append((scene_from_state(s, state, heights, stream), world_from_sensor(s, state)))
    return s, out


def _cpu_ms(renderer, scene, pose, img, reps: int) -> float:
    """Median process CPU ms of one frame drawn and read by ``renderer``."""
    times = []
    for _ in range(reps):
        c = time.process_time()
        renderer.set_scene(scene)
        renderer.draw(0, pose)
        renderer.read_depth(0, img)
        times.append(1e3 * (time.process_time() - c))
    return statistics.median(times)


@case("terrain_cull", "the GL beam-native renderer's terrain patch culled against every triangle drawn: CPU per "
      "frame, triangles kept, the images' agreement", options={"frames": 10, "span": 20.0, "reps": 7},
      quick={"frames": 1, "reps": 1})
def terrain_cull(ctx: Context) -> dict:
    """Both renderers on ``frames`` sample frames (module docstring)."""
    import numpy as np

    from cosim.world.beamtarget import beam_layout
    from renderer_proc.gl.backend import create_gl_context
    from renderer_proc.gl.beam import GLBeamRenderer
    from renderer_proc.gl.meshcull import pattern_planes, visible_faces

    s, frames = _frames(ctx["frames"], ctx["span"])
    lay = beam_layout(s.lidar.pattern)
    planes = pattern_planes(lay.direction_image())
    gl = create_gl_context()
    arms = {c: GLBeamRenderer(lay, s.lidar.codec, context=gl, cull_terrain=c) for c in (True, False)}
    ms, kept, same = {True: [], False: []}, [], True
    try:
        for r in arms.values():                              # unmetered: shaders, buffers, the first patch
            _cpu_ms(r, *frames[0], np.zeros(lay.shape + (4,), np.uint8), 1)
        for k, (scene, pose) in enumerate(frames):
            imgs = {}
            for cull in ((True, False) if k % 2 == 0 else (False, True)):
                imgs[cull] = np.zeros(lay.shape + (4,), np.uint8)
                ms[cull].append(_cpu_ms(arms[cull], scene, pose, imgs[cull], ctx["reps"]))
            same &= bool(np.array_equal(imgs[True], imgs[False]))
            mesh = scene.meshes[-1]
            sfm = np.linalg.inv(pose) @ mesh.world_from_mesh
            points = mesh.vertices @ sfm[:3, :3].T + sfm[:3, 3]
            kept.append(len(visible_faces(points, mesh.faces, *planes)) / len(mesh.faces))
    finally:
        for r in arms.values():
            r.close()
        gl.release()
    cull, every = statistics.median(ms[True]), statistics.median(ms[False])
    return {"terrain patch, per frame": {"culled": {"CPU ms": cull}, "every triangle": {"CPU ms": every}},
            "culled / every triangle": {"per frame": {"CPU": cull / every, "triangles kept": statistics.median(kept),
                                                      "images": "same" if same else "differ"}}}
