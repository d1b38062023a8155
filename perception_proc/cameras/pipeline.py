"""One camera sensor in perception (docs/cameras.md): its images -> its depth -> its points in the level frame.

``CameraPipeline(scenario, name, index)`` precomputes the camera's pinhole, ``K``, its pose in its parent's
body frame and the pixel grid it back-projects (every ``points_stride``-th pixel along each axis, centred in
its stride cell). Per frame:

1. ``gather(views)``: copies of the renderer's blocks (``rgb``, ``right``, ``depth``, ``labels``), the only
   read of the shared images;
2. the camera effects' ``images`` stage (``perception_proc.cameras.effects``: the seam where field conditions
   such as dust change what the sensor receives; nothing by default), then for a stereo camera its image formation
   (``perception_proc.cameras.imaging``: lens distortion, shot and read noise, rectification; off by default);
3. ``measure``: the sensor's model: the depth camera's noise model (``perception_proc.cameras.depth_models``), the stereo
   matcher (``perception_proc.cameras.stereo``), nothing for an RGB camera;
4. the effects' ``depth`` stage on the measured depth;
5. ``points``: the strided pixels back-projected (Eq 5), a depth camera's flying pixels left out
   (``perception_proc.cameras.jump_edges``), mapped into the level frame, with their ranges and
   border flags (``perception_proc.estimates.rim.border_beams`` on the strided grid: pixels next to a nearer one; and a
   band of :data:`EDGE_BAND_RAD` along the edge of the camera's field, which for a stereo pair begins right of
   the columns its matcher cannot search).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from cosim.scenario.config.cameras import Camera, DepthCamera, StereoCamera
from cosim.scenario.config.scenario import Scenario
from cosim.world.sensors import (
    camera_block,
    camera_parts,
    camera_pinhole,
    intrinsics_matrix,
    level_from_sensor,
    points_stride,
)
from perception_proc.cameras.depth_models import depth_model, normal_sigma_m
from perception_proc.cameras.effects import camera_effects
from perception_proc.cameras.expected import GATE_SIGMA_M, point_sigma_m
from perception_proc.cameras.images import SIGMA_DISTANCE_M, CameraImages
from perception_proc.cameras.imaging import ImageFormation
from perception_proc.cameras.jump_edges import flying_pixels, jump_threshold
from perception_proc.cameras.stereo import make_matcher, stereo_depth
from perception_proc.cameras.tof import frame_generator
from perception_proc.estimates.rim import FOV_EDGE, border_beams

__all__ = ["CameraImages", "CameraPipeline", "SIGMA_DISTANCE_M", "STEREO_DISPARITY_SIGMA_PX", "ranges_of"]

#: disparity 1-sigma assumed for that typical figure, px (a matcher on textured images does about this well)
STEREO_DISPARITY_SIGMA_PX = 0.25
#: angular width of the band along the edge of a camera's field whose points are flagged as on the field's edge
#: (``rim.FOV_EDGE``), rad: a camera's points are far denser than a LiDAR's beams, so the rim finder's test of an
#: end cut by the field (a share of its end strip on the edge) needs a band, not one row of points
EDGE_BAND_RAD = 0.02


def ranges_of(points: np.ndarray) -> np.ndarray:
    """Euclidean norm (M,) float64 of each row of ``points`` (M, 3) float64: ``np.linalg.norm(points, axis=1)``
    to the bit (the squares summed in the same order, x + y then + z) without its reduction over rows of three,
    which costs five times more."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    return np.sqrt(x * x + y * y + z * z)


