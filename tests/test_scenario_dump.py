"""dump_resolved: the fully resolved scenario as YAML; loading it back gives an equal Scenario."""
from __future__ import annotations

import math

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cosim.scenario.config import Scenario
from cosim.scenario.loader import (
    dump_resolved,
    load_scenario,
    load_scenario_text,
    resolve_scenario_arg,
)
from cosim.scenario.yamlmarks import Loader as _Loader


def roundtrip(scenario: Scenario) -> Scenario:
    return load_scenario_text(dump_resolved(scenario), "resolved.yaml")


def test_default_round_trip_has_every_field():
    s = load_scenario(resolve_scenario_arg("default"))
    text = dump_resolved(s)
    assert roundtrip(s) == s
    data = yaml.load(text, Loader=_Loader)
    assert data == s.model_dump(mode="json")  # every field, defaults included
    assert data["tractor"]["steer_rate_max_degps"] == 30.0 and data["crop"]["density_kgpm3"] is None


def test_round_trip_with_paths_and_tricky_strings(tmp_path):
    mesh = tmp_path / "cart mesh.obj"
    mesh.write_text("v 0 0 0\n")
    s = load_scenario_text("format_version: 1\n", extra={
        "name": "1e3", "description": "on: yes # not a comment\n2nd line", "cart.mesh_file": str(mesh),
        "integrator.rtol": 1e-12, "crop.density_kgpm3": 750.5, "combine.heading_deg": -0.0})
    back = roundtrip(s)
    assert back == s and back.name == "1e3" and back.cart.mesh_file == mesh
    # a plain YAML 1.1 reader agrees on every value, too
    assert yaml.safe_load(dump_resolved(s)) == s.model_dump(mode="json")


# every value within its unit's limits (cosim.scenario.config.limits): degrees, metres, seconds, kg/m^3
degrees = st.floats(min_value=-360.0, max_value=360.0, allow_nan=False, width=64)
metres = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, width=64)
seconds = st.floats(min_value=1e-300, max_value=1e5, allow_nan=False)
density = st.floats(min_value=1e-300, max_value=2e4, allow_nan=False)
text = st.text(alphabet=st.characters(blacklist_categories=("Cs", "Cc")) | st.sampled_from("\t\n"), max_size=40)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    name=st.from_regex(r"[A-Za-z0-9_.-]{1,64}", fullmatch=True),
    description=text,
    seed=st.integers(min_value=0, max_value=2**63 - 1),
    duration=seconds,
    heading=degrees,
    xyz=st.tuples(metres, metres, metres),
    density=st.none() | density,
    strategy=st.sampled_from(["front_to_back", "back_to_front", "lowest_first"]),
)
def test_round_trip_property(name, description, seed, duration, heading, xyz, density, strategy):
    s = load_scenario_text("format_version: 1\n", extra={
        "name": name, "description": description, "seed": seed, "duration_s": duration,
        "combine.heading_deg": heading, "sensor.mount.xyz_m": xyz, "crop.density_kgpm3": density,
        "controller.strategy": strategy})
    back = roundtrip(s)
    assert back == s
    assert math.copysign(1.0, back.combine.heading_deg) == math.copysign(1.0, heading)


@pytest.mark.parametrize("text", ["a\u2028b", "c\u2029d", "multi\nline", "1e3"])
def test_yaml_line_break_characters_survive_the_round_trip(text):
    """Regression (found by hypothesis): U+0085 in a description reloaded as a space."""
    s = load_scenario_text("format_version: 1\n", extra={"description": text})
    assert roundtrip(s).description == text
