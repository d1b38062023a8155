"""Scenario records of the named sensors (``sensors:``): the LiDAR and three camera kinds. Owned by perception_proc
and renderer_proc (docs/cameras.md).

``sensors`` maps a name to a sensor whose ``kind`` picks its record:

* ``lidar`` (:class:`LidarSensor`): the LiDAR of ``sensor:`` (every key of it), at most one per scenario;
* ``depth_camera`` (:class:`DepthCamera`): exact rendered depth with a published noise model picked by ``model``:
  ``structured_light`` (Nguyen et al. 2012, fitted to the structured-light Kinect: axial and lateral noise
  growing with range and incidence) or ``time_of_flight`` (noise growing as the returned amplitude falls,
  amplitude-weighted mixed pixels at depth edges); invalid pixels beyond range or at grazing incidence; seeded;
* ``stereo_camera`` (:class:`StereoCamera`): left and right textured images ``baseline_m`` apart, disparity
  from OpenCV's StereoSGBM (or StereoBM), depth = f B / d; its error is the matcher's;
* ``rgb_camera`` (:class:`RgbCamera`): a textured, lit colour image (no depth).

Cameras follow the camera frame of docs/architecture.md (X right, Y up, Z forward along the optical axis): the
``mount`` places a body-axes frame (x forward, y left, z up) on its parent and the optical axis is its x axis;
``rpy_deg`` turns it (positive pitch looks down). The pinhole has ``width_px`` x ``height_px`` square pixels,
``hfov_deg`` horizontally and its principal point at the image centre. ``profile`` fills every value the
camera does not set from a packaged device profile (cosim.scenario.config.profiles).
"""
from __future__ import annotations

import math
from typing import Annotated, Literal, Union

from pydantic import AfterValidator, Field, model_validator

from .base import Fraction, Model, Mount, NonNegFloat, PosFloat
from .imaging import ImageNoise, LensDistortion
from .profiles import load_profile
from .sensing import Sensor

__all__ = ["SENSOR_NAME", "KINDS", "STEREO_BASELINE_M", "MAX_SENSORS", "DEPTH_KINDS", "DEPTH_MODELS", "DISPARITY_STEP_PX",
           "SEARCH_EDGE_PX", "Camera", "LidarSensor", "DepthCamera", "StereoCamera",
           "RgbCamera", "SensorSpec", "SensorMap", "Sensors"]

#: what a sensor name may look like (it names the sensor's shared-memory blocks, ``cam_<name>_...``)
SENSOR_NAME = r"^[a-z][a-z0-9_]{0,23}$"
#: the sensor kinds
KINDS = ("lidar", "depth_camera", "stereo_camera", "rgb_camera")
#: the kinds that give depth (points for the built-in perception)
DEPTH_KINDS = ("lidar", "depth_camera", "stereo_camera")
#: the depth camera's noise models (perception_proc.cameras.depth_models)
DEPTH_MODELS = ("structured_light", "time_of_flight")
#: OpenCV's disparity search must be a multiple of this, px
DISPARITY_STEP_PX = 16
#: a disparity within this of either end of the search is invalid: a surface outside the searched depths has its
#: cost minimum at the end of the search, px (perception_proc.cameras.stereo)
SEARCH_EDGE_PX = 1.0
#: StereoBM's smallest block, px
BM_MIN_BLOCK_PX = 5
#: (shortest, longest) stereo baseline, m: from a compact module's (Intel RealSense D405: 18 mm) with room below,
#: to a vehicle-wide rig (about 1.5 m); the packaged profiles are 75 mm (OAK-D) and 0.21 m (MultiSense S21)
STEREO_BASELINE_M = (0.005, 2.0)
#: most sensors of a scenario: each is a render pass, a perception pipeline and its shared blocks a frame; a
#: harvester carries one to four
MAX_SENSORS = 16


def _tuples(value):
    """JSON arrays as tuples, recursively: a before-validator hands Python objects on, and the strict records take
    fixed-length arrays (``mount.xyz_m``) only as tuples from Python."""
    if isinstance(value, dict):
        return {k: _tuples(v) for k, v in value.items()}
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    return value


