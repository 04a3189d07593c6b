"""The guidance and safety config blocks: validation and what they build."""

from __future__ import annotations

import math

import pytest
from pydantic import ValidationError

from agvsim.scenario_guidance import (
    SafetyConfig,
    TapeConfig,
    build_tape,
    safety_problems,
    safety_spec,
)

FIELD = [[0.0, -0.3], [0.6, -0.3], [0.6, 0.3], [0.0, 0.3]]


def test_a_tape_line_is_points_or_an_arc_not_both():
    with pytest.raises(ValidationError, match="either points"):
        TapeConfig(
            lines=[
                {
                    "points": [[0, 0], [1, 0]],
                    "arc": {"center": [0, 0], "radius_m": 1, "start_deg": 0, "sweep_deg": 90},
                }
            ]
        )
    tape = build_tape(
        TapeConfig(
            lines=[
                {"points": [[0, 0], [1, 0]]},
                {"arc": {"center": [1, 1], "radius_m": 1, "start_deg": -90, "sweep_deg": 90}},
            ]
        )
    )
    assert tape.length_m == pytest.approx(1 + math.pi / 2, abs=1e-3)  # chords: a bit short


def test_fields_too_short_or_missing_speeds_are_refused_naming_the_block():
    cfg = SafetyConfig(
        sensor="lidar",
        field_sets=[
            {"name": "slow", "protective": FIELD, "speed_min_m_s": -0.1, "speed_max_m_s": 0.5}
        ],
    )
    spec = safety_spec(cfg, "robots[0].safety")
    problems = safety_problems(cfg, spec, "robots[0].safety", ["lidar"], 0.3, 0.3, 1.0)
    # FIELD reaches 0.6 m ahead: 0.3 m body + 0.5 x 0.1 + 0.5^2 / 2 = 0.475 m needed at 0.5
    # m/s; behind it reaches nothing though the set is active backing at 0.1 m/s; and no set
    # covers [-1, -0.1) nor [0.5, 1]
    assert problems[0].startswith("robots[0].safety.field_sets[0]: the protective field ")
    assert "reaches 0.000 m behind but at 0.100 m/s the vehicle needs 0.315 m" in problems[0]
    assert "no field set is active between -1.000 and -0.100 m/s" in problems[1]
    assert "no field set is active between 0.500 and 1.000 m/s" in problems[2]
    assert len(problems) == 3 and problems[2].endswith(
        "check_lengths: false to run with them anyway)"
    )
    # a sensor the robot does not have
    assert safety_problems(cfg, spec, "r.safety", ["front"], 0.3, 0.3, 0.0)[0].startswith(
        "r.safety.sensor: 'lidar' is not a range sensor of this robot"
    )
    assert spec.select(0.2) == 0
    with pytest.raises(ValidationError, match="NaN"):
        SafetyConfig(
            sensor="lidar",
            field_sets=[{"name": "a", "protective": FIELD, "speed_max_m_s": float("nan")}],
        )
