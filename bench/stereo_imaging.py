"""The stereo depth error against its closed form dZ = Z^2 dd / (f B) with the eyes' image formation switched on
one at a time (cosim.testing.stereo_error, docs/cameras.md): a textured plane (the grain material) seen 40 deg down
from 3 m by the OAK-D profile's pair, rendered by the GL renderer; prints the table of docs/cameras.md.

    python bench/stereo_imaging.py
"""
from __future__ import annotations

from cosim.testing.stereo_error import VARIANTS, measure
from cosim.testing.stereo_plane import profile_plane

__all__ = ["main"]


def main() -> None:
    """Render the plane once and print the table of every variant."""
    base, pin, left, right, z = profile_plane("oak_d")
    print("| variant | valid 3-9 m | dd fitted (px) | log-log slope | > 10 sigma | RMS at 3.5 / 5.5 / 8.5 m (mm) |")
    print("|---|---|---|---|---|---|")
    for name, keys in VARIANTS.items():
        r = measure(base.model_copy(update=keys), pin, left, right, z)
        mm = " / ".join(f"{r['rms_mm'][i]:.0f}" for i in (0, 2, 5))
        print(f"| {name} | {r['valid']:.1%} | {r['dd_px']:.3f} | {r['slope']:.2f} | {r['gross']:.2%} | {mm} |")


if __name__ == "__main__":
    main()
