"""Local-SLAM edges shaped by their keyframe's match
(:func:`~agvsim.slam.graph_slam.local_information`): a keyframe in a corridor is placed across
it by the walls, along it by odometry. A round 2 cm edge there held a one-metre tracking slip
against the loop closures that would have mended it (issue 19, ACES with a heading bias)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.slam.graph_slam import local_information

SIGMA_M, SIGMA_RAD = 0.02, math.radians(0.5)


def _corridor_hessian(along_rad: float, ratio: float) -> np.ndarray:
    """``J^T J`` of a scan in a corridor running at ``along_rad`` (local frame): ``ratio`` of
    the across-corridor sharpness along it, heading terms of their own."""
    d = np.array([math.cos(along_rad), math.sin(along_rad)])
    n = np.array([-d[1], d[0]])
    h = np.zeros((3, 3))
    h[:2, :2] = 400.0 * (np.outer(n, n) + ratio * np.outer(d, d))
    h[2, 2], h[0, 2], h[2, 0] = 900.0, 30.0, 30.0
    return h


def test_a_corridor_along_the_keyframe_is_soft_along_it() -> None:
    # corridor along local x, keyframe heading 0: along it 0.1 % of the sharpness across,
    # floored at 5 %: std 2 cm / sqrt(0.05) = 8.9 cm along, 2 cm across, 0.5 deg in heading
    info = local_information(_corridor_hessian(0.0, 1e-3), 0.0, SIGMA_M, SIGMA_RAD, 0.05)
    np.testing.assert_allclose(info, np.diag([0.05 / SIGMA_M**2, 1 / SIGMA_M**2, SIGMA_RAD**-2]))
    # a ratio above the floor is kept: 30 % -> 750 and 2500 per m^2
    info = local_information(_corridor_hessian(0.0, 0.3), 0.0, SIGMA_M, SIGMA_RAD, 0.05)
    np.testing.assert_allclose(np.diag(info)[:2], [750.0, 2500.0])


def test_the_information_is_turned_into_the_keyframes_frame() -> None:
    # the same corridor (along local x) seen by a keyframe heading 90 deg: along the corridor
    # is the keyframe's -y
    info = local_information(_corridor_hessian(0.0, 1e-3), math.pi / 2, SIGMA_M, SIGMA_RAD, 0.05)
    np.testing.assert_allclose(info[:2, :2], np.diag([2500.0, 125.0]), atol=1e-9)
    # a corridor at 50 deg, keyframe heading 20 deg: it runs at 30 deg in the keyframe's frame
    info = local_information(
        _corridor_hessian(math.radians(50), 1e-3), math.radians(20), SIGMA_M, SIGMA_RAD, 0.05
    )
    along = np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    np.testing.assert_allclose(info[:2, :2] @ along, 125.0 * along, atol=1e-9)
    np.testing.assert_allclose(
        info[:2, :2] @ [-along[1], along[0]], 2500.0 * np.array([-along[1], along[0]]), atol=1e-9
    )


def test_round_where_the_match_says_nothing() -> None:
    round_ = np.diag([2500.0, 2500.0, SIGMA_RAD**-2])
    for hess, floor in (
        (None, 0.05),
        (np.zeros((3, 3)), 0.05),
        (_corridor_hessian(0.3, 1e-3), 1.0),
    ):
        np.testing.assert_allclose(local_information(hess, 0.4, SIGMA_M, SIGMA_RAD, floor), round_)
    for bad in (0.0, -0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="local_weak_floor must lie in"):
            local_information(None, 0.0, SIGMA_M, SIGMA_RAD, bad)
    # a room's match, as sharp every way, stays round whatever the heading
    room = np.diag([400.0, 400.0, 900.0])
    np.testing.assert_allclose(local_information(room, 1.1, SIGMA_M, SIGMA_RAD, 0.05), round_)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-3.0, 3.0), min_size=9, max_size=9),
    st.floats(-math.pi, math.pi),
    st.floats(0.01, 1.0),
)
def test_std_between_sigma_and_sigma_over_root_floor(
    a: list[float], heading: float, floor: float
) -> None:
    m = np.array(a).reshape(3, 3)
    hess = m @ m.T  # J^T J: symmetric, positive semi-definite
    info = local_information(hess, heading, SIGMA_M, SIGMA_RAD, floor)
    np.testing.assert_allclose(info, info.T)
    assert info[2, 2] == SIGMA_RAD**-2 and not info[:2, 2].any()
    w = np.linalg.eigvalsh(info[:2, :2]) * SIGMA_M**2
    if np.linalg.eigvalsh(hess[:2, :2])[-1] > 0:
        assert math.isclose(w[-1], 1.0, rel_tol=1e-9)
        assert w[0] >= floor * (1 - 1e-9)
