"""Camera rig planning: the fewest pinhole cameras, at the smallest resolution, that cover a LiDAR pattern
with a bounded nearest-pixel angular error (the paper stitches two cameras; docs/architecture.md, docs/CONTRACTS.md).

Error bound. A beam meets the image plane somewhere in a pixel; the nearest pixel centre is at most
delta = sqrt(2)/2 pixels away. For image-plane points p and q = p + delta (pixels, focal length f),
sin(angle) = |p x delta| / (|p| |q|) <= |delta| / |q| <= delta / f, so the angle never exceeds
asin(delta / f), with equality only on the optical axis. A camera with f >= (sqrt(2)/2) / sin(eps) therefore
keeps every beam within eps of its nearest pixel ray, wherever the beam falls in the image.

Coverage. Cameras share the LiDAR origin and tile the pattern's angular extent: ``n_cols`` equal azimuth
sectors (yaw) times ``n_rows`` equal elevation bands (pitch about the camera X axis). A beam belongs to the
camera of its sector and band; that camera's image is made just large enough (symmetric about the principal
point) to contain all of its beams. Tall fields (the Honeycomb-like preset spans 95 deg vertically) are met by
a tall image while the vertical field stays <= MAX_FOV_DEG, and by pitched rows beyond it. Among layouts that
meet the limits (field of view per camera, pixels per side), the planner takes the fewest cameras, then the
fewest pixels.
"""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config.scenario import Scenario
from cosim.scenario.config.sensing import Pattern
from cosim.world.camera import Pinhole, Rig, RigCamera, beam_directions, yaw_transform

__all__ = [
    "MAX_CAMERAS",
    "MAX_FOV_DEG",
    "MAX_SIDE_PX",
    "NEAREST_PIXEL_OFFSET",
    "beam_angles",
    "beam_pixel_error",
    "pitch_transform",
    "plan_cameras",
    "plan_rig",
    "required_focal_px",
    "scale_rig",
]

#: largest field of view (either axis) of one planned pinhole camera, deg. A pinhole's pixels per radian grow
#: as 1 / cos^2 of the off-axis angle; at 100 deg the edges hold 2.4 times the centre's density, beyond it one
#: wide camera costs more pixels than two narrower ones (the Honeycomb-like 90 x 95 deg pattern: one camera
#: would need a 114 deg vertical field and 1.01 Mpx, two cameras need 0.64 Mpx)
MAX_FOV_DEG = 100.0
#: largest image side of one planned camera, px (a safe GL framebuffer size everywhere)
MAX_SIDE_PX = 4096
#: most cameras a rig may have (render.cameras allows 16)
MAX_CAMERAS = 16
#: largest distance from a point in a pixel to the pixel centre, px
NEAREST_PIXEL_OFFSET = math.sqrt(2.0) / 2.0


def required_focal_px(max_error_rad: float) -> float:
    """Smallest focal length (px) whose nearest-pixel angular error is <= ``max_error_rad`` everywhere."""
    if not 0.0 < max_error_rad < math.pi / 2.0:
        raise ValueError(f"max angular error must lie in (0, pi/2) rad, got {max_error_rad}")
    return NEAREST_PIXEL_OFFSET / math.sin(max_error_rad)


def pitch_transform(pitch_up_rad: float) -> np.ndarray:
    """4 x 4 rotation about the camera X axis taking +Z to (0, sin p, cos p) (optical axis tipped up by p)."""
    c, s = math.cos(pitch_up_rad), math.sin(pitch_up_rad)
    t = np.eye(4)
    t[1:3, 1:3] = np.array([[c, s], [-s, c]])
    return t