class CameraPipeline:
    """Camera ``name`` (the ``index``-th sensor of the scenario) in perception."""

    def __init__(self, scenario: Scenario, name: str, index: int):
        spec: Camera = scenario.cameras[name]
        self.scenario, self.name, self.index, self.spec = scenario, name, index, spec
        self.kind = spec.kind
        self.pin = camera_pinhole(spec, scenario)
        self.K = intrinsics_matrix(self.pin)
        self.parent = spec.mount.parent
        #: the camera in its parent's body frame
        self.parent_from_camera = level_from_sensor(spec)
        self.blocks = {part: camera_block(name, part) for _, part in camera_parts(spec)}
        self.depth_giving = self.kind in ("depth_camera", "stereo_camera")
        s = points_stride(spec, scenario)
        #: every ``stride``-th pixel along each axis is back-projected
        self.stride = s
        h, w = self.pin.height, self.pin.width
        self.rows = np.arange(s // 2, h, s)
        self.cols = np.arange(s // 2, w, s)
        uu, vv = np.meshgrid(self.cols + 0.5, self.rows + 0.5)
        #: (M, 3) camera-frame point per unit planar depth of the strided pixels (Eq 5 with Z = 1)
        self.unit_points = np.stack([(uu - w / 2.0) / self.pin.f, (h / 2.0 - vv) / self.pin.f,
                                     np.ones_like(uu)], axis=-1).reshape(-1, 3)
        self._matcher = make_matcher(spec) if isinstance(spec, StereoCamera) else None
        self.formation = ImageFormation(spec, self.pin, scenario.seed, index) if isinstance(
            spec, StereoCamera) and (spec.image_noise is not None or spec.distortion is not None) else None
        self.edge = self._edge_band()
        self.effects = camera_effects(scenario, name)

    def _edge_band(self) -> np.ndarray:
        """(M,) bool: the strided pixels within :data:`EDGE_BAND_RAD` of the edge of the camera's field (for a
        stereo pair the field starts right of the left band the matcher cannot search, ``min_disparity_px +
        num_disparities`` columns)."""
        band = self.pin.f * EDGE_BAND_RAD
        left = 0.0
        if isinstance(self.spec, StereoCamera):
            left = float(self.spec.min_disparity_px + self.spec.num_disparities)
        h, w = self.pin.height, self.pin.width
        u, v = self.cols + 0.5, self.rows + 0.5
        cols = (u < left + band) | (u > w - band)
        rows = (v < band) | (v > h - band)
        return (rows[:, None] | cols[None, :]).reshape(-1)

    @property
    def grid_shape(self) -> tuple[int, int]:
        """(rows, cols) of the strided pixel grid of :meth:`points`."""
        return len(self.rows), len(self.cols)

    @property
    def n_points(self) -> int:
        return len(self.rows) * len(self.cols)

    @property
    def typical_sigma_m(self) -> float:
        """The depth 1-sigma at :data:`SIGMA_DISTANCE_M`, m: the depth camera's model at normal incidence,
        or the stereo law Z^2 dd / (f B) with dd = :data:`STEREO_DISPARITY_SIGMA_PX`; 0 for an RGB camera."""
        z = SIGMA_DISTANCE_M
        if isinstance(self.spec, DepthCamera):
            return float(normal_sigma_m(self.spec, z))
        if isinstance(self.spec, StereoCamera):
            return z * z * STEREO_DISPARITY_SIGMA_PX / (self.pin.f * self.spec.baseline_m)
        return 0.0

    def gather(self, views: dict[str, np.ndarray], frame: int) -> CameraImages:
        """Copies of the camera's blocks (``views``: part -> the shared view) taken at ring frame ``frame``."""
        return CameraImages(frame, **{part: np.array(v, copy=True) for part, v in views.items()})

    def measure(self, images: CameraImages) -> np.ndarray | None:
        """The camera's measured planar depth (H, W) float32 m, NaN invalid (after the effects' image stage,
        before their depth stage); None for an RGB camera."""
        images = self.effects.images(images)
        sc = self.scenario
        if isinstance(self.spec, DepthCamera):
            gen = frame_generator(sc.seed, images.frame, self.index) if self.spec.noise else None
            z = depth_model(self.spec)(images.depth, self.pin, self.spec, gen)
        elif isinstance(self.spec, StereoCamera):
            if self.formation is not None:                      # the eyes' images as the sensor gives them
                images = replace(images, rgb=self.formation.eye(images.rgb, 0, images.frame),
                                 right=self.formation.eye(images.right, 1, images.frame))
            z = stereo_depth(self._matcher, self.spec, self.pin.f, images.rgb, images.right)
        else:
            return None
        return self.effects.depth(images, z)

    def points(self, depth_m: np.ndarray | None, level_from_parent: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The strided pixels of ``depth_m`` (H, W) m back-projected: (level points (M, 3) float64, ranges (M,)
        float32 m from the camera, border flags (M,) uint8, camera-frame record (M, 4) float32 x y z range);
        NaN rows where the depth is invalid, its expected 1-sigma exceeds
        :data:`~perception_proc.cameras.expected.GATE_SIGMA_M`, or (a depth camera's) the pixel is a flying pixel
        between two surfaces (:func:`perception_proc.cameras.jump_edges.flying_pixels`). ``level_from_parent``
        (4, 4) maps the camera's parent body frame into the level frame (identity when they are the same body)."""
        if depth_m is None:
            empty = np.zeros((0, 3))
            return empty, np.zeros(0, np.float32), np.zeros(0, np.uint8), np.zeros((0, 4), np.float32)
        s = self.stride                                                        # the strided pixels, as a view
        z = np.asarray(depth_m)[s // 2::s, s // 2::s].astype(np.float64).reshape(-1)
        sigma = point_sigma_m(self.spec, self.pin.f, z)
        if isinstance(self.spec, DepthCamera):                                 # between two surfaces: flying
            jump = jump_threshold(z, sigma, self.pin.f, self.spec.max_incidence_deg).reshape(self.grid_shape)
            z[flying_pixels(depth_m, jump, self.rows, self.cols).reshape(-1)] = np.nan
        with np.errstate(invalid="ignore"):
            z[sigma > GATE_SIGMA_M] = np.nan                                   # gated by its own error
        cam = self.unit_points * z[:, None]                                    # camera frame, m
        rng = ranges_of(cam)
        level_from_camera = level_from_parent @ self.parent_from_camera
        level = cam @ level_from_camera[:3, :3].T + level_from_camera[:3, 3]
        record = np.empty((len(z), 4), np.float32)
        record[:, :3] = cam
        record[:, 3] = rng
        rng32 = record[:, 3].copy()                                            # the ranges as float32
        flags = border_beams(rng32, self.grid_shape)
        flags[self.edge] |= FOV_EDGE
        return level, rng32, flags, record