class LidarSensor(Sensor):
    """The LiDAR under ``sensors:`` (``kind: lidar``): the same keys as ``sensor:``."""

    kind: Literal["lidar"]
    """lidar: this sensor is the LiDAR (the keys of sensor:)."""


class Camera(Model):
    """What every camera has: ``profile`` (a packaged device profile that fills the values not set here),
    ``mount`` (required), the pinhole (``width_px`` x ``height_px``, ``hfov_deg``), the depths it reports
    (``range_min_m`` .. ``range_max_m``, planar depth Z), ``labels`` (also render the per-pixel label image,
    docs/cameras.md), ``every_frames`` (it takes an image every that many ring frames; between them perception
    keeps its last image) and ``points_stride`` (perception back-projects every that many pixels along each image
    axis into the level-frame points the built-in algorithm uses; under the mock renderer it scales with the
    image, at least 1)."""

    profile: str | None = None
    """A packaged device profile (cosim/scenario/profiles: oak_d, multisense_s21b, kinect_v1_structured_light,
    azure_kinect_nfov, ...) that fills every key not set here; a renamed profile's old name resolves to its new one."""
    mount: Mount
    """Where the camera is: parent body, position and roll, pitch, yaw; the optical axis is the mount's x axis."""
    width_px: int = Field(default=640, ge=16, le=4096)
    """Image width, px (a colour or stereo camera's scaled by render.mock_scale under the mock renderer)."""
    height_px: int = Field(default=480, ge=16, le=4096)
    """Image height, px (a colour or stereo camera's scaled by render.mock_scale under the mock renderer)."""
    hfov_deg: float = Field(default=60.0, gt=1.0, lt=170.0, allow_inf_nan=False)
    """Horizontal field of view, deg (square pixels, principal point at the image centre)."""
    range_min_m: NonNegFloat = 0.3
    """Nearest planar depth the camera reports, m."""
    range_max_m: PosFloat = 10.0
    """Farthest planar depth the camera reports, m."""
    labels: bool = False
    """Also render the per-pixel label image (ground, cart wall, cart rim, grain, stream, combine, tractor, auger)."""
    every_frames: int = Field(default=1, ge=1, le=1000)
    """Take an image every this many ring frames (perception keeps the last one in between)."""
    points_stride: int = Field(default=2, ge=1, le=64)
    """Back-project every this many pixels along each axis into the built-in algorithm's points."""

    @model_validator(mode="before")
    @classmethod
    def _profile(cls, data):
        """Every value the camera does not set, from its ``profile``."""
        if not isinstance(data, dict):
            return data
        if data.get("profile") is None:
            return _tuples(data)
        prof = load_profile(str(data["profile"]))
        kind = data.get("kind")
        if prof.kind != kind:
            raise ValueError(f"profile {prof.name!r} describes a {prof.kind}, this sensor is a {kind}")
        return _tuples({**prof.plain(), **data, "profile": prof.name})

    @model_validator(mode="after")
    def _limits(self) -> "Camera":
        if self.range_max_m <= self.range_min_m:
            raise ValueError("range_max_m must be larger than range_min_m")
        return self

    @property
    def focal_px(self) -> float:
        """Focal length in pixels, f = w / (2 tan(hfov / 2))."""
        return self.width_px / (2.0 * math.tan(math.radians(self.hfov_deg) / 2.0))


