"""SE(2) helpers: hand-worked values and group identities (hypothesis)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from agvsim.slam.se2 import between, compose, inverse, rotation_matrices, wrap_angle

coord = st.floats(-50.0, 50.0, allow_nan=False)
angle = st.floats(-10.0, 10.0, allow_nan=False)
pose = st.tuples(coord, coord, angle).map(lambda p: np.array(p, dtype=np.float64))
batch = st.integers(1, 6).flatmap(lambda n: st.lists(pose, min_size=n, max_size=n).map(np.stack))


def assert_poses_close(a: np.ndarray, b: np.ndarray, atol: float = 1e-9) -> None:
    np.testing.assert_allclose(a[..., :2], b[..., :2], atol=atol, rtol=0)
    np.testing.assert_allclose(wrap_angle(a[..., 2] - b[..., 2]), 0.0, atol=atol)


def test_hand_worked_compose_between() -> None:
    a = np.array([1.0, 2.0, math.pi / 2])
    b = np.array([3.0, 0.0, math.pi / 2])
    # b's x axis in a's frame points along world +y
    np.testing.assert_allclose(compose(a, b), [1.0, 5.0, math.pi], atol=1e-12)
    np.testing.assert_allclose(inverse(a), [-2.0, 1.0, -math.pi / 2], atol=1e-12)
    np.testing.assert_allclose(between(a, [1.0, 5.0, math.pi]), b, atol=1e-12)


def test_shapes_and_broadcast() -> None:
    a = np.zeros((4, 3))
    assert compose(a, np.array([1.0, 0.0, 0.0])).shape == (4, 3)
    assert inverse(np.zeros(3)).shape == (3,)
    assert rotation_matrices(np.zeros(5)).shape == (5, 2, 2)
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        compose(np.zeros((4, 2)), np.zeros(3))


def test_wrap_angle_range_and_pi() -> None:
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)


@given(arrays(np.float64, 20, elements=st.floats(-1e4, 1e4, allow_nan=False)))
def test_wrap_angle_property(a: np.ndarray) -> None:
    w = wrap_angle(a)
    assert np.all(w > -math.pi) and np.all(w <= math.pi)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-9)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-9)


@settings(max_examples=100)
@given(batch)
def test_compose_inverse_is_identity(a: np.ndarray) -> None:
    assert_poses_close(compose(a, inverse(a)), np.zeros_like(a))
    assert_poses_close(compose(inverse(a), a), np.zeros_like(a))
    assert_poses_close(inverse(inverse(a)), a)


@settings(max_examples=100)
@given(pose, pose, pose)
def test_associativity_and_between(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> None:
    assert_poses_close(compose(compose(a, b), c), compose(a, compose(b, c)), atol=1e-8)
    assert_poses_close(between(a, compose(a, b)), b, atol=1e-8)
    assert_poses_close(between(a, b), compose(inverse(a), b), atol=1e-8)
    assert_poses_close(inverse(between(a, b)), between(b, a), atol=1e-8)
