"""TrackingConfig refuses values no tracking could run with, naming the field, the value and
what is allowed (instead of a window that searches nothing or a fusion with no lag)."""

from __future__ import annotations

import math

import pytest

from agvsim.slam.frontend import TrackingConfig
from agvsim.slam.graph_slam import SlamConfig


def test_the_defaults_and_the_point_samples_variant_are_valid() -> None:
    TrackingConfig()
    SlamConfig.point_samples()
    TrackingConfig(observed_share=None, edge_on_max_step_m=0.5, unmatched_hold_scans=0)


@pytest.mark.parametrize(
    ("field", "value", "allowed"),
    [
        ("window_m", -0.15, "positive"),
        ("window_m", 0.0, "positive"),
        ("sigma_m", math.nan, "positive"),
        ("fusion_lag", 0, "positive"),
        ("submap_length_m", -8.0, "positive"),
        ("gn_prior_weight", -1e-4, ">= 0"),
        ("unmatched_hold_scans", -1, ">= 0"),
        ("retry_score", 1.5, "a mean likelihood in [0, 1]"),
        ("observed_share", 0.0, "in (0, 1] or None"),
        ("observed_share", 1.5, "in (0, 1] or None"),
        ("edge_on_turn_rad", math.pi, "in (0, pi/2] or None"),
        ("edge_on_max_step_m", 0.0, "positive or None"),
        ("l_miss", 0.4, "negative"),
    ],
)
def test_a_bad_value_names_field_value_and_what_is_allowed(
    field: str, value: float, allowed: str
) -> None:
    with pytest.raises(ValueError) as err:
        TrackingConfig(**{field: value})
    text = str(err.value)
    assert f"TrackingConfig.{field} must be {allowed}" in text
    assert repr(value) in text


def test_a_lost_score_above_the_retry_score_is_refused() -> None:
    with pytest.raises(ValueError, match=r"lost_score \(0.7\) must not exceed retry_score"):
        TrackingConfig(lost_score=0.7)