class DepthCamera(Camera):
    """A depth camera: the exact rendered depth with the noise model ``model`` picks
    (perception_proc.cameras.depth_models; docs/cameras.md gives each model's source and where it stops holding).

    ``structured_light``: the model of Nguyen, Izadi and Lovell (2012), fitted to the structured-light Kinect
    (defaults are the paper's coefficients). Axial 1-sigma ``axial_a_m + axial_b_per_m (z - axial_z0_m)^2`` m at
    planar depth z (m), plus ``axial_grazing_m / sqrt(z) theta^2 / (pi/2 - theta)^2`` beyond
    ``grazing_from_deg`` of incidence theta; lateral 1-sigma ``lateral_px + lateral_grazing_px theta / (pi/2 -
    theta)`` px (the pixel reads the depth of a point displaced by it); a pixel whose 3 x 3 neighbourhood spans
    more than ``flying_edge_m`` of depth is a mixed ("flying") pixel uniformly between its nearest and farthest
    neighbour.

    ``time_of_flight`` (continuous-wave time of flight, Lange and Seitz 2001): the returned amplitude of a
    surface of ``albedo`` at range r and incidence theta is A = albedo cos(theta) / r^2; the axial 1-sigma is
    ``tof_ref_sigma_m`` sqrt(s q + (1 - s) q^2), q = A_ref / A, A_ref that of a ``tof_ref_albedo`` surface at
    ``tof_ref_range_m`` facing the camera, s = ``tof_signal_share`` (the share of the reference variance from
    the signal's own shot noise; the rest is the background's); a pixel straddling a depth edge (as above)
    reports the amplitude-weighted mixture of its nearest and farthest neighbour, a uniform share of its
    footprint on each; ``multipath`` adds the one-bounce diffuse multipath (Fuchs 2010).

    Both: pixels at incidence beyond ``max_incidence_deg`` or outside the range are invalid. ``noise: false``
    reports the exact depth (tests). ``rgb``: also render the colour image (an RGB-D camera)."""

    kind: Literal["depth_camera"]
    """depth_camera: exact rendered depth with the noise model of ``model``."""
    model: Literal["structured_light", "time_of_flight"] = "structured_light"
    """The noise model: structured_light (Nguyen et al. 2012, the structured-light Kinect) or time_of_flight
    (amplitude-dependent noise and mixed pixels of a continuous-wave time-of-flight camera)."""
    rgb: bool = False
    """Also render the colour image (an RGB-D camera)."""
    noise: bool = True
    """Apply the noise model (false: the exact depth within the range limits)."""
    axial_a_m: NonNegFloat = 0.0012
    """structured_light: axial 1-sigma at z0, m (Nguyen et al. 2012: 0.0012)."""
    axial_b_per_m: NonNegFloat = 0.0019
    """structured_light: axial 1-sigma's growth with (z - z0)^2, m per m^2 (Nguyen et al. 2012: 0.0019)."""
    axial_z0_m: NonNegFloat = 0.4
    """structured_light: depth of the axial model's minimum, m (Nguyen et al. 2012: 0.4)."""
    axial_grazing_m: NonNegFloat = 0.0001
    """structured_light: axial grazing term's coefficient, m (Nguyen et al. 2012: 0.0001 / sqrt(z) theta^2 /
    (pi/2 - theta)^2)."""
    grazing_from_deg: float = Field(default=60.0, ge=0.0, lt=90.0, allow_inf_nan=False)
    """structured_light: incidence beyond which the axial grazing term applies, deg (Nguyen et al. 2012: 60)."""
    lateral_px: NonNegFloat = 0.8
    """structured_light: lateral 1-sigma at normal incidence, px (Nguyen et al. 2012: 0.8)."""
    lateral_grazing_px: NonNegFloat = 0.035
    """structured_light: lateral growth with theta / (pi/2 - theta), px (Nguyen et al. 2012: 0.035)."""
    albedo: float = Field(default=0.3, gt=0.0, le=1.0, allow_inf_nan=False)
    """time_of_flight: the scene's diffuse reflectance at the camera's near-infrared wavelength (0-1]."""
    tof_ref_sigma_m: float = Field(default=0.017, gt=0.0, le=1.0, allow_inf_nan=False)
    """time_of_flight: axial 1-sigma of the reference return, m (Azure Kinect datasheet: at most 17 mm)."""
    tof_ref_range_m: float = Field(default=3.86, gt=0.0, le=100.0, allow_inf_nan=False)
    """time_of_flight: range of the reference return, m (Azure Kinect NFOV unbinned: 3.86, its range's end)."""
    tof_ref_albedo: float = Field(default=0.15, gt=0.0, le=1.0, allow_inf_nan=False)
    """time_of_flight: reflectance of the reference return (Azure Kinect datasheet: 15 %, its darkest target)."""
    tof_signal_share: Fraction = 0.5
    """time_of_flight: share of the reference variance from the signal's own shot noise (variance ~ 1 / A); the
    rest is the background light's (variance ~ 1 / A^2)."""
    multipath: bool = False
    """time_of_flight: add the one-bounce diffuse multipath of the camera's own light (Fuchs 2010): concave scenes
    read farther."""
    max_incidence_deg: float = Field(default=80.0, gt=0.0, lt=90.0, allow_inf_nan=False)
    """Pixels seen at a steeper incidence are invalid, deg."""
    flying_edge_m: PosFloat = 0.1
    """A pixel whose 3 x 3 neighbourhood spans more depth than this is a mixed (flying) pixel, m."""


