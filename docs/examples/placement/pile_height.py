"""The stereo head's pile height by the definition of the published stereo pile-height study (Sensors 2024,
24(22):7204), beside the project's fill-height error (docs/cameras.md).

The study measures, at key points, the camera's distance to the empty container's bottom and to the material's
surface; the pile height is their difference, its error relative to the true height: mean |h - h_true| / h_true.
Here: the packaged ``stereo_spout`` head (looking straight down, so a pixel's planar depth is its vertical
distance) over the cart, empty and with the grain flat at each of ``--fills`` m, one GL frame each, with each
matcher. The key points are the perception's strided pixels whose exact ray (the scene's ray cast) meets the floor
when empty and the grain when loaded. For each: h = Z_floor - Z_surface, both measured by the matcher (the
study's), against h_true = the exact difference; and the project's h = (camera height - Z_surface) - floor height,
the floor known from the cart's pose (the fill-height error of docs/cameras.md). No regression correction (the
study fitted one to its measurements).

    python docs/examples/placement/pile_height.py                 # sgbm and bm; fills 0.5, 1.0, 1.5 m
"""
from __future__ import annotations

import argparse
import math

import numpy as np

__all__ = ["capture", "pile_errors", "main"]


def capture(matcher: str, fill: float) -> tuple:
    """(scenario, camera pipeline, dyn_state, measured depth (H, W), exact planar depth of the strided pixels (M,))
    of frame 0 of ``stereo_spout`` with ``matcher`` and the grain flat at ``fill`` m (in-process, GL)."""
    import perception_proc.accuracy.sensors as cacc
    import perception_proc.participant as part
    from cosim.runtime.inprocess import simulate
    from cosim.scenario.files import resolve_scenario_arg
    from cosim.scenario.loader import load_scenario
    from cosim.world.scene import scene_from_state
    from cosim.world.sensors import world_from_sensor

    extra = {"grain.initial_fill_m": fill, "sensors.spout.matcher": matcher, "sensors.spout.every_frames": 1,
             "perception.accuracy_every_frames": 1}
    sc = load_scenario(resolve_scenario_arg("stereo_spout"), extra=extra)
    got = {}
    original = part.PerceptionParticipant._finish

    def finish(self, frame, t0, state, clean, beams, truth, cam_images, stream=None):
        original(self, frame, t0, state, clean, beams, truth, cam_images, stream)
        if frame == 0 and truth is not None:
            got.update(state=dict(state), truth=truth, pipe=self.cameras.pipes[0],
                       measured=np.array(self.cameras.latest["spout"].measured))

    part.PerceptionParticipant._finish = finish
    try:
        simulate(sc, frames=1)
    finally:
        part.PerceptionParticipant._finish = original
    p, state = got["pipe"], got["state"]
    pixels = (p.rows[:, None] * p.pin.width + p.cols[None, :]).reshape(-1)
    scene = scene_from_state(sc, state, *got["truth"])
    exact = cacc.exact_depths(scene, world_from_sensor(p.spec, state), p.pin, pixels)
    return sc, p, state, got["measured"].reshape(-1)[pixels], np.asarray(exact, np.float64)


def pile_errors(empty: tuple, loaded: tuple, fill: float) -> dict:
    """Mean relative pile-height errors at the key points of an empty and a loaded capture (module docstring)."""
    from cosim.world.sensors import world_from_sensor

    sc, p, state, zf, zf_exact = empty
    _, _, _, zs, zs_exact = loaded
    cam_z = world_from_sensor(p.spec, state)[2, 3]
    floor = sc.cart.floor_height_m
    tol = 0.01
    key = (np.abs(zf_exact - (cam_z - floor)) < tol) & (np.abs(zs_exact - (cam_z - floor - fill)) < tol) \
        & np.isfinite(zf) & np.isfinite(zs)
    h_true = zf_exact[key] - zs_exact[key]
    study = np.abs((zf[key] - zs[key]) - h_true) / h_true
    ours = np.abs((cam_z - zs[key] - floor) - h_true) / h_true
    return {"key points": int(np.count_nonzero(key)), "study %": 100 * float(np.mean(study)),
            "project %": 100 * float(np.mean(ours)),
            "floor depth error cm": 100 * float(np.mean(zf[key] - zf_exact[key])),
            "surface depth error cm": 100 * float(np.mean(zs[key] - zs_exact[key]))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--matchers", default="sgbm,bm")
    ap.add_argument("--fills", default="0.5,1.0,1.5", help="grain levels above the floor, m")
    a = ap.parse_args(argv)
    print("| matcher | grain m | key points | study's definition % | project's % | floor depth bias cm | "
          "surface depth bias cm |\n|---|---|---|---|---|---|---|")
    for m in a.matchers.split(","):
        empty = capture(m, 0.0)
        pooled = []
        for fill in (float(f) for f in a.fills.split(",")):
            r = pile_errors(empty, capture(m, fill), fill)
            pooled.append(r)
            print(f"| {m} | {fill:g} | {r['key points']} | {r['study %']:.2f} | {r['project %']:.2f} | "
                  f"{r['floor depth error cm']:.2f} | {r['surface depth error cm']:.2f} |", flush=True)
        n = sum(r["key points"] for r in pooled)
        study = sum(r["study %"] * r["key points"] for r in pooled) / n if n else math.nan
        ours = sum(r["project %"] * r["key points"] for r in pooled) / n if n else math.nan
        print(f"| {m} | all | {n} | {study:.2f} | {ours:.2f} | | |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