def beam_angles(pattern: Pattern) -> tuple[np.ndarray, np.ndarray]:
    """(elevation_rad (N,), azimuth_rad (N,)) of the pattern's beams (LiDAR frame, see cosim.world.camera).

    Uses ``cosim.world.patterns.beam_table`` when it exists; otherwise the regular grid spanned by the
    pattern's min / max / count (inclusive end points)."""
    try:
        from cosim.world.patterns import beam_table
    except ImportError:
        el = np.radians(np.linspace(pattern.elevation_min_deg, pattern.elevation_max_deg, pattern.elevation_count))
        az = np.radians(np.linspace(pattern.azimuth_min_deg, pattern.azimuth_max_deg, pattern.azimuth_count))
        ee, aa = np.meshgrid(el, az, indexing="ij")
        return ee.ravel(), aa.ravel()
    el, az = beam_table(pattern)
    return np.asarray(el, dtype=np.float64).ravel(), np.asarray(az, dtype=np.float64).ravel()


def _layout(el, az, f, n_cols, n_rows) -> list[tuple[float, float, int, int]] | None:
    """(yaw, pitch, w, h) per camera for a n_cols x n_rows tiling, or None when a limit is broken."""
    a0, a1, e0, e1 = az.min(), az.max(), el.min(), el.max()
    da, de = (a1 - a0) / n_cols, (e1 - e0) / n_rows
    col = np.clip(((az - a0) / da).astype(int) if da > 0 else np.zeros(len(az), int), 0, n_cols - 1)
    row = np.clip(((el - e0) / de).astype(int) if de > 0 else np.zeros(len(el), int), 0, n_rows - 1)
    dirs = beam_directions(el, az)
    tan_max = math.tan(math.radians(MAX_FOV_DEG) / 2.0) * (1.0 + 1e-9)   # a field of exactly MAX_FOV_DEG is fine
    out = []
    for r in range(n_rows):
        for c in range(n_cols):
            yaw, pitch = a0 + (c + 0.5) * da, e0 + (r + 0.5) * de
            sel = (col == c) & (row == r)
            if not sel.any():
                return None
            rot = (yaw_transform(yaw) @ pitch_transform(pitch))[:3, :3]
            p = dirs[sel] @ rot                      # camera-frame directions (rows: R^T s)
            if np.any(p[:, 2] <= 0.0):
                return None
            xm, ym = np.max(np.abs(p[:, 0] / p[:, 2])), np.max(np.abs(p[:, 1] / p[:, 2]))
            if xm > tan_max or ym > tan_max:
                return None
            w, h = max(1, math.ceil(2.0 * f * xm - 1e-9)), max(1, math.ceil(2.0 * f * ym - 1e-9))
            if w > MAX_SIDE_PX or h > MAX_SIDE_PX:
                return None
            out.append((yaw, pitch, w, h))
    return out


