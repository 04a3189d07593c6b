"""The one angle wrap (agvsim.angles): (-pi, pi], the array and the scalar form bit for bit
alike, and every module's wrap is this one."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from agvsim.angles import wrap_angle, wrap_scalar

PROPERTY = settings(max_examples=300, deadline=None)


@PROPERTY
@given(a=st.floats(-1e6, 1e6, allow_nan=False))
@example(a=math.pi)
@example(a=-math.pi)
@example(a=3 * math.pi)
@example(a=-3 * math.pi)
@example(a=2 * math.pi)
@example(a=0.0)
@example(a=-1e-300)
def test_wrap_angle(a: float) -> None:
    w = float(wrap_angle(a))
    assert -math.pi < w <= math.pi
    k = round((a - w) / (2 * math.pi))
    assert abs(a - w - 2 * math.pi * k) <= 1e-15 * max(1.0, abs(a)) * 8
    assert float(wrap_angle(w)) == w  # idempotent
    if -math.pi < a <= math.pi:
        assert w == pytest.approx(a, abs=1e-15)


@PROPERTY
@given(a=arrays(np.float64, 16, elements=st.floats(-1e4, 1e4, allow_nan=False)))
def test_scalar_and_array_give_the_same_bits(a: np.ndarray) -> None:
    got = np.array([wrap_scalar(float(x)) for x in a])
    assert np.array_equal(got.view(np.int64), wrap_angle(a).view(np.int64))


def test_hand_worked_values() -> None:
    assert wrap_scalar(math.pi) == math.pi
    assert wrap_scalar(-math.pi) == math.pi  # the seam belongs to +pi
    assert wrap_scalar(2 * math.pi) == 0.0
    assert wrap_scalar(1.5 * math.pi) == pytest.approx(-0.5 * math.pi, abs=1e-15)
    # a tiny negative angle is lost in pi - a (rounds to pi): it becomes 0, never +-pi
    assert wrap_scalar(-1e-300) == 0.0 and wrap_scalar(1e-300) == 0.0
    a = np.array([[0.5, -0.5 + 4 * math.pi], [math.pi, -math.pi]])
    np.testing.assert_allclose(wrap_angle(a), [[0.5, -0.5], [math.pi, math.pi]], atol=1e-14)
    assert wrap_angle(a).shape == (2, 2)


def test_just_above_pi_wraps_to_just_above_minus_pi() -> None:
    assert float(wrap_angle(np.nextafter(math.pi, 4.0))) > -math.pi


def test_every_module_wraps_with_the_one_function() -> None:
    from agvsim import kinematics
    from agvsim.control import mobility, statemachine
    from agvsim.slam import se2

    assert kinematics.wrap_angle is wrap_angle and se2.wrap_angle is wrap_angle
    for a in (-7.0, -math.pi, -1.0, 0.3, math.pi, 10.0):
        assert statemachine.wrap(a) == mobility.wrap(a) == wrap_scalar(a)
