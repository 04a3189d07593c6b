"""The guidance and safety config blocks: validation and what they build."""

from __future__ import annotations

import math

import pytest
from pydantic import ValidationError

from agvsim.scenario_guidance import SafetyConfig, TapeConfig, build_safety, build_tape

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
    with pytest.raises(ValueError, match=r"robots\[0\].safety: no field set is active between"):
        build_safety(cfg, "robots[0].safety", 0.3, 0.3, 1.0, 0.0)
    spec = build_safety(cfg, "robots[0].safety", 0.3, 0.3, 0.49, 0.0)
    assert spec.select(0.2) == 0
    with pytest.raises(ValidationError, match="NaN"):
        SafetyConfig(
            sensor="lidar",
            field_sets=[{"name": "a", "protective": FIELD, "speed_max_m_s": float("nan")}],
        )
