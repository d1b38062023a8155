"""The beam-native mock renderer's cost per frame: Embree against the numpy ray cast.

For ``--frames`` sample frames of the default scene (``renderer_proc.sample.sample_frame`` spread over
``--span`` s), interleaved per frame (A B, B A, ...), one mock frame = ``draw`` (the exact cast of every beam)
+ ``read_depth`` (Eqs 1-2) of :class:`renderer_proc.beam_mock.MockBeamRenderer` with ``backend`` numpy and
embree. CPU is process CPU time (every thread, Embree's BVH build included); medians. Also checks that the two
backends' bytes agree. Prints Markdown. Usage::

    python bench/mock_cast.py --frames 30
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from datetime import datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from cosim.scenario.config import Scenario  # noqa: E402
from cosim.world.beamtarget import beam_layout  # noqa: E402
from cosim.world.scene import scene_from_state  # noqa: E402
from renderer_proc.beam_mock import MockBeamRenderer  # noqa: E402
from renderer_proc.projection import world_from_sensor  # noqa: E402
from renderer_proc.sample import sample_frame  # noqa: E402

BACKENDS = ("numpy", "embree")


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--span", type=float, default=8.0, help="simulated seconds the sample frames spread over")
    a = ap.parse_args(argv)
    sc = Scenario(format_version=1)
    lay = beam_layout(sc.sensor.pattern)
    rend = {b: MockBeamRenderer(lay, sc.sensor.codec, backend=b) for b in BACKENDS}
    img = {b: np.zeros(lay.shape + (4,), np.uint8) for b in BACKENDS}
    cpu = {b: [] for b in BACKENDS}
    wall = {b: [] for b in BACKENDS}
    same = []
    for i, t in enumerate(np.linspace(0.0, a.span, a.frames)):
        state, heights, stream = sample_frame(sc, float(t))
        scene = scene_from_state(sc, state, heights, stream)
        pose = world_from_sensor(sc, state)
        for b in (BACKENDS if i % 2 == 0 else BACKENDS[::-1]):
            c0, w0 = time.process_time(), time.perf_counter()
            rend[b].set_scene(scene)
            rend[b].draw(0, pose)
            rend[b].read_depth(0, img[b])
            cpu[b].append(1e3 * (time.process_time() - c0))
            wall[b].append(1e3 * (time.perf_counter() - w0))
        same.append(float(np.all(img["numpy"] == img["embree"], axis=-1).reshape(-1)[:lay.n_beams].mean()))
    res = {b: (statistics.median(cpu[b]), statistics.median(wall[b])) for b in BACKENDS}
    print(f"Beam mock, default scene, {a.frames} frames x {lay.n_beams} beams, interleaved; {os.cpu_count()} cores, "
          f"{datetime.now():%Y-%m-%d %H:%M}; medians.\n")
    print("| ray cast | CPU ms/frame | wall ms/frame |\n|---|---:|---:|")
    for b in BACKENDS:
        print(f"| {b} | {res[b][0]:.1f} | {res[b][1]:.1f} |")
    print(f"\nembree / numpy = {res['embree'][0] / res['numpy'][0]:.3f}x CPU; encoded bytes equal on "
          f"{100 * min(same):.3f} % of the beams (worst frame)")
    return {"cpu_ms": {b: res[b][0] for b in BACKENDS}, "bytes_equal_min": min(same)}


if __name__ == "__main__":
    main()
