"""Scenario sections for the LiDAR, the depth codec and the perception algorithms.

Owned by perception_proc; ``Codec`` is shared with renderer_proc (the shader encodes, perception
decodes) and ``Sensor.mount`` / ``Sensor.pattern`` with the renderer's rig planner.
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from .base import Fraction, Model, Mount, NonNegFloat, Options, PluginRef, PosFloat

__all__ = ["Codec", "Pattern", "Noise", "Sensor", "Stages", "Perception"]


#: largest alpha / beta for which |d' - d| <= beta / 510 holds with Eqs 1-3 as written
MAX_RATIO = 254.0
#: relative slack on the limit, so that alpha / (alpha / 254) passes despite round-off
RATIO_SLACK = 1e-12


class Codec(Model):
    """Depth-in-colour codec of the paper's Eqs 1-3 (d in cm). docs/CONTRACTS.md.

    ``gamma_mode``: ``linear`` stores linear bytes (the shader writes x^gamma and the inverse gamma is undone
    before 8-bit storage, as in Unreal); ``mishandled`` quantises in the gamma domain, for the error study.
    """

    alpha_cm: PosFloat = 5000.0
    """Largest encodable planar depth, cm (alpha / beta at most 254)."""
    beta_cm: PosFloat = 100.0
    """Period of the fine depth channel, cm; the worst-case quantisation error is beta / 510."""
    gamma: PosFloat = 2.2
    """Gamma of the depth image's colour channels."""
    gamma_mode: Literal["linear", "mishandled"] = "linear"
    """linear: linear bytes (the inverse gamma undone before 8-bit storage); mishandled: quantised in the gamma
    domain (for the error study)."""

    @model_validator(mode="after")
    def _ratio(self) -> "Codec":
        if self.alpha_cm <= self.beta_cm:
            raise ValueError(f"alpha_cm ({self.alpha_cm}) must be larger than beta_cm ({self.beta_cm})")
        ratio = self.alpha_cm / self.beta_cm
        if ratio > MAX_RATIO * (1.0 + RATIO_SLACK):
            raise ValueError(
                f"alpha_cm / beta_cm = {ratio:g} exceeds {MAX_RATIO:g}: R's quantisation step then exceeds half a "
                "period and Eq 3 loses whole periods (255, the naive limit, holds only "
                "for an encoder that rounds R and B from one shared value); raise beta_cm or lower alpha_cm"
            )
        return self

    @property
    def max_depth_m(self) -> float:
        """Largest encodable planar depth, m (pixels at or beyond it are invalid)."""
        return self.alpha_cm / 100.0

    @property
    def bound_m(self) -> float:
        """Worst-case quantisation error beta/510, m."""
        return self.beta_cm / 510.0 / 100.0


class Pattern(Model):
    """Beam pattern: a preset grid, a Honeycomb-like unit, or a CSV table (elevation_deg, azimuth_deg per row).

    Angles are in the LiDAR frame (aligned with the camera frame: X right, Y up, Z forward). Azimuth is measured
    from the forward axis towards the left (positive yaw) ... see cosim.world.patterns for the exact
    convention and the conversion to the paper's (theta, phi).
    """

    preset: Literal["grid", "honeycomb", "csv"] = "honeycomb"
    """grid (uniform), honeycomb (a Honeycomb-like unit, denser near the horizon) or csv (a table in csv_file)."""
    csv_file: Path | None = None
    """Beam table for preset csv: a header line elevation_deg,azimuth_deg then one row per beam; relative to the
    scenario file."""
    azimuth_min_deg: float = Field(default=-45.0, ge=-180.0, le=180.0)
    """Smallest azimuth, deg (from the forward axis towards the left)."""
    azimuth_max_deg: float = Field(default=45.0, ge=-180.0, le=180.0)
    """Largest azimuth, deg."""
    elevation_min_deg: float = Field(default=-47.5, ge=-90.0, le=90.0)
    """Smallest elevation, deg."""
    elevation_max_deg: float = Field(default=47.5, ge=-90.0, le=90.0)
    """Largest elevation, deg."""
    azimuth_count: int = Field(default=240, ge=1, le=100_000)
    """Beams per row (azimuth steps)."""
    elevation_count: int = Field(default=160, ge=1, le=10_000)
    """Rows of beams (elevation steps)."""

    @model_validator(mode="after")
    def _ranges(self) -> "Pattern":
        if self.azimuth_max_deg <= self.azimuth_min_deg:
            raise ValueError("azimuth_max_deg must be larger than azimuth_min_deg")
        if self.elevation_max_deg <= self.elevation_min_deg:
            raise ValueError("elevation_max_deg must be larger than elevation_min_deg")
        if self.preset == "csv" and self.csv_file is None:
            raise ValueError("preset 'csv' needs csv_file")
        return self


class Noise(Model):
    """Range noise (Gaussian, m) and independent random dropout per beam, seeded from the scenario seed."""

    range_sigma_m: NonNegFloat = 0.0
    """1-sigma of the Gaussian range noise of each beam, m."""
    dropout: Fraction = 0.0
    """Fraction of beams lost at random (0-1)."""


