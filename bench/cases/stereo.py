"""The stereo matcher alone (docs/cameras.md): what each configuration costs per pair and how well it does, on the
same rendered pairs.

``stereo_matcher``: the packaged profile's pairs of textured planes (``cosim.testing.stereo_plane``: facing the
camera at 2, 6 and 15 m, slanted 40 deg down from 3 m, a wall seen obliquely from 3 m), each configuration run on
every pair in rotating order, ``repeats`` times: medians per pair of the wall time and of the process CPU time
(OpenCV's threads included), the share of the pixels with an exact depth in 2-15 m that the matcher reports valid,
and the share of those valid pixels off by more than 10 times the profile's sigma_Z = Z^2 sigma_d / (f B).
Configurations: ``opencv`` (StereoSGBM's one-pass mode with its own checks and its parabola, nothing after it),
``refined`` (the camera's default: the texture check and the Gauss-Newton sub-pixel step), ``refined_3way``
(the same on OpenCV's parallel three-way mode), ``refined_3way_search`` (and the search cut to the disparities a
camera 0.9-6.1 m above what it sees needs: 16 to 111 px; the packaged ``stereo_spout`` head's is derived in
cosim/world/disparity_search.py) and ``bm``
(StereoBM, refined).
"""
from __future__ import annotations

import math
import statistics
import time

import numpy as np
from harness import Context, case, rotating

__all__ = ["stereo_matcher"]

#: configuration -> the stereo camera's keys over its profile
CONFIGS = {"opencv": {"texture_threshold": 0.0, "subpixel": "matcher"}, "refined": {},
           "refined_3way": {"sgbm_mode": "3way"},
           "refined_3way_search": {"sgbm_mode": "3way", "min_disparity_px": 16, "num_disparities": 96},
           "bm": {"matcher": "bm"}}
#: (pitch deg, height m, roll deg) of the pairs
SCENES = ((90.0, 2.0, 0.0), (90.0, 6.0, 0.0), (90.0, 15.0, 0.0), (40.0, 3.0, 0.0), (25.0, 3.0, -90.0))
WORKING_M = (2.0, 15.0)
GROSS_SIGMAS = 10.0


def _pairs(profile: str) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The grey pairs and exact depths of :data:`SCENES` for ``profile``."""
    from cosim.scenario.config.cameras import StereoCamera
    from cosim.testing.stereo_plane import textured_plane_pair
    from cosim.world.camera import Pinhole
    from perception_proc.cameras.stereo import grey
    from renderer_proc.gl.backend import create_gl_context

    cam = StereoCamera(kind="stereo_camera", profile=profile, mount={"parent": "world"})
    pin = Pinhole(cam.width_px, cam.height_px, math.radians(cam.hfov_deg))
    ctx = create_gl_context()
    try:
        out = []
        for pitch, height, roll in SCENES:
            left, right, z = textured_plane_pair(ctx, pin, cam.baseline_m, pitch_deg=pitch, height_m=height,
                                                 roll_deg=roll)
            out.append((grey(left), grey(right), z))
        return out
    finally:
        ctx.release()


def _quality(cam, d: np.ndarray, z: np.ndarray) -> tuple[int, int, int]:
    """(pixels in the working range, valid among them, gross among those) of disparity ``d`` against depth ``z``."""
    band = cam.min_disparity_px + cam.num_disparities
    inside = np.isfinite(z) & (z >= WORKING_M[0]) & (z <= WORKING_M[1])
    inside[:, :band] = False
    ok = inside & np.isfinite(d)
    zm = cam.focal_px * cam.baseline_m / d[ok]
    gross = np.abs(zm - z[ok]) > GROSS_SIGMAS * cam.depth_sigma_m(z[ok])
    return int(inside.sum()), int(ok.sum()), int(gross.sum())


@case("stereo_matcher", "the stereo matcher's cost per pair (wall and CPU) and its valid and gross shares on "
      "rendered planes, per configuration", options={"profile": "multisense_s21b", "repeats": 3,
                                                     "configs": ",".join(CONFIGS)},
      quick={"profile": "oak_d", "repeats": 1}, settings=True, compare=("cpu ms per pair",))
def stereo_matcher(ctx: Context) -> dict:
    """Every configuration of ``configs`` on the same pairs, interleaved (module docstring)."""
    from cosim.scenario.config.cameras import StereoCamera
    from perception_proc.cameras.stereo import camera_disparity, make_matcher

    names = [n for n in ctx["configs"].split(",") if n]
    unknown = set(names) - set(CONFIGS)
    if unknown:
        raise ValueError(f"unknown configurations {sorted(unknown)}; choose from {', '.join(CONFIGS)}")
    cams = {n: StereoCamera(kind="stereo_camera", profile=ctx["profile"], mount={"parent": "world"}, **CONFIGS[n])
            for n in names}
    matchers = {n: make_matcher(c) for n, c in cams.items()}
    pairs = _pairs(ctx["profile"])
    wall = {n: [] for n in names}
    cpu = {n: [] for n in names}
    counts = {n: np.zeros(3, np.int64) for n in names}
    for rep in range(int(ctx["repeats"])):
        for k, (left, right, z) in enumerate(pairs):
            for n in rotating(names, rep + k):
                t0, c0 = time.perf_counter(), time.process_time()
                d = camera_disparity(matchers[n], cams[n], left, right)
                wall[n].append(time.perf_counter() - t0)
                cpu[n].append(time.process_time() - c0)
                if rep == 0:
                    counts[n] += _quality(cams[n], d, z)
    rows = {n: {"wall ms per pair": 1e3 * statistics.median(wall[n]),
                "cpu ms per pair": 1e3 * statistics.median(cpu[n]),
                "valid % (2-15 m)": 100.0 * counts[n][1] / max(counts[n][0], 1),
                "gross % of valid": 100.0 * counts[n][2] / max(counts[n][1], 1)} for n in names}
    return {f"{ctx['profile']}, {len(pairs)} pairs": rows}