class StereoCamera(Camera):
    """A stereo pair: the left camera at the mount, the right one ``baseline_m`` to its right (camera +X), the
    same pinhole, parallel axes (rectified by construction). Disparity from OpenCV's ``sgbm`` (StereoSGBM, the
    default) or ``bm`` (StereoBM) on the grey images, depth Z = f B / d, invalid where the matcher gives no
    disparity. ``sgbm_mode``: OpenCV's SGBM variant, ``sgbm`` (one pass, five path directions, OpenCV's
    default), ``3way`` (OpenCV's faster three-way variant) or ``hh`` (two passes, eight directions: the full
    Hirschmuller method, about three times the time); the one-pass modes prefer the disparity of the rows above
    on surfaces that slant in the image's vertical (docs/cameras.md gives the measured bias). ``num_disparities`` (a multiple of 16) and ``min_disparity_px`` bound the search; ``block_size``
    (odd; BM needs >= 5), ``uniqueness_ratio``, ``speckle_window_px``, ``speckle_range_px`` and
    ``disp12_max_diff_px`` are OpenCV's parameters of the same names; ``texture_threshold`` invalidates blocks without
    texture (StereoBM's check, which SGBM lacks), ``subpixel`` picks the sub-pixel step and ``disparity_sigma_px``
    states the disparity error the camera is expected to hold (perception weighs and gates its points by it).
    ``image_noise`` and ``distortion`` (cosim.scenario.config.imaging; off by default) make the eyes' images what a
    real sensor gives before the matcher sees them. It needs the GL renderer's textured images: the mock renderer's plain shading has nothing to match."""

    kind: Literal["stereo_camera"]
    """stereo_camera: left and right textured images, disparity from OpenCV's matcher, depth = f B / d."""
    baseline_m: float = Field(default=0.12, ge=STEREO_BASELINE_M[0], le=STEREO_BASELINE_M[1], allow_inf_nan=False)
    """Distance from the left camera (the mount) to the right one along the image's X (right), m (5 mm to 2 m:
    compact modules to vehicle-wide rigs)."""
    matcher: Literal["sgbm", "bm"] = "sgbm"
    """OpenCV's StereoSGBM (sgbm) or StereoBM (bm)."""
    sgbm_mode: Literal["sgbm", "3way", "hh"] = "sgbm"
    """SGBM's variant: sgbm (one pass, five paths; OpenCV's default), 3way, or hh (two passes, eight paths)."""
    num_disparities: int = Field(default=128, ge=16, le=512)
    """Disparities searched, px (a multiple of 16)."""
    min_disparity_px: int = Field(default=0, ge=0, le=512)
    """Smallest disparity searched, px."""
    block_size: int = Field(default=5, ge=3, le=51)
    """Matched block size, px (odd; BM needs >= 5)."""
    uniqueness_ratio: int = Field(default=10, ge=0, le=100)
    """OpenCV's uniqueness ratio, percent."""
    speckle_window_px: int = Field(default=100, ge=0, le=10_000)
    """OpenCV's speckle filter window, px (0: off)."""
    speckle_range_px: int = Field(default=2, ge=0, le=64)
    """OpenCV's speckle filter range, px of disparity."""
    disp12_max_diff_px: int = Field(default=1, ge=-1, le=64)
    """OpenCV's left-right check tolerance, px (-1: off)."""
    texture_threshold: NonNegFloat = 0.5
    """Pixels whose block has less mean absolute horizontal gradient are invalid, grey levels per px (0: off)."""
    subpixel: Literal["refine", "matcher"] = "refine"
    """Sub-pixel disparity: refine (Gauss-Newton on the intensity difference, no pixel locking) or matcher
    (OpenCV's parabola over whole-pixel costs, which locks towards whole disparities)."""
    disparity_sigma_px: PosFloat = 0.25
    """The disparity 1-sigma the camera is expected to hold with SGBM, px; perception scales it by the matcher's
    measured ratio (BM 1.36, docs/cameras.md): its depth 1-sigma is Z^2 sigma / (f B)."""
    image_noise: ImageNoise | None = None
    """Shot and read noise of the eyes' images before the matcher (EMVA 1288 photon transfer); null: none."""
    distortion: LensDistortion | None = None
    """Each lens's Brown-Conrady distortion and its rectification from a calibration with a stated residual; null:
    ideal pinholes, rectified exactly."""
    motion_blur: bool = False
    """Blur each eye's image by the scene's motion relative to the camera over the exposure ``exposure_ms``
    (renderer_proc.motion_blur); false: the renderer's bytes."""
    exposure_ms: float = Field(default=5.0, gt=0.0, le=100.0, allow_inf_nan=False)
    """Exposure time of each image, ms, ending at the frame's time (the motion blur's); the packaged profiles
    state theirs."""

    @model_validator(mode="after")
    def _matcher(self) -> "StereoCamera":
        if self.num_disparities % DISPARITY_STEP_PX:
            raise ValueError(f"num_disparities ({self.num_disparities}) must be a multiple of {DISPARITY_STEP_PX}")
        if self.block_size % 2 == 0:
            raise ValueError(f"block_size ({self.block_size}) must be odd")
        if self.matcher == "bm" and self.block_size < BM_MIN_BLOCK_PX:
            raise ValueError(f"StereoBM needs block_size >= {BM_MIN_BLOCK_PX}, got {self.block_size}")
        if self.num_disparities + self.min_disparity_px >= self.width_px:
            raise ValueError("num_disparities + min_disparity_px must be smaller than width_px")
        return self

    def depth_sigma_m(self, z_m):
        """The expected depth 1-sigma at planar depth ``z_m`` (m, scalar or array), m: Z^2 sigma_d / (f B)."""
        return z_m * z_m * self.disparity_sigma_px / (self.focal_px * self.baseline_m)

    @property
    def disparity_range_px(self) -> tuple[int, int]:
        """(smallest, largest) disparity the matcher searches, px."""
        return self.min_disparity_px, self.min_disparity_px + self.num_disparities - 1


class RgbCamera(Camera):
    """A colour camera: the textured, lit image (and labels when asked); no depth."""

    kind: Literal["rgb_camera"]
    """rgb_camera: a textured, lit colour image (no depth)."""


#: one entry of ``sensors:``, its record picked by ``kind``
SensorSpec = Annotated[Union[LidarSensor, DepthCamera, StereoCamera, RgbCamera], Field(discriminator="kind")]


class SensorMap(dict):
    """``sensors:`` as a mapping name -> sensor record, hashable by value (a scenario stays a cache key)."""

    def __hash__(self) -> int:  # type: ignore[override]
        return hash(tuple(self.items()))

    def __reduce__(self):
        return SensorMap, (dict(self),)


#: the ``sensors:`` field's type
Sensors = Annotated[dict[Annotated[str, Field(pattern=SENSOR_NAME)], SensorSpec], Field(max_length=MAX_SENSORS),
                    AfterValidator(SensorMap)]