def plan_cameras(elevation_rad: np.ndarray, azimuth_rad: np.ndarray, max_error_rad: float) -> Rig:
    """Fewest cameras (then fewest pixels) covering the beams with nearest-pixel error <= ``max_error_rad``.

    ``elevation_rad``, ``azimuth_rad``: (N,) beam angles (LiDAR frame). Raises ValueError when no layout of up
    to MAX_CAMERAS cameras meets the limits."""
    el, az = np.asarray(elevation_rad, np.float64).ravel(), np.asarray(azimuth_rad, np.float64).ravel()
    if len(el) == 0 or el.shape != az.shape:
        raise ValueError("need matching, non-empty elevation and azimuth arrays")
    f = required_focal_px(max_error_rad)
    for total in range(1, MAX_CAMERAS + 1):
        found = [lay for rows in range(1, total + 1) if total % rows == 0
                 if (lay := _layout(el, az, f, total // rows, rows)) is not None]
        if found:
            best = min(found, key=lambda lay: sum(w * h for _, _, w, h in lay))
            return Rig(tuple(
                RigCamera(f"cam{k}", Pinhole(w, h, 2.0 * math.atan(w / (2.0 * f))),
                          yaw_transform(yaw) @ pitch_transform(pitch))
                for k, (yaw, pitch, w, h) in enumerate(best)))
    raise ValueError(f"no rig of <= {MAX_CAMERAS} cameras covers the pattern at {math.degrees(max_error_rad):g} "
                     f"deg with fields <= {MAX_FOV_DEG:g} deg and sides <= {MAX_SIDE_PX} px; allow a larger "
                     "sensor.max_angular_error_deg or a narrower pattern")


def scale_rig(rig: Rig, scale: float) -> Rig:
    """The same cameras at ``scale`` times the resolution (same fields of view), e.g. for the mock renderer."""
    if scale == 1.0:
        return rig
    return Rig(tuple(RigCamera(c.name, Pinhole(max(1, round(c.intrinsics.width * scale)),
                                               max(1, round(c.intrinsics.height * scale)), c.intrinsics.hfov_rad),
                               c.sensor_from_camera) for c in rig.cameras))


def _fixed_rig(scenario: Scenario) -> Rig:
    r, p = scenario.render, scenario.lidar.pattern
    hfov = math.radians(r.hfov_deg)
    yaw0 = math.radians(p.azimuth_min_deg + p.azimuth_max_deg) / 2.0
    pitch = math.radians(p.elevation_min_deg + p.elevation_max_deg) / 2.0
    return Rig(tuple(
        RigCamera(f"cam{k}", Pinhole(r.width_px, r.height_px, hfov),
                  yaw_transform(yaw0 + (k - (r.cameras - 1) / 2.0) * hfov) @ pitch_transform(pitch))
        for k in range(r.cameras)))


def plan_rig(scenario: Scenario) -> Rig:
    """The rig the scenario's renderer renders (pure). ``render.rig == "auto"``: planned from the LiDAR pattern
    and ``sensor.max_angular_error_deg``; ``"fixed"``: ``render.cameras`` cameras of ``width_px`` x
    ``height_px`` and ``hfov_deg``, side by side in yaw about the pattern's centre. With ``renderer == "mock"``
    the resolution is scaled by ``render.mock_scale`` (the blocks follow the renderer actually used)."""
    if scenario.render.rig == "fixed":
        rig = _fixed_rig(scenario)
    else:
        el, az = beam_angles(scenario.lidar.pattern)
        rig = plan_cameras(el, az, math.radians(scenario.lidar.max_angular_error_deg))
    return scale_rig(rig, scenario.render.mock_scale) if scenario.renderer == "mock" else rig


def beam_pixel_error(rig: Rig, elevation_rad: np.ndarray, azimuth_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each beam, the smallest angle (rad) to the ray of the nearest pixel centre over the cameras whose
    image contains it, and the index of that camera (-1 and inf where no camera sees the beam). (N,) each."""
    dirs = beam_directions(elevation_rad, azimuth_rad).reshape(-1, 3)
    best = np.full(len(dirs), np.inf)
    cam = np.full(len(dirs), -1)
    for k, c in enumerate(rig.cameras):
        p = dirs @ c.sensor_from_camera[:3, :3]
        k_in = p[:, 2] > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = c.intrinsics.project(np.where(k_in[:, None], p, np.array([0.0, 0.0, 1.0])))
        w, h = c.intrinsics.width, c.intrinsics.height
        inside = k_in & (uv[:, 0] >= 0) & (uv[:, 0] <= w) & (uv[:, 1] >= 0) & (uv[:, 1] <= h)
        uc = np.clip(np.floor(uv[:, 0]), 0, w - 1) + 0.5
        vc = np.clip(np.floor(uv[:, 1]), 0, h - 1) + 0.5
        ray = np.stack([uc - w / 2.0, h / 2.0 - vc, np.full_like(uc, c.intrinsics.f)], axis=1)
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        err = np.arctan2(np.linalg.norm(np.cross(ray, p), axis=1), np.einsum("ni,ni->n", ray, p))
        better = inside & (err < best)
        best = np.where(better, err, best)
        cam = np.where(better, k, cam)
    return best, cam
