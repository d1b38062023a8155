"""The stereo depth error with motion blur (renderer_proc.motion_blur, docs/cameras.md, "Motion blur"): the textured
plane of bench/stereo_imaging.py (40 deg down from 3 m, OAK-D pair, GL renderer) with the pair translating parallel
to the image plane at v for a 5 ms exposure, along the baseline (the image's rows, the direction the matcher
searches) and across it (the columns). The plane slants along the image's vertical only, so each eye's planar depth
at a pixel is the left eye's; each eye is blurred by its own displacement f v T / Z. Prints dd (px) fitted to
dZ = Z^2 dd / (f B) over 3-9 m and the valid share, on the ideal images and with the CMV2000's shot and read noise
after the blur (one draw), and the blur at 3 and 9 m.

    python bench/stereo_motion_blur.py
"""
from __future__ import annotations

import numpy as np

from cosim.testing.stereo_error import CMV2000, measure
from cosim.testing.stereo_plane import profile_plane
from cosim.world.geometry import make_transform
from renderer_proc.motion_blur import blur, pixel_displacement

__all__ = ["main", "SPEEDS_MPS", "EXPOSURE_S"]

#: the pair's speeds, m/s: still, the combine at work (2 and 3.3 m/s), a road speed
SPEEDS_MPS = (0.0, 2.0, 3.3, 8.0)
EXPOSURE_S = 0.005


def main() -> None:
    """Render the plane once; blur it for each speed and direction; print the table."""
    cam, pin, left, right, z = profile_plane("oak_d")
    noisy = cam.model_copy(update={"image_noise": CMV2000})
    print("| motion | v (m/s) | blur at 3 / 9 m (px) | valid 3-9 m | dd fitted (px) | with noise: valid | dd (px) |")
    print("|---|---|---|---|---|---|---|")
    for name, axis in (("along the rows (baseline)", 0), ("along the columns", 1)):
        for v in SPEEDS_MPS:
            move = np.zeros(3)
            move[axis] = v * EXPOSURE_S
            d = pixel_displacement(z, pin, np.eye(4), make_transform(np.eye(3), -move))
            a, b = blur(left, d), blur(right, d)
            r, n = measure(cam, pin, a, b, z, frames=1), measure(noisy, pin, a, b, z, frames=1)
            near, far = (pin.f * v * EXPOSURE_S / zz for zz in (3.0, 9.0))
            print(f"| {name} | {v:g} | {near:.2f} / {far:.2f} | {r['valid']:.1%} | {r['dd_px']:.3f} | "
                  f"{n['valid']:.1%} | {n['dd_px']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
