"""Each stereo matcher's disparity error on the same rendered pairs (cosim.testing.stereo_error, docs/cameras.md,
"Each matcher's expected error"): the textured plane seen 40 deg down from 3 m by each packaged stereo profile's
pair, rendered once by the GL renderer, matched by StereoSGBM and StereoBM (both with the camera's texture check and
sub-pixel refinement), ideal images and with the image formation of bench/stereo_imaging.py; prints dd (px) fitted
to dZ = Z^2 dd / (f B) over 3-9 m and the valid share. The ratio of BM's dd to SGBM's on the ideal pair is the
constant perception_proc.cameras.expected.MATCHER_DD_RATIO holds.

    python bench/stereo_matchers.py
"""
from __future__ import annotations

from cosim.testing.stereo_error import VARIANTS, measure
from cosim.testing.stereo_plane import profile_plane

__all__ = ["main", "PROFILES", "FORMATIONS"]

PROFILES = ("oak_d", "multisense_s21b")
FORMATIONS = ("ideal", "noise + distortion 0.15 px")


def main() -> None:
    """Render each profile's plane once and print a row per (profile, images, matcher)."""
    print("| profile | images | matcher | valid 3-9 m | dd fitted (px) | BM / SGBM |")
    print("|---|---|---|---|---|---|")
    for profile in PROFILES:
        base, pin, left, right, z = profile_plane(profile)
        for images in FORMATIONS:
            dd = {}
            for matcher in ("sgbm", "bm"):
                r = measure(base.model_copy(update={**VARIANTS[images], "matcher": matcher}), pin, left, right, z)
                dd[matcher] = r["dd_px"]
                ratio = f"{dd['bm'] / dd['sgbm']:.2f}" if matcher == "bm" else ""
                print(f"| {profile} | {images} | {matcher} | {r['valid']:.1%} | {r['dd_px']:.3f} | {ratio} |",
                      flush=True)


if __name__ == "__main__":
    main()
