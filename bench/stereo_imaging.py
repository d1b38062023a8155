"""The stereo depth error against its closed form dZ = Z^2 dd / (f B) with the eyes' image formation switched on
one at a time (cosim.testing.stereo_error, docs/cameras.md): a textured plane (the grain material) seen 40 deg down
from 3 m by the OAK-D profile's pair, rendered by the GL renderer; prints the table of docs/cameras.md.

    python bench/stereo_imaging.py
"""
from __future__ import annotations

import math

from cosim.scenario.config.cameras import StereoCamera
from cosim.testing.stereo_error import VARIANTS, measure
from cosim.testing.stereo_plane import textured_plane_pair
from cosim.world.camera import Pinhole

__all__ = ["main"]


def main() -> None:
    """Render the plane once and print the table of every variant."""
    from renderer_proc.gl.backend import create_gl_context

    base = StereoCamera(kind="stereo_camera", profile="oak_d", mount={"parent": "world"})
    pin = Pinhole(base.width_px, base.height_px, math.radians(base.hfov_deg))
    ctx = create_gl_context()
    try:
        left, right, z = textured_plane_pair(ctx, pin, base.baseline_m)
    finally:
        ctx.release()
    print("| variant | valid 3-9 m | dd fitted (px) | log-log slope | > 10 sigma | RMS at 3.5 / 5.5 / 8.5 m (mm) |")
    print("|---|---|---|---|---|---|")
    for name, keys in VARIANTS.items():
        r = measure(base.model_copy(update=keys), pin, left, right, z)
        mm = " / ".join(f"{r['rms_mm'][i]:.0f}" for i in (0, 2, 5))
        print(f"| {name} | {r['valid']:.1%} | {r['dd_px']:.3f} | {r['slope']:.2f} | {r['gross']:.2%} | {mm} |")


if __name__ == "__main__":
    main()