class Sensor(Model):
    """The LiDAR: where it is, what it samples, its range limits and noise, the codec its images use."""

    # on a mast on the combine's auger side, 1.5 m behind the auger, 3.5 m out from the centre line and 6 m up,
    # looking left, 15 deg forward and 60 deg down, rolled 90 deg so the 95 deg vertical field runs along the
    # cart. Exact ray cast from half full to the target, wherever Machine Sync puts the cart: 50-85 % of the
    # grain cells seen and ~230 beams on the stream's lowest metre (a mast on the auger saw 58 % of the cells but
    # the tube hid the stream; the combine's side saw 5 %).
    mount: Mount = Mount(parent="combine", xyz_m=(-3.5, 5.0, 6.0), rpy_deg=(90.0, 60.0, 75.0))
    """Where the LiDAR is: by default on a mast on the combine's auger side, 6 m up, looking left and down at the
    cart (so that 50-85 % of the grain cells and the stream are seen)."""
    pattern: Pattern = Pattern()
    """The beam pattern: a preset grid, a Honeycomb-like unit or a CSV table."""
    range_min_m: NonNegFloat = 0.0
    """Shortest range returned, m."""
    range_max_m: PosFloat = 40.0
    """Longest range returned, m."""
    noise: Noise = Noise()
    """Range noise and dropout."""
    codec: Codec = Codec()
    """The depth-in-colour codec of the camera images."""
    max_angular_error_deg: PosFloat = 0.1
    """Largest angle between a beam and the pixel ray it is read from (the auto rig is planned for it), deg."""
    method: Literal["camera_rig", "beam_native"] = "camera_rig"
    """camera_rig: the paper's pipeline (camera images, Eqs 5-7 resample); beam_native: one pixel per beam, drawn
    from the LiDAR origin and decoded per beam (docs/lidar.md)."""

    @model_validator(mode="after")
    def _limits(self) -> "Sensor":
        if self.range_max_m <= self.range_min_m:
            raise ValueError("range_max_m must be larger than range_min_m")
        return self


class Stages(Model):
    """The stages of the ``staged`` perception algorithm, each replaceable on its own (perception_proc.protocol):
    ``rim`` finds the cart, ``heightmap`` grids the grain surface, ``impact`` finds where the stream lands.
    ``builtin``, an entry point name or an import path ``package.module:name``; ``<stage>_options``: keyword
    arguments the stage is called with."""

    rim: PluginRef = "builtin"
    """The stage that finds the cart: builtin, an entry point name or an import path."""
    rim_options: Options = {}
    """Keyword arguments the rim stage is called with."""
    heightmap: PluginRef = "builtin"
    """The stage that grids the grain surface: builtin, an entry point name or an import path."""
    heightmap_options: Options = {}
    """Keyword arguments the height-map stage is called with."""
    impact: PluginRef = "builtin"
    """The stage that finds where the stream lands: builtin, an entry point name or an import path."""
    impact_options: Options = {}
    """Keyword arguments the impact stage is called with."""


class Perception(Model):
    """Offloading perception: LiDAR resampling, cart boundary, height map, impact location, accuracy.

    ``sampler``: ``planar`` interpolates inverse depth inside continuous 2 x 2 pixel patches (exact on planes,
    never across an edge); ``nearest`` is the paper's nearest pixel. ``accuracy_every_frames``: compare with
    an exact ray cast of the same scene every that many frames (0: never). An evaluation's cost is mostly fixed
    (building the ray caster's scene, ~6-9 ms on a laptop core, plus ~0.2 us per beam), so the default casts many
    beams seldom: 16384 every 120 frames is ~0.1 ms per frame amortised (under 2 % of a default frame) and
    ~180,000 beams over a 120 s run; truth never feeds the estimates.
    ``accuracy_beams``: how many beams each evaluation casts, one drawn per stratum of equal runs of the beam
    table, seeded by (seed, frame) (0: every beam; see perception_proc.accuracy.stage.sample_beams).
    ``algorithm``: the per-frame algorithm (points -> cart, height map, impact): ``staged`` runs ``stages``;
    an entry point name or an import path ``package.module:name`` replaces it whole (docs/plugins.md);
    ``algorithm_options``: keyword arguments it is called with.
    ``pose_gate_m``, ``pose_gate_deg``: a found cart farther or more turned than these from where Machine Sync puts
    it (perception_proc.posegate) is rejected: a phantom in dust, not the cart.
    """

    min_points_per_cell: int = Field(default=1, ge=1)
    """Points a grid cell needs to get a height."""
    impact_search_radius_m: PosFloat = 0.6
    """Radius around the predicted impact searched for the stream, m."""
    sampler: Literal["planar", "nearest"] = "planar"
    """planar: inverse depth interpolated inside continuous 2 x 2 pixel patches; nearest: the paper's nearest
    pixel."""
    accuracy_every_frames: int = Field(default=120, ge=0, le=1_000_000)
    """Compare with an exact ray cast of the same scene every that many frames (0: never)."""
    accuracy_beams: int = Field(default=16384, ge=0, le=10_000_000)
    """Beams each accuracy evaluation casts, one per stratum of the beam table (0: every beam)."""
    pose_gate_m: NonNegFloat = 0.5
    """A cart found farther than this from where Machine Sync puts it is no cart (0: no gate), m."""
    pose_gate_deg: float = Field(default=5.0, ge=0.0, le=180.0, allow_inf_nan=False)
    """A cart found turned more than this from where Machine Sync puts it is no cart, deg."""
    algorithm: PluginRef = "staged"
    """The per-frame algorithm: staged (runs stages), an entry point name or an import path that replaces it
    whole."""
    algorithm_options: Options = {}
    """Keyword arguments the algorithm is called with."""
    stages: Stages = Stages()
    """The stages of the staged algorithm, each replaceable on its own."""
