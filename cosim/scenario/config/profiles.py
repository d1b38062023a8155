"""Sensor profiles: packaged data files that fill a camera's parameters from a real device (docs/cameras.md).

A profile is ``cosim/scenario/profiles/<name>.yaml``: the ``kind`` of sensor it describes, a ``title``, and
``values``, each key of the camera record with its ``value``, its ``source`` (``datasheet``: the maker's
published figure; ``paper``: a published measurement or model; ``tuned``: chosen here, the reason given) and
``ref``, where it comes from. A camera that names ``profile: <name>`` takes every value it does not set itself
from the profile (cosim.scenario.config.cameras); the resolved scenario then carries them all.

A profile renamed keeps its old name working (:data:`RENAMED`): the old name loads the same values under the new
name, which the resolved scenario shows.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import yaml

__all__ = ["PROFILE_DIR", "SOURCES", "RENAMED", "ProfileValue", "Profile", "load_profile", "profile_names"]

#: where the packaged profiles live
PROFILE_DIR = Path(__file__).resolve().parents[1] / "profiles"
#: what a value's ``source`` may be
SOURCES = ("datasheet", "paper", "tuned")
#: old profile name -> its name now: the Kinect v2 image with the structured-light noise model was named for a
#: time-of-flight camera; it loads unchanged under the name of what it models
RENAMED = {"tof_kinect_class": "kinect_class_structured_light"}


@dataclass(frozen=True)
class ProfileValue:
    """One parameter of a profile: its ``value``, ``source`` (one of :data:`SOURCES`) and ``ref``."""

    value: float | int | str
    source: str
    ref: str


@dataclass(frozen=True)
class Profile:
    """A packaged sensor profile: ``name`` (file stem), ``kind`` (a sensor kind), ``title``, ``values`` by key."""

    name: str
    kind: str
    title: str
    values: dict[str, ProfileValue]

    def plain(self) -> dict:
        """The values alone, key -> value (what a camera record takes)."""
        return {k: v.value for k, v in self.values.items()}


def profile_names() -> list[str]:
    """The packaged profiles' names, sorted."""
    return sorted(p.stem for p in PROFILE_DIR.glob("*.yaml"))


@functools.lru_cache(maxsize=32)
def load_profile(name: str) -> Profile:
    """The packaged profile ``name`` (an old name of :data:`RENAMED` gives the renamed profile, under its new
    name); ValueError naming the profiles there are when it does not exist, and when a value lacks its source or
    reference."""
    name = RENAMED.get(name, name)
    path = PROFILE_DIR / f"{name}.yaml"
    if not name.replace("_", "").isalnum() or not path.is_file():
        raise ValueError(f"no sensor profile {name!r} (packaged: {', '.join(profile_names())})")
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    values = {}
    for key, item in doc["values"].items():
        if not isinstance(item, dict) or set(item) != {"value", "source", "ref"} or item["source"] not in SOURCES:
            raise ValueError(f"profile {name!r}: {key} needs value, source ({' | '.join(SOURCES)}) and ref")
        values[key] = ProfileValue(item["value"], item["source"], str(item["ref"]))
    return Profile(name, str(doc["kind"]), str(doc.get("title", name)), values)
