"""The machines' full poses on the terrain (dynamics_proc.vehicles.ground.machine_poses) answer a repeated question
from the last answer: the same poses bit for bit as computed afresh, and a new question (a pose that differs in
its last bit, or only in the sign of a zero) computed anew."""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config import Scenario
from dynamics_proc.vehicles.ground import _machine_poses, machine_poses, stance_of


def _stance():
    s = Scenario.model_validate({"format_version": 1, "terrain": {"roughness_rms_m": 0.04, "grade_pct": 2.0,
                                                                   "cross_slope_pct": 1.0}})
    return stance_of(s, -1.2)


def _bits(poses) -> bytes:
    return np.array(poses, np.float64).tobytes()


def test_a_repeated_question_gets_the_same_poses_as_computed_afresh():
    st = _stance()
    planar = ((10.0, 7.3, 0.1), (9.0, 1.5, 0.05), (4.5, 1.2, 0.02))
    first = machine_poses(st, *planar)
    assert _bits(first) == _bits(_machine_poses(st, *planar))
    assert machine_poses(st, *planar) is first                    # the last answer, not computed again
    moved = ((10.0, 7.3, 0.1), (9.0, 1.5, 0.05), (math.nextafter(4.5, 5.0), 1.2, 0.02))
    again = machine_poses(st, *moved)
    assert again is not first and _bits(again) == _bits(_machine_poses(st, *moved))
    signed = ((0.0, 7.3, 0.0), (9.0, 1.5, 0.05), (4.5, 1.2, 0.02))
    zero = machine_poses(st, *signed)
    negative = machine_poses(st, (0.0, 7.3, -0.0), *signed[1:])
    assert negative is not zero and _bits(negative) == _bits(_machine_poses(st, (0.0, 7.3, -0.0), *signed[1:]))
