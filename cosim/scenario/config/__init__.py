"""Typed, frozen scenario records (pydantic v2). ``Scenario`` is the root."""
from .atmosphere import Atmosphere
from .base import Model, Mount
from .control import Controller, Coping, Fusion, Grain, Integrator
from .fmu import FMU_REF, Fmu, TractorCart, Vehicles
from .machines import CROP_PRESETS, Auger, Cart, Combine, Crop, MachineSync, Tractor
from .outcome import Outcome
from .rendering import Render
from .scenario import FORMAT_VERSION, Outputs, Scenario, Timing
from .sensing import Codec, Noise, Pattern, Perception, Sensor
from .terrain import Terrain

__all__ = [
    "Atmosphere",
    "Model", "Mount", "Controller", "Coping", "Fusion", "Grain", "Integrator", "CROP_PRESETS", "Auger", "Cart", "Combine", "Crop",
    "MachineSync", "Outcome", "Tractor", "FMU_REF", "Fmu", "TractorCart", "Vehicles", "Render", "FORMAT_VERSION", "Outputs", "Scenario", "Timing", "Codec", "Noise",
    "Pattern", "Perception", "Sensor", "Terrain",
]
